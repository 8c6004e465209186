"""Environments whose agents end their episodes in different ways (``tests/test_episode_ends.py``).

Served as ``episode_end_envs:...`` with ``tests/`` on ``PYTHONPATH``. Each agent is a Pair
seeker (:mod:`examples.pair`) that is truncated after :attr:`TimedAgent.limit` physics ticks
of its episode unless it caught its apple first, as a per-agent time-out in a game would: a
chaser that catches terminates, one that stands still times out.
"""

from __future__ import annotations

import numpy as np

from examples.pair import PairAgent, PairEnvironment, PairWorld
from rlenv.environment import RLEnvironment

__all__ = ["TimedAgent", "TimedPair", "TimedSolo"]


class TimedAgent(PairAgent):
    """A Pair seeker truncated after ``limit`` physics ticks, unless it terminated first."""

    limit = 240
    """Physics ticks of an episode (60 steps of 4 ticks)."""

    def reset(self, arguments: np.ndarray) -> None:
        """Put the disc at the sampled spot; the clock of its time-out starts again."""
        super().reset(arguments)
        self._ticks = 0

    def _after_physics_tick(self, delta: float) -> None:
        super()._after_physics_tick(delta)
        self._ticks += 1
        if self._ticks >= self.limit and not self.terminated:
            self.set_truncated()


class TimedPair(PairEnvironment):
    """Red and Blue, each timed (``TimedAgent``)."""

    def __init__(self) -> None:
        RLEnvironment.__init__(self, "TimedPair", repeat_action=4)
        for name in ("Red", "Blue"):
            self.add_child(TimedAgent(name))
        self.add_child(PairWorld())


class TimedSolo(PairEnvironment):
    """Red alone (one agent: plain spaces), timed; Blue's disc stays where it was built."""

    def __init__(self) -> None:
        RLEnvironment.__init__(self, "TimedSolo", repeat_action=4)
        self.add_child(TimedAgent("Red"))
        self.add_child(PairWorld())
