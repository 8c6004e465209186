"""Environments for ``rlenv check``'s own tests (``rlenv check check_envs:...``).

Served with ``tests/`` on ``PYTHONPATH``:

- :class:`TupleEnvironment`: one agent whose observation is a ``Tuple`` (a number and a 2x2
  array), which SB3 cannot read, so its check is skipped; its actions' ``Box`` is not
  normalized, so gymnasium's checker warns (in colour: gymnasium colours its warnings);
- :class:`DriftingPairEnvironment`: two agents; Blue's observation counts the episodes begun
  (never reset: the bug), so a seeded reset is not reproducible, in Blue's member only.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from examples.faulty import CountingWorld
from rlenv.agent import RLAgent
from rlenv.environment import RLEnvironment

__all__ = ["DriftingPairEnvironment", "TupleEnvironment"]


class _CountingAgent(RLAgent):
    """Acts on nothing; sees the ticks of the counting world."""

    action_space = spaces.Discrete(3)

    def set_action(self, action: Any) -> None:
        """Actions change nothing."""

    @property
    def ticks(self) -> int:
        """The ticks since the reset."""
        world = self.environment.world
        assert isinstance(world, CountingWorld)
        return world.ticks


class _TupleAgent(_CountingAgent):
    action_space = spaces.Box(-2.0, 2.0, (1,), np.float32)  # not normalized: gymnasium warns
    observation_space = spaces.Tuple(
        (spaces.Discrete(4), spaces.Box(-1.0, 1.0, (2, 2), np.float32))
    )

    def get_data(self, observation_request: Mapping[str, Any]) -> tuple[int, np.ndarray]:
        """The ticks modulo 4, and a 2x2 array of their fraction of 100."""
        return self.ticks % 4, np.full((2, 2), min(self.ticks / 100, 1.0), np.float32)


class TupleEnvironment(RLEnvironment):
    """One agent with a ``Tuple`` observation."""

    def __init__(self) -> None:
        super().__init__("Tuple", repeat_action=2)
        self.add_child(_TupleAgent("Agent"))
        self.add_child(CountingWorld())


class _DriftingAgent(_CountingAgent):
    """Sees the episodes begun (if it ``drifts``: never reset) and the ticks."""

    observation_space = spaces.Box(0.0, 1e9, (2,), np.float64)

    def __init__(self, name: str, drifts: bool) -> None:
        super().__init__(name)
        self.drifts = drifts
        self.episodes = 0

    def reset(self, arguments: Any) -> None:
        """Count one more episode (the drifting one keeps counting across resets)."""
        self.episodes = self.episodes + 1 if self.drifts else 1

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Episodes begun, and ticks."""
        return np.array([self.episodes, self.ticks], np.float64)


class DriftingPairEnvironment(RLEnvironment):
    """Red is reproducible, Blue is not."""

    def __init__(self) -> None:
        super().__init__("DriftingPair", repeat_action=2)
        self.add_child(_DriftingAgent("Red", drifts=False))
        self.add_child(_DriftingAgent("Blue", drifts=True))
        self.add_child(CountingWorld())
