"""How a timeline's branch goes on after the step it shares with its timeline.

A :class:`Continuation` is the actions given to :meth:`~rlenv_tools.timeline.Timeline.branch`,
or the policy that chooses them for at most ``max_steps`` steps (a callable, or an ONNX file
that :func:`load_policy` loads), checked, and taken on the timeline's processes.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from rlenv_tools._timeline_processes import Checkpoints, Processes, Result
from rlenv_tools.forking import StepRecord

__all__ = ["Continuation", "load_policy"]

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
    ) -> Result:
        """Its steps after ``step`` on the processes' cursor; what the last one returned.

        ``result`` is what ``step`` returned; each step's record is appended to ``records``
        and checkpoints are parked where due. It stops early where the episode ends.
        """
        if self.policy is None:
            steps = [[["action", action, repeat_action]] for action in self.actions or ()]
            return processes.take(step, steps, result, checkpoints, records, None)
        return processes.play(self.policy, self.length, repeat_action, result, checkpoints, records)


def load_policy(path: str | Path) -> Callable[[Any], Any]:
    """``OnnxPolicy(path).act``: a policy file as a branch's policy (loaded once, here).

    Raises:
        ImportError: onnxruntime is missing (the message says to install ``rlenv[onnx]``).
        ValueError: the file is not a policy file (one line naming it).
    """
    from rlenv.serving.onnx_policy import OnnxPolicy

    return OnnxPolicy(path).act
