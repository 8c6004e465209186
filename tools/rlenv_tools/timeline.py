"""A recorded episode as a timeline: go to any step, look inside it, branch from it, compare.

A :class:`Timeline` is built from a recording (:class:`~rlenv_client.replay.RecordEpisodes`)
and re-simulates it in processes of its own that it starts, owns and ends (never on the server
a trainer uses)::

    from rlenv_tools.timeline import Timeline

    with Timeline.open("episodes/episode-0001.rlenv") as timeline:
        len(timeline)                      # the number of actions
        state = timeline.at(120)           # after the 120th action: observation, reward, info,
        state.draw, state.properties       # the inspector's draw list, every exported property
        timeline.ticks(120)                # each physics tick inside that action
        other = timeline.branch(100, policy=my_policy, max_steps=200)
        timeline.diff(other).first_difference   # 101 or later: where they part
        other.save("episodes/what-if.rlenv")    # rlenv replay re-runs it

Steps are numbered as ``rlenv replay`` numbers them: 0 is the state after the reset, ``k`` the
state after the ``k``-th action. Changes made during the episode (an inspector's property
sets, configuration) belong to the step of the action that follows them. On an unbranched
timeline every observation is the recorded one, bit for bit (its
:func:`~rlenv_client.replay.digest` is checked at every step: an environment that
re-simulates differently raises ``RuntimeError``).

Opening a timeline re-simulates the whole episode once, and on the way parks checkpoints: every
``checkpoint_every`` steps, a copy of the environment's process made by ``fork``
(:mod:`rlenv_tools.forking`), which holds the whole state to the bit. Going to a step copies
the nearest checkpoint at or before it and takes the steps from there (about 5 ms of them at
most); going forward from where the timeline stands just steps on. ``benchmarks/time_travel.py``
measures a step of a 10,000-step episode. Each checkpoint is a process that holds, of its own,
the memory the episode changed since the one before (a few MiB for Plinko); there are at most
256 over an episode, and branches add theirs, within bounds: ``max_processes`` in all (the
episode's checkpoints take at most half, each branch at most half of what is left) and
``max_memory``, past which no more are parked. Every process dies with the timeline's owner
(:mod:`rlenv_tools.forking`'s lifeline). A timeline is not thread-safe, and needs ``os.fork``
(Linux, macOS).

Where agents come and go, or decide at their own pace, each step's observation holds the agents
of that answer (and is checked as such); :meth:`Timeline.agents_in_play`,
:meth:`Timeline.departures` and :meth:`Timeline.agent_returns` say who was in play at each step,
who left, and what each earned.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any, cast

from rlenv.protocol import Hello
from rlenv_client._recorded_parts import as_recorded, driven_agents, split_step
from rlenv_client.replay import EpisodeFile, digest
from rlenv_tools._branch_continuation import Continuation, branch_recording, load_policy
from rlenv_tools._recorded_steps import check_digest, recorded_steps, recorded_target
from rlenv_tools._timeline_agents import AgentHistory, answer_agents
from rlenv_tools._timeline_diff import TimelineDiff, timeline_diff
from rlenv_tools._timeline_processes import (
    WORKING,
    Checkpoints,
    Mark,
    Processes,
    Result,
    measured_spacing,
)
from rlenv_tools._timeline_reads import (
    Step,
    Tick,
    answer_tick,
    read_step,
    read_ticks,
    restored_ticks,
    tick_span,
)
from rlenv_tools.forking import StepRecord

__all__ = ["MAX_MEMORY", "MAX_PROCESSES", "Step", "Tick", "Timeline", "TimelineDiff", "load_policy"]

MAX_PROCESSES = 512
"""A timeline's processes at most, its branches' included (``max_processes``' default)."""
MAX_MEMORY = 2 << 30
"""The memory a timeline's processes hold at most, in bytes (``max_memory``' default)."""


class Timeline:
    """A recorded episode to re-simulate, inspect and branch (see the module docstring).

    Building one re-simulates the whole episode once, checking it against the recording and
    parking the checkpoints (a recording without digests gets them here).

    Args:
        episode: the recording.
        target: the environment to serve (``MODULE:CLASS``; default: the recorded one, imported
            only where it is an installed package, see :mod:`rlenv_client.trusted_targets`).
        trust_target: import the recorded target whatever it is (it runs its code: only for
            recordings you trust).
        checkpoint_every: how many steps apart the checkpoints are (default: as many as take
            about 5 ms to re-simulate, from the cost of the first steps; at most 256
            checkpoints over the episode).
        timeout: seconds a re-simulation may take (a step, a scene read, a branch's run of
            steps) before its process is ended and the call fails.
        max_processes: the most processes the timeline and its branches hold at once (the
            episode's checkpoints take at most half; each branch at most half of what is left).
        max_memory: the most memory (PSS, bytes) they hold: past it, no more checkpoints are
            parked (Linux measures it; elsewhere only ``max_processes`` bounds them).

    Attributes:
        episode: the recording (a branch's: what :meth:`save` writes).
        hello: what the environment says first, as a client of its server sees it (its agents
            and spaces, its ``repeat_action``).

    Raises:
        ValueError: the recording names no target and none is given, or its digests do not
            match its actions.
        UntrustedTargetError: the recorded target is not installed, and neither ``target``
            nor ``trust_target`` is given (a ``ValueError``; the message says both).
        ServerStartError: the environment did not start.
        RuntimeError: the environment re-simulated the recording differently.
    """

    def __init__(
        self,
        episode: EpisodeFile,
        *,
        target: str | None = None,
        trust_target: bool = False,
        checkpoint_every: int | None = None,
        timeout: float = 60.0,
        max_processes: int = MAX_PROCESSES,
        max_memory: int = MAX_MEMORY,
    ) -> None:
        target = recorded_target(episode, target, trust_target)
        if checkpoint_every is not None and checkpoint_every < 1:
            raise ValueError("checkpoint_every must be at least 1")
        if max_processes < 2 * WORKING:
            raise ValueError(f"max_processes must be at least {2 * WORKING}")
        processes = Processes(target, timeout, max_processes, max_memory)
        episode = replace(episode, observations=list(episode.observations))
        try:
            unspaced = Checkpoints(len(episode.snapshot["events"]) + 1, {})  # until measured
            self._setup(episode, processes, True, unspaced, [])
            start = {**episode.snapshot, "events": []}
            processes.driven = driven_agents(episode.snapshot["events"], episode.driven)
            restored, info = processes.first.call("restore", start)
            observation = as_recorded(
                (restored, 0.0, False, False, info), self.hello, processes.driven
            )[0]
            self._starting = answer_agents(observation, self.hello)
            result: Result = (observation, 0.0, False, False, info)
            self._check(0, digest(observation))
            self._checkpoints.keep(0, Mark(processes.first, result))
            self._checkpoints.every = checkpoint_every or measured_spacing(len(self), self._goto)
            self._checkpoints.within(len(self), processes.room())
            self._goto(len(self))
        except BaseException:
            processes.close()
            raise

    @classmethod
    def open(
        cls,
        path: str | Path,
        *,
        target: str | None = None,
        trust_target: bool = False,
        checkpoint_every: int | None = None,
        timeout: float = 60.0,
        max_processes: int = MAX_PROCESSES,
        max_memory: int = MAX_MEMORY,
    ) -> Timeline:
        """The timeline of the recording at ``path`` (see :class:`Timeline` for the rest).

        Raises:
            ValueError: the file is not an rlenv episode, not a regular file, or too large
                (:func:`~rlenv_client.recordings.read_recording`; and as :class:`Timeline`).
        """
        return cls(
            EpisodeFile.load(path),
            target=target,
            trust_target=trust_target,
            checkpoint_every=checkpoint_every,
            timeout=timeout,
            max_processes=max_processes,
            max_memory=max_memory,
        )

    def _setup(
        self,
        episode: EpisodeFile,
        processes: Processes,
        owner: bool,
        checkpoints: Checkpoints,
        records: list[StepRecord],
    ) -> None:
        self.episode = episode
        # A started process has said its hello (ForkedEnvironment.start).
        self.hello = cast(Hello, processes.first.hello)
        self._processes = processes
        self._owner = owner
        self._checkpoints = checkpoints
        self._records = records  # step k's record at k - 1, as each step is first taken
        self._member_histories: dict[str, Any] = {}  # AgentHistory.members' (per group)
        self._steps = recorded_steps(episode)  # each step's events, its action last

    def __len__(self) -> int:
        """The number of actions (the last step's number)."""
        return len(self._steps)

    def frames(self, step: int) -> int:
        """The physics ticks the action of ``step`` asked for (its ``repeat_action``).

        Raises:
            IndexError: no such step (step 0 has no action).
        """
        if not 1 <= step <= len(self):
            raise IndexError(f"step {step} has no action (steps 1 to {len(self)} have)")
        return sum(int(event[2]) for event in split_step(self._steps[step - 1])[1])

    @property
    def ended(self) -> bool:
        """Whether the episode ended at its last step (recordings older than that say so)."""
        return self.episode.terminated is not False or self.episode.truncated is not False

    @property
    def rewards(self) -> list[float]:
        """Every step's reward, 0.0 at step 0 (as the timeline first took them: no re-run)."""
        return [0.0] + [record[1] for record in self._records]

    @property
    def agents(self) -> AgentHistory:
        """Its agents, step by step: in play, departures, returns (agents may come and go)."""
        return AgentHistory(self._starting, self._records, self.hello, self._member_histories)

    @property
    def memory(self) -> int:
        """The memory (PSS, bytes) its processes hold now, its branches' included.

        0 where ``/proc`` does not say.
        """
        return self._processes.used()

    @property
    def processes(self) -> list[int]:
        """The ids of the processes holding the environment and its checkpoints (the root's)."""
        return self._processes.pids()

    def at(self, step: int, *, nodes: Iterable[str] | None = None) -> Step:
        """The state after ``step``, re-simulated.

        Args:
            step: the step.
            nodes: the paths of the nodes whose properties to read (default: every node's;
                reading a few is cheaper on large scenes).

        Raises:
            IndexError: no such step.
            RemoteError: the environment refused a read (no node at one of ``nodes``, a
                ``_draw`` that raised).
            RuntimeError: the timeline is closed, or its environment failed.
        """
        result = self._goto(step)
        return read_step(self._processes.stepping(), step, result, nodes)

    def tree(self, step: int) -> list[dict[str, Any]]:
        """Every node after ``step``, as the inspector's tree lists them (``client.tree()``).

        Each entry has the node's ``path``, ``type``, ``exported`` values and ``read_only``
        names; the environment, agent and world nodes also ``config`` and ``configurable`` (and
        an agent its ``demonstration_keys``).

        Raises:
            IndexError: no such step.
            RuntimeError: as :meth:`at`.
        """
        self._goto(step)
        return self._processes.stepping().call("tree")

    def ticks(self, step: int, *, first: int = 1, count: int | None = None) -> list[Tick]:
        """Physics ticks inside the action of ``step``, re-simulated, a page at a time.

        From tick ``first`` (ticks count from 1), ``count`` of them at most (default: to the
        step's end).

        From the state before the step, the action runs with ``repeat_action=1`` as many times
        as the step ran ticks (on a copy: the timeline's own state is untouched); the ticks
        before ``first`` are only taken, not read, so a page of a long step costs its own
        ticks and a run to them. This is bit for bit the state one step with
        ``repeat_action=N`` reaches when the agent's ``set_action`` only sets what each tick
        uses (CartPole's and Plinko's do: the tests check the last tick against :meth:`at` and
        the rewards' sum); an agent that does something once per action (a jump, a counter)
        would do it at every tick here. Fewer ticks come back where the episode ends.

        Where agents come and go or decide at their own pace, or with a group of agents
        (whose members may join inside a step, with no action until they decide), each tick
        but the last is
        instead the recording's log restored up to it (bit for bit the state after that tick
        of the step, driven agents' decisions inside it included, at the cost of a replay from
        the reset): its observation holds the agents due at that tick and its reward is 0.0
        (each agent's reward is summed until its decision); the last tick is the step's own
        answer (:meth:`at`).

        Raises:
            IndexError: no such step (step 0 has no action), or ``first`` past its ticks.
            ValueError: ``count`` below 1.
            RuntimeError: as :meth:`at`.
        """
        frames = self.frames(step)
        last = tick_span(step, frames, first, count)
        changes, actions = (list(map(list, events)) for events in split_step(self._steps[step - 1]))
        if self.hello.possible_agents is None and not self.hello.groups:
            self._goto(step - 1)
            return read_ticks(self._processes.stepping(), changes, actions[0][1], first, last)
        ticks = []
        if first < frames:
            before = [event for events in self._steps[: step - 1] for event in events]
            ticks = restored_ticks(
                self._processes.stepping(),
                self.episode.snapshot,
                [*before, *changes],
                actions,
                first,
                min(last, frames - 1),
            )
        if last == frames:  # the step's own answer: its observation, rewards and flags
            ticks.append(answer_tick(self.at(step), frames))
        return ticks

    def branch(
        self,
        step: int,
        actions: Iterable[Any] | None = None,
        *,
        policy: Callable[[Any], Any] | str | Path | None = None,
        max_steps: int | None = None,
        repeat_action: int | None = None,
    ) -> Timeline:
        """A timeline sharing this one's first ``step`` steps, then going on differently.

        It continues with ``actions``, or with a policy for at most ``max_steps`` steps, and
        ends early where its episode ends (a branch from a step where this episode ended has no
        more steps). Changes recorded before this timeline's next action are not part of the
        branch. The branch shares its root's processes (its :meth:`close` leaves them to the
        root).

        Args:
            step: the last step both share.
            actions: the branch's actions after ``step``.
            policy: instead of ``actions``, what chooses each action: ``policy(observation) ->
                action``, or the path of an ONNX file
                (:func:`~rlenv_tools.policies.export_onnx`; the ``onnx`` extra).
            max_steps: with ``policy``, the most steps it takes.
            repeat_action: ticks per action; default: the recorded action's at ``step + 1``
                (or the last one), else the server's setting.

        Raises:
            ValueError: not exactly one of ``actions`` and ``policy``, ``policy`` without
                ``max_steps``, or a policy file that cannot be used.
            IndexError: no such step.
            RemoteError: the environment refused an action (nothing of the branch is kept).
            RuntimeError: as :meth:`at`.
        """
        continuation = Continuation.of(actions, policy, max_steps)
        result = self._goto(step)
        if repeat_action is None and self._steps:
            repeat_action = split_step(self._steps[min(step, len(self) - 1)])[1][0][2]
        checkpoints = self._checkpoints.upto(step)
        records = self._records[:step]
        ends = (result[2], result[3])
        if step == len(self) and self.ended:
            ends = (bool(self.episode.terminated), bool(self.episode.truncated))
        processes = self._processes
        result, snapshot = continuation.take(
            processes, step, repeat_action, result, checkpoints, records, ended=any(ends)
        )
        episode = branch_recording(
            self.episode, self._steps, step, snapshot, records, ends, processes.driven
        )
        branch = object.__new__(Timeline)
        branch._setup(episode, processes, False, checkpoints, records)
        branch._starting = self._starting
        processes.position, processes.result = (branch, len(branch)), result
        return branch

    def diff(self, other: Timeline) -> TimelineDiff:
        """How ``other`` differs from this timeline, step by step (both re-simulated)."""
        pair = (self, other)
        return timeline_diff(
            [
                [(each.episode.observations[0], 0.0, False, False, None), *each._records]
                for each in pair
            ],
            [each._every_observation() for each in pair],
            [each.rewards for each in pair],
        )

    def save(self, path: str | Path) -> None:
        """Write this timeline as a recording that ``rlenv replay`` re-runs."""
        self.episode.save(path)

    def close(self) -> None:
        """End the processes (a root timeline's; a branch leaves them to its root)."""
        if self._owner:
            self._processes.close()

    def __enter__(self) -> Timeline:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Timeline({self.episode.target}, {len(self)} steps)"

    def _goto(self, step: int) -> Result:
        """Bring the cursor to ``step`` of this timeline; what that step returned."""
        if not 0 <= step <= len(self):
            raise IndexError(f"no step {step}: the timeline has steps 0 to {len(self)}")
        return self._processes.goto(
            self, step, self._steps, self._checkpoints, self._records, self._check
        )

    def _check(self, step: int, observed: str) -> None:
        check_digest(self.episode, self.hello.agents, step, observed)

    def _every_observation(self) -> list[Any]:
        """Every step's observation, re-simulated from the reset in one run."""
        _, mark = self._checkpoints.nearest(0)
        return self._processes.every_observation(mark, self._steps)
