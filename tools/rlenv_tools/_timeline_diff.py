"""How two timelines differ: where they part, and their observations' and rewards' differences.

:meth:`~rlenv_tools.timeline.Timeline.diff` gives a :class:`TimelineDiff`, from each timeline's
outcomes, observations and rewards step by step (:func:`timeline_diff`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rlenv_client.replay import digest

__all__ = ["TimelineDiff", "timeline_diff"]


@dataclass(frozen=True)
class TimelineDiff:
    """How two timelines differ (:meth:`~rlenv_tools.timeline.Timeline.diff`).

    Attributes:
        first_difference: the first step where the observations (bit for bit) or the rewards
            differ, where one of the two episodes ended (terminated or truncated) and the
            other did not, or that only one of the two reaches; ``None`` when they are the
            same.
        observations: for each step both reach, the other's observation minus this one's
            (float64 arrays; maps and sequences of them for composite observations; of a map
            by agent, the agents both answers hold).
        rewards: for each step both reach, the other's reward minus this one's.
    """

    first_difference: int | None
    observations: list[Any]
    rewards: list[float]


def timeline_diff(
    outcomes: Sequence[Sequence[Any]],
    observations: Sequence[Sequence[Any]],
    rewards: Sequence[Sequence[float]],
) -> TimelineDiff:
    """How the second of two timelines differs from the first.

    Each argument holds the two timelines' steps, from step 0: ``outcomes`` each step's
    observation digest, reward and ends (compared bit for bit), ``observations`` and
    ``rewards`` what is subtracted where both reach.
    """
    first = next(
        (k for k, (a, b) in enumerate(zip(*outcomes, strict=False)) if not _same(a, b)),
        None if len(outcomes[0]) == len(outcomes[1]) else min(map(len, outcomes)),
    )
    mine, theirs = observations
    return TimelineDiff(
        first,
        [_subtract(a, b) for a, b in zip(mine, theirs, strict=False)],
        [b - a for a, b in zip(*rewards, strict=False)],
    )


def _same(mine: Sequence[Any], theirs: Sequence[Any]) -> bool:
    """Whether two steps' outcomes are the same, bit for bit (a group's are arrays)."""
    return digest(list(mine)) == digest(list(theirs))


def _subtract(mine: Any, theirs: Any) -> Any:
    """``theirs - mine`` as float64 arrays, through maps and sequences.

    Of two maps, the keys both hold (agents that come and go: those of both answers).
    """
    if isinstance(mine, Mapping):
        return {key: _subtract(mine[key], theirs[key]) for key in mine if key in theirs}
    if isinstance(mine, (tuple, list)):
        return [_subtract(a, b) for a, b in zip(mine, theirs, strict=True)]
    return np.asarray(theirs, np.float64) - np.asarray(mine, np.float64)
