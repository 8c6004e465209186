"""A recorded episode as a timeline: go to any step, look inside it, branch from it, compare.

A :class:`Timeline` is built from a recording (:class:`~rlenv_client.replay.RecordEpisodes`)
and re-simulates it on a scratch server of the recording's environment that it starts, owns and
closes (never on the server a trainer uses)::

    from rlenv_client.timeline import Timeline

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
:func:`~rlenv_client.replay.digest` is checked at every step: a server that re-simulates
differently raises ``RuntimeError``).

Going to a step restores the nearest earlier checkpoint (a snapshot taken every
``checkpoint_every`` steps as the timeline passes them, the reset's at first) and replays the
actions from there; going forward from where the scratch server stands just steps on.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rlenv_client.client import Client
from rlenv_client.launcher import ServerProcess
from rlenv_client.replay import EpisodeFile, digest

__all__ = ["Step", "Tick", "Timeline", "TimelineDiff"]

_END = object()  # the end of a branch's actions
_Result = tuple[Any, float, bool, bool, dict[str, Any]]  # observation, reward, ends, info


@dataclass(frozen=True)
class Step:
    """The state after a step (:meth:`Timeline.at`).

    Attributes:
        step: its number (0: after the reset).
        observation: the agent's observation, as the recording saw it.
        reward: the step's reward (0.0 at step 0).
        terminated: whether the episode terminated at this step.
        truncated: whether the episode was truncated at this step.
        info: the step's info (the reset's at step 0).
        draw: the scene as the inspector's vector draw list (``client.draw()``).
        properties: every node's exported properties, by node path (the inspect tree's).
    """

    step: int
    observation: Any
    reward: float
    terminated: bool
    truncated: bool
    info: dict[str, Any]
    draw: dict[str, Any]
    properties: dict[str, dict[str, Any]]


@dataclass(frozen=True)
class Tick:
    """The state after one physics tick inside a step's action (:meth:`Timeline.ticks`).

    Attributes:
        tick: its number inside the action, from 1.
        observation: the agent's observation after the tick.
        reward: the tick's reward.
        terminated: whether the episode terminated at this tick.
        truncated: whether the episode was truncated at this tick.
        info: the tick's info.
        properties: every node's exported properties, by node path.
    """

    tick: int
    observation: Any
    reward: float
    terminated: bool
    truncated: bool
    info: dict[str, Any]
    properties: dict[str, dict[str, Any]]


@dataclass(frozen=True)
class TimelineDiff:
    """How two timelines differ (:meth:`Timeline.diff`).

    Attributes:
        first_difference: the first step where the observations (bit for bit) or the rewards
            differ, or that only one of the two reaches; ``None`` when they are the same.
        observations: for each step both reach, the other's observation minus this one's
            (float64 arrays; maps and sequences of them for composite observations).
        rewards: for each step both reach, the other's reward minus this one's.
    """

    first_difference: int | None
    observations: list[Any]
    rewards: list[float]


@dataclass(frozen=True)
class _Mark:
    """A checkpoint: the snapshot at a step and what that step returned."""

    snapshot: dict[str, Any]
    reward: float
    terminated: bool
    truncated: bool
    info: dict[str, Any]


class _Checkpoints:
    """Snapshots taken every ``every`` steps as a timeline passes them (the reset's at 0).

    Going to step ``k`` restores the nearest one at or before ``k`` and replays at most
    ``every - 1`` actions. Kept small and private so that faster checkpoints can replace it.
    """

    def __init__(self, every: int, marks: Mapping[int, _Mark]) -> None:
        self.every = every
        self._marks = dict(marks)

    def due(self, step: int) -> bool:
        """Whether a snapshot should be taken on reaching ``step``."""
        return step % self.every == 0 and step not in self._marks

    def keep(self, step: int, mark: _Mark) -> None:
        """Remember ``mark`` as the checkpoint at ``step``."""
        self._marks[step] = mark

    def nearest(self, step: int) -> tuple[int, _Mark]:
        """The checkpoint at ``step`` or the latest before it."""
        best = max(k for k in self._marks if k <= step)
        return best, self._marks[best]

    def upto(self, step: int) -> _Checkpoints:
        """A copy holding the checkpoints at ``step`` and before (a branch's shared part)."""
        return _Checkpoints(self.every, {k: m for k, m in self._marks.items() if k <= step})


class _Scratch:
    """The scratch server a root timeline owns, its client, and where its episode stands."""

    def __init__(self, target: str, server_args: Iterable[str]) -> None:
        self.server = ServerProcess(target, args=tuple(server_args))
        try:
            self.client = Client(self.server.host, self.server.port, timeout=120.0)
        except BaseException:
            self.server.close()
            raise
        self.position: tuple[Timeline, int] | None = None
        self.result: _Result | None = None
        self.closed = False

    def close(self) -> None:
        """Close the client and end the server."""
        if not self.closed:
            self.closed = True
            self.position = self.result = None
            self.client.close()
            self.server.close()


class Timeline:
    """A recorded episode to re-simulate, inspect and branch (see the module docstring).

    Args:
        episode: the recording.
        target: the environment to serve (``MODULE:CLASS``; default: the recorded one).
        checkpoint_every: how many steps apart the checkpoints are.
        server_args: extra arguments for the scratch server's ``rlenv serve``.

    Attributes:
        episode: the recording (a branch's: what :meth:`save` writes).
        server: the scratch server (a branch shares its root's).

    Raises:
        ValueError: the recording names no target and none is given, or its digests do not
            match its actions.
        ServerStartError: the scratch server did not start.
    """

    def __init__(self, episode: EpisodeFile, *, target: str | None = None,
                 checkpoint_every: int = 100, server_args: Iterable[str] = ()) -> None:
        target = target or episode.target
        if target is None:
            raise ValueError("the recording names no target: pass target='MODULE:CLASS'")
        if checkpoint_every < 1:
            raise ValueError("checkpoint_every must be at least 1")
        start = {**episode.snapshot, "events": []}
        scratch = _Scratch(target, server_args)
        try:
            observation, info = scratch.client.restore(start)
        except BaseException:
            scratch.close()
            raise
        marks = {0: _Mark(start, 0.0, False, False, info)}
        self._setup(episode, scratch, True, _Checkpoints(checkpoint_every, marks))
        scratch.position, scratch.result = (self, 0), (observation, 0.0, False, False, info)

    @classmethod
    def open(cls, path: str | Path, *, target: str | None = None, checkpoint_every: int = 100,
             server_args: Iterable[str] = ()) -> Timeline:
        """The timeline of the recording at ``path`` (see :class:`Timeline` for the rest).

        Raises:
            ValueError: the file is not an rlenv episode (and as :class:`Timeline`).
        """
        return cls(EpisodeFile.load(path), target=target, checkpoint_every=checkpoint_every,
                   server_args=server_args)

    def _setup(self, episode: EpisodeFile, scratch: _Scratch, owner: bool,
               checkpoints: _Checkpoints) -> None:
        self.episode = episode
        self.server = scratch.server
        self._scratch = scratch
        self._owner = owner
        self._checkpoints = checkpoints
        self._steps: list[list[list[Any]]] = []  # each step's events, its action last
        pending: list[list[Any]] = []
        for event in episode.snapshot["events"]:
            pending.append(event)
            if event[0] == "action":
                self._steps.append(pending)
                pending = []
        if len(episode.observations) != len(self._steps) + 1:
            raise ValueError(f"the recording has {len(episode.observations)} observations for "
                             f"{len(self._steps)} actions (one more expected)")

    def __len__(self) -> int:
        """The number of actions (the last step's number)."""
        return len(self._steps)

    @property
    def ended(self) -> bool:
        """Whether the episode ended at its last step (recordings older than that say so)."""
        return self.episode.terminated is not False or self.episode.truncated is not False

    def at(self, step: int) -> Step:
        """The state after ``step``, re-simulated on the scratch server.

        Raises:
            IndexError: no such step.
            RuntimeError: the scratch server re-simulated the step differently, or is closed.
        """
        observation, reward, terminated, truncated, info = self._goto(step)
        client = self._scratch.client
        properties = {node["path"]: dict(node["exported"]) for node in client.tree()}
        return Step(step, copy.deepcopy(observation), reward, terminated, truncated,
                    copy.deepcopy(info), client.draw(), properties)

    def ticks(self, step: int) -> list[Tick]:
        """Each physics tick inside the action of ``step`` (from 1), re-simulated.

        From the state before the step, the action runs with ``repeat_action=1`` as many times
        as the step ran ticks. This is bit for bit the state one step with ``repeat_action=N``
        reaches when the agent's ``set_action`` only sets what each tick uses (CartPole's and
        Plinko's do: the tests check the last tick against :meth:`at` and the rewards' sum);
        an agent that does something once per action (a jump, a counter) would do it at every
        tick here.

        Raises:
            IndexError: no such step (step 0 has no action).
            RuntimeError: as :meth:`at`.
        """
        if not 1 <= step <= len(self):
            raise IndexError(f"step {step} has no action (steps 1 to {len(self)} have)")
        self._goto(step - 1)
        scratch = self._scratch
        scratch.position = scratch.result = None  # the log now holds single ticks
        *changes, (_, action, frames) = self._steps[step - 1]
        self._apply(changes)
        ticks = []
        for tick in range(1, frames + 1):
            observation, reward, terminated, truncated, info = scratch.client.step(action, 1)
            properties = {node["path"]: dict(node["exported"]) for node in scratch.client.tree()}
            ticks.append(Tick(tick, observation, float(reward), bool(terminated),
                              bool(truncated), info, properties))
            if terminated or truncated:
                break
        return ticks

    def branch(self, step: int, actions: Iterable[Any] | None = None, *,
               policy: Callable[[Any], Any] | None = None, max_steps: int | None = None,
               repeat_action: int | None = None) -> Timeline:
        """A timeline sharing this one's first ``step`` steps, then going on differently.

        It continues with ``actions``, or with ``policy(observation) -> action`` for at most
        ``max_steps`` steps, and ends early where its episode ends (a branch from a step where
        this episode ended has no more steps). Changes recorded before this timeline's next
        action are not part of the branch. The branch shares the scratch server (its
        :meth:`close` leaves it to this timeline's root).

        Args:
            step: the last step both share.
            actions: the branch's actions after ``step``.
            policy: instead of ``actions``, what chooses each action from the observation.
            max_steps: with ``policy``, the most steps it takes.
            repeat_action: ticks per action; default: the recorded action's at ``step + 1``
                (or the last one), else the server's setting.

        Raises:
            ValueError: not exactly one of ``actions`` and ``policy``, or ``policy`` without
                ``max_steps``.
            IndexError: no such step.
            RuntimeError: as :meth:`at`.
        """
        if (actions is None) == (policy is None):
            raise ValueError("branch needs actions or a policy (one of them)")
        if policy is not None and max_steps is None:
            raise ValueError("a policy needs max_steps")
        result = self._goto(step)
        if repeat_action is None and self._steps:
            repeat_action = self._steps[min(step, len(self) - 1)][-1][2]
        checkpoints = self._checkpoints.upto(step)
        digests = self.episode.observations[:step + 1]
        terminated, truncated = result[2], result[3]
        if step == len(self) and self.ended:
            terminated, truncated = bool(self.episode.terminated), bool(self.episode.truncated)
        chosen = None if actions is None else iter(actions)
        client = self._scratch.client
        taken = 0
        while not (terminated or truncated):
            if chosen is None:
                if taken >= max_steps:  # type: ignore[operator]
                    break
                action = policy(result[0])  # type: ignore[misc]
            else:
                action = next(chosen, _END)
                if action is _END:
                    break
            observation, reward, terminated, truncated, info = client.step(action, repeat_action)
            result = (observation, float(reward), bool(terminated), bool(truncated), info)
            digests.append(digest(observation))
            taken += 1
            if checkpoints.due(step + taken):
                checkpoints.keep(step + taken, _Mark(client.snapshot(), *result[1:]))
        episode = EpisodeFile(self.episode.target, client.snapshot(), digests,
                              bool(terminated), bool(truncated))
        branch = object.__new__(Timeline)
        branch._setup(episode, self._scratch, False, checkpoints)
        self._scratch.position, self._scratch.result = (branch, len(branch)), result
        return branch

    def diff(self, other: Timeline) -> TimelineDiff:
        """How ``other`` differs from this timeline, step by step (both re-simulated)."""
        mine = [self._goto(k)[:2] for k in range(len(self) + 1)]
        theirs = [other._goto(k)[:2] for k in range(len(other) + 1)]
        first = None
        for k in range(max(len(mine), len(theirs))):
            if k >= len(mine) or k >= len(theirs) or mine[k][1] != theirs[k][1] or \
                    digest(mine[k][0]) != digest(theirs[k][0]):
                first = k
                break
        common = zip(mine, theirs, strict=False)
        return TimelineDiff(first, [_subtract(a[0], b[0]) for a, b in common],
                            [float(b[1]) - float(a[1]) for a, b in zip(mine, theirs,
                                                                       strict=False)])

    def save(self, path: str | Path) -> None:
        """Write this timeline as a recording that ``rlenv replay`` re-runs."""
        self.episode.save(path)

    def close(self) -> None:
        """End the scratch server (a root timeline's; a branch leaves it to its root)."""
        if self._owner:
            self._scratch.close()

    def __enter__(self) -> Timeline:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Timeline({self.episode.target}, {len(self)} steps)"

    def _goto(self, step: int) -> _Result:
        """Bring the scratch server to ``step`` of this timeline; what that step returned."""
        if not 0 <= step <= len(self):
            raise IndexError(f"no step {step}: the timeline has steps 0 to {len(self)}")
        scratch = self._scratch
        if scratch.closed:
            raise RuntimeError("the timeline's scratch server is closed")
        base, mark = self._checkpoints.nearest(step)
        position = scratch.position
        if position is not None and position[0] is self and base <= position[1] <= step:
            base, result = position[1], scratch.result
        else:
            scratch.position = None
            observation, _ = scratch.client.restore(mark.snapshot)
            result = (observation, mark.reward, mark.terminated, mark.truncated, mark.info)
            self._check(base, observation)
        for k in range(base + 1, step + 1):
            *changes, (_, action, frames) = self._steps[k - 1]
            self._apply(changes)
            observation, reward, terminated, truncated, info = scratch.client.step(action, frames)
            result = (observation, float(reward), bool(terminated), bool(truncated), info)
            self._check(k, observation)
            if self._checkpoints.due(k):
                self._checkpoints.keep(k, _Mark(scratch.client.snapshot(), *result[1:]))
        scratch.position, scratch.result = (self, step), result
        assert result is not None
        return result

    def _apply(self, changes: list[list[Any]]) -> None:
        """Apply the configuration and property changes recorded before an action."""
        client = self._scratch.client
        for event in changes:
            if event[0] == "config":
                part = event[1]
                settings = {k: v for k, v in part.get("environment", {}).items() if k != "record"}
                client.configure(agent=part.get("agent"), world=part.get("world"), **settings)
            else:  # ["set", path, property, value]
                client.set_property(*event[1:])

    def _check(self, step: int, observation: Any) -> None:
        if digest(observation) != self.episode.observations[step]:
            raise RuntimeError(f"step {step}: the scratch server's observation differs from the "
                               "recording (the environment is not deterministic here)")


def _subtract(mine: Any, theirs: Any) -> Any:
    """``theirs - mine`` as float64 arrays, through maps and sequences."""
    if isinstance(mine, Mapping):
        return {key: _subtract(mine[key], theirs[key]) for key in mine}
    if isinstance(mine, (tuple, list)):
        return [_subtract(a, b) for a, b in zip(mine, theirs, strict=True)]
    return np.asarray(theirs, np.float64) - np.asarray(mine, np.float64)
