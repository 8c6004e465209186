"""Scores for a level sampler: how much an agent has left to learn on a level.

Each takes what one episode (or, for :func:`learnability`, the episodes of one level) gave and
returns one float, the ``score`` of :meth:`LevelSampler.insert` and :meth:`LevelSampler.update`.

- :func:`positive_value_loss` (PLR): the mean positive GAE advantage over one episode;
- :func:`max_mc` (Robust PLR, ACCEL): the mean regret against the best return seen on the level;
- :func:`learnability` (SFL): ``p * (1 - p)`` for a success rate ``p``, highest at ``p = 0.5``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["learnability", "max_mc", "positive_value_loss"]


def positive_value_loss(advantages: ArrayLike) -> float:
    """The mean of ``max(a, 0)`` over one episode's GAE advantages.

    Args:
        advantages: the advantage of each step of the episode.

    Raises:
        ValueError: ``advantages`` is empty.
    """
    return float(np.maximum(_episode("advantages", advantages), 0.0).mean())


def max_mc(max_return: float, values: ArrayLike) -> float:
    """The mean of ``max_return - V(s)`` over one episode.

    Args:
        max_return: the highest return reached on this level so far.
        values: the value estimate ``V(s)`` of each state of the episode.

    Raises:
        ValueError: ``values`` is empty.
    """
    return float((max_return - _episode("values", values)).mean())


def learnability(successes: ArrayLike) -> float:
    """``p * (1 - p)``, where ``p`` is the mean of one level's outcomes.

    Args:
        successes: one outcome per episode on the level, 1 (or True) for a success, 0 otherwise.

    Raises:
        ValueError: ``successes`` is empty or holds a value other than 0 and 1.
    """
    outcomes = _episode("successes", successes)
    if not np.isin(outcomes, (0.0, 1.0)).all():
        raise ValueError("successes must hold 0 or 1 for each episode")
    p = outcomes.mean()
    return float(p * (1.0 - p))


def _episode(name: str, values: ArrayLike) -> np.ndarray:
    array = np.asarray(values, dtype=np.float64).ravel()
    if array.size == 0:
        raise ValueError(f"{name} is empty: a score needs at least one value")
    return array
