"""How a timeline's branch goes on after the step it shares with its timeline.

A :class:`Continuation` is the actions given to :meth:`~rlenv_tools.timeline.Timeline.branch`,
or the policy that chooses them for at most ``max_steps`` steps (a callable, or an ONNX file
that :func:`load_policy` loads), checked, and taken on the timeline's processes;
:func:`branch_recording` is the branch's recording, its shared steps as its timeline's.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from rlenv.protocol.errors import RemoteError
from rlenv_client.replay import EpisodeFile
from rlenv_tools._timeline_processes import Checkpoints, Events, Processes, Result
from rlenv_tools.forking import StepRecord

__all__ = ["Continuation", "branch_recording", "load_policy"]

Policy = Callable[[Any], Any]


@dataclass(frozen=True)
class Continuation:
    """A branch's steps after its step: ``actions``, or ``policy``'s for ``max_steps`` at most.

    Attributes:
        actions: the actions, in order (``None`` with a policy).
        policy: what chooses each action, ``policy(observation) -> action`` (``None`` with
            actions).
        max_steps: with ``policy``, the most steps it takes.
    """

    actions: list[Any] | None
    policy: Policy | None
    max_steps: int | None

    @classmethod
    def of(
        cls,
        actions: Iterable[Any] | None,
        policy: Policy | str | Path | None,
        max_steps: int | None,
    ) -> Continuation:
        """The continuation :meth:`~rlenv_tools.timeline.Timeline.branch`'s arguments ask for.

        Raises:
            ValueError: not exactly one of ``actions`` and ``policy``, ``policy`` without
                ``max_steps``, or a policy file that cannot be used.
            ImportError: a policy file, without onnxruntime.
        """
        if (actions is None) == (policy is None):
            raise ValueError("branch needs actions or a policy (one of them)")
        if policy is not None and max_steps is None:
            raise ValueError("a policy needs max_steps")
        if isinstance(policy, (str, Path)):
            policy = load_policy(policy)
        return cls(None if actions is None else list(actions), policy, max_steps)

    @property
    def length(self) -> int:
        """The most steps it takes."""
        return len(self.actions) if self.actions is not None else cast(int, self.max_steps)

    def take(
        self,
        processes: Processes,
        step: int,
        repeat_action: int | None,
        result: Result,
        checkpoints: Checkpoints,
        records: list[StepRecord],
        *,
        ended: bool,
    ) -> tuple[Result, dict[str, Any]]:
        """Its steps after ``step`` on the processes' cursor, which leaves its timeline.

        ``result`` is what ``step`` returned; each step's record is appended to ``records``
        and checkpoints are parked where due (half the processes' room, at most). It stops
        early where the episode ends, and takes no step where it ``ended`` at ``step``.

        Returns:
            What the last step returned, and the cursor's snapshot after it.

        Raises:
            RemoteError: the environment refused an action (the cursor, which took part of
                the branch, is ended).
            RuntimeError: the environment failed.
        """
        checkpoints.within(self.length, processes.room())
        cursor = processes.stepping()
        processes.position = None  # the cursor leaves its timeline
        try:
            if ended:
                pass  # no step where the episode ended at ``step``
            elif self.policy is None:
                steps = [[["action", action, repeat_action]] for action in self.actions or ()]
                result = processes.take(step, steps, result, checkpoints, records, None)
            else:
                result = processes.play(
                    self.policy, self.length, repeat_action, result, checkpoints, records
                )
            return result, cursor.call("snapshot")
        except ConnectionError as error:
            raise RuntimeError(f"the timeline's environment failed: {error}") from None
        except RemoteError:
            processes.drop_cursor()  # it took part of the branch
            raise


def branch_recording(
    episode: EpisodeFile,
    steps: Events,
    step: int,
    snapshot: dict[str, Any],
    records: list[StepRecord],
    ends: tuple[bool, bool],
    driven: frozenset[str],
) -> EpisodeFile:
    """The recording of a branch from ``step`` of the timeline of ``episode`` (its ``steps``).

    ``snapshot`` is the branch's cursor's after its last step, ``records`` each of its steps'
    (the shared ones first), ``ends`` its flags at ``step``, ``driven`` the agents its server
    drove. The first ``step`` steps' events are the timeline's own, one for each of the
    branch's: where the branch's server took a step whose driven agents decided during it part
    by part, it logged each part as an action of its own, and the recording's events say it as
    one step (``rlenv_client._recorded_parts``).
    """
    shared = [event for events in steps[:step] for event in events]
    events = [*shared, *snapshot["events"][len(shared) :]]
    digests = episode.observations[: step + 1] + [record[0] for record in records[step:]]
    terminated, truncated = records[-1][2:4] if len(records) > step else ends
    return EpisodeFile(
        episode.target,
        {**snapshot, "events": events},
        digests,
        terminated,
        truncated,
        driven=sorted(driven) or None,
    )


def load_policy(path: str | Path) -> Callable[[Any], Any]:
    """``OnnxPolicy(path).act``: a policy file as a branch's policy (loaded once, here).

    Raises:
        ImportError: onnxruntime is missing (the message says to install ``rlenv[onnx]``).
        ValueError: the file is not a policy file (one line naming it).
    """
    from rlenv.serving.onnx_policy import OnnxPolicy

    return OnnxPolicy(path).act
