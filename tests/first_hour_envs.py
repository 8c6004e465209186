"""Environments a new user writes in their first hour, with the mistakes they make.

Served as ``first_hour_envs:...`` with ``tests/`` on ``PYTHONPATH``.

- :class:`LanderEnvironment`: a lander whose ``_get_info`` reads the episode's state (which does
  not exist before the first reset), whose world has two settings that its own ``configure``
  applies one after the other (and refuses ``wind`` 13 half way, after ``gravity`` changed),
  and whose agent, given action 1, puts a bin map key in ``info``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv import RLAgent, RLEnvironment, RLEnvWorld


class LanderWorld(RLEnvWorld):
    """Gravity and wind; the lander's height and speed exist once an episode began."""

    configurable = ("gravity", "wind")

    def __init__(self) -> None:
        super().__init__("World")
        self.gravity = -1.0
        self.wind = 0.0
        self.height: float | None = None
        self.speed = 0.0

    def configure(self, config: Mapping[str, Any]) -> None:
        """Apply each setting in turn; ``wind`` 13 is refused after the others were set."""
        for key, value in config.items():
            if key == "wind" and value == 13:
                raise ValueError("unlucky wind")
            super().configure({key: value})

    def reset(self, options: Mapping[str, Any]) -> None:
        """Start 10 units up, at rest."""
        self.height, self.speed = 10.0, 0.0

    def _physics_process(self, delta: float) -> None:
        assert self.height is not None
        self.speed += (self.gravity + self.environment.agent.thrust) * delta
        self.height += self.speed * delta


class LanderAgent(RLAgent):
    """Thrusts 0 or 2 (action 0 or 2); action 1 puts a bin key in ``info``."""

    action_space = spaces.Discrete(3)
    observation_space = spaces.Box(-1e6, 1e6, (2,), np.float32)

    def __init__(self) -> None:
        super().__init__("Agent")
        self.thrust = 0.0
        self.odd_info = False

    def reset(self, arguments: Any) -> None:
        """No thrust."""
        self.thrust, self.odd_info = 0.0, False

    def set_action(self, action: Any) -> None:
        """Thrust, or the odd ``info``."""
        self.thrust = float(action)
        self.odd_info = action == 1

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Height and speed."""
        world = self.environment.world
        return np.array([world.height, world.speed], np.float32)


class LanderEnvironment(RLEnvironment):
    """See the module docstring."""

    def __init__(self) -> None:
        super().__init__("Lander", repeat_action=2)
        self.add_child(LanderAgent())
        self.add_child(LanderWorld())

    def _get_info(self) -> dict[Any, Any]:
        world = self.world
        info: dict[Any, Any] = {"height": round(world.height, 3)}  # fails before any reset
        if self.agent.odd_info:
            info[b"raw"] = 1
        return info
