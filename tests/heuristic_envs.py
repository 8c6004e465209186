"""Environments whose agents have heuristics (``rlenv serve heuristic_envs:...``).

``ChasingPair`` is examples.pair with a heuristic for Blue only (the seeker's greedy push), so
that a heuristic drives one agent and Red has none. ``HeuristicSeeker`` is the seeker with
one. ``WrongHeuristicPair`` gives Blue a heuristic that answers outside its action space.
``TimedChasingPair`` is ChasingPair whose episodes are cut short after 40 steps (for
demonstrations, which record an episode when it ends).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from examples.pair import PairAgent, PairEnvironment, PairWorld, chase
from examples.seeker import SeekerAgent, SeekerEnvironment, SeekerWorld, greedy
from rlenv import RLEnvironment


class ChasingPairAgent(PairAgent):
    """A pair agent that pushes towards its apple when a heuristic drives it."""

    def heuristic(self, observation: np.ndarray) -> np.ndarray:
        """The greedy push (examples.pair's ``chase``)."""
        return chase(observation)


class WrongPairAgent(PairAgent):
    """A pair agent whose heuristic gives three numbers, not the two of its action space."""

    def heuristic(self, observation: np.ndarray) -> Any:
        """Not an action of the agent's space."""
        return np.zeros(3, np.float32)


class ChasingPair(PairEnvironment):
    """Red (PairAgent, no heuristic) and Blue (ChasingPairAgent)."""

    blue = ChasingPairAgent

    def __init__(self) -> None:
        RLEnvironment.__init__(self, "Pair", repeat_action=4)
        self.add_child(PairAgent("Red"))
        self.add_child(self.blue("Blue"))
        self.add_child(PairWorld())


class WrongHeuristicPair(ChasingPair):
    """Blue's heuristic answers outside its space."""

    blue = WrongPairAgent


class HeuristicSeekerAgent(SeekerAgent):
    """The seeker with its greedy push as a heuristic."""

    def heuristic(self, observation: np.ndarray) -> np.ndarray:
        """Push towards the apple."""
        return greedy(observation)


class HeuristicSeeker(SeekerEnvironment):
    """The seeker whose agent has a heuristic."""

    def __init__(self) -> None:
        RLEnvironment.__init__(self, "Seeker", repeat_action=4)
        self.add_child(HeuristicSeekerAgent())
        self.add_child(SeekerWorld())


class TimedPairAgent(PairAgent):
    """A pair agent whose episode is cut short after 160 ticks (40 steps)."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.ticks = 0

    def _after_physics_tick(self, delta: float) -> None:
        super()._after_physics_tick(delta)
        self.ticks += 1
        if self.ticks >= 160 and not self.terminated:
            self.set_truncated()

    def reset(self, arguments: np.ndarray) -> None:
        """As the pair's, and the clock starts again."""
        super().reset(arguments)
        self.ticks = 0


class TimedChasingAgent(TimedPairAgent, ChasingPairAgent):
    """Timed, with the greedy heuristic."""


class TimedChasingPair(ChasingPair):
    """Red (no heuristic) and Blue (a heuristic), both cut short after 40 steps."""

    blue = TimedChasingAgent

    def __init__(self) -> None:
        RLEnvironment.__init__(self, "Pair", repeat_action=4)
        self.add_child(TimedPairAgent("Red"))
        self.add_child(self.blue("Blue"))
        self.add_child(PairWorld())
