"""Environments made for tests: they misbehave on purpose."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv.agent import RLAgent
from rlenv.environment import RLEnvironment
from rlenv.world import RLEnvWorld


class CountingWorld(RLEnvWorld):
    """No physics: counts the physics ticks it processed since the reset."""

    def __init__(self) -> None:
        super().__init__("World")
        self.ticks = 0

    def reset(self, options: Mapping[str, Any]) -> None:
        self.ticks = 0

    def _physics_process(self, delta: float) -> None:
        self.ticks += 1

    def get_data(self, observation_request: Mapping[str, Any]) -> dict[str, Any]:
        return {"ticks": self.ticks}


class FaultyAgent(RLAgent):
    """Raises inside the tick for action 1, inside get_data for action 2; ends at tick 10."""

    action_space = spaces.Discrete(3)
    observation_space = spaces.Box(0, 1000, (1,), np.int64)

    def __init__(self) -> None:
        super().__init__("Agent")
        self.action = 0

    def reset(self, arguments: Any) -> None:
        self.action = 0

    def set_action(self, action: Any) -> None:
        self.action = int(action)

    def _physics_process(self, delta: float) -> None:
        if self.action == 1:
            raise RuntimeError("the agent tripped over action 1")

    def _after_physics_tick(self, delta: float) -> None:
        self.add_reward(0.5)
        world = self.environment.world
        assert isinstance(world, CountingWorld)
        if world.ticks >= 10:
            self.set_terminated()

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        if self.action == 2:
            raise ValueError("no observation for action 2")
        world = self.environment.world
        assert isinstance(world, CountingWorld)
        return np.array([world.ticks], dtype=np.int64)


class FaultyEnvironment(RLEnvironment):
    """A counting world and an agent that raises on demand."""

    def __init__(self) -> None:
        super().__init__("Faulty", repeat_action=3)
        self.add_child(FaultyAgent())
        self.add_child(CountingWorld())


class WrongShapeAgent(FaultyAgent):
    """Declares a 1-element observation and returns 2 elements."""

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        return np.zeros(2, dtype=np.int64)


class WrongShapeEnvironment(RLEnvironment):
    """An environment whose observations do not match its observation space."""

    def __init__(self) -> None:
        super().__init__("WrongShape")
        self.add_child(WrongShapeAgent())
        self.add_child(CountingWorld())
