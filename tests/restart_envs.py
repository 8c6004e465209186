"""An environment for the tests of exact restarts (``rlenv serve restart_envs:DroppedBall``)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv import (
    CollisionShape,
    PhysicsWorld,
    RigidBody,
    RLAgent,
    RLEnvironment,
    RLEnvWorld,
    StaticBody,
)


class DropWorld(RLEnvWorld):
    """A ball above a floor, in a physics world built once and restarted at every reset.

    ``slop`` (configurable) is the space's ``collision_slop``: at 0 the solver pushes a
    resting ball out of the floor at every step.
    """

    configurable = ("slop",)

    def __init__(self) -> None:
        super().__init__("World")
        self.physics = PhysicsWorld(gravity=(0.0, -9.81), name="Physics")
        floor = StaticBody(name="Floor")
        floor.add_child(
            CollisionShape.segment((-10.0, 0.0), (10.0, 0.0), 0.1, name="Line", elasticity=0.3)
        )
        self.ball = RigidBody(position=(0.0, 1.0), name="Ball")
        self.ball.add_child(CollisionShape.circle(0.2, mass=1.0, elasticity=0.3, name="Skin"))
        self.physics.add_child(floor)
        self.physics.add_child(self.ball)
        self.add_child(self.physics)

    @property
    def slop(self) -> float:
        """The space's collision slop."""
        return self.physics.space.collision_slop

    @slop.setter
    def slop(self, value: float) -> None:
        self.physics.space.collision_slop = value

    def reset(self, options: Mapping[str, Any]) -> None:
        """Start the physics afresh, the ball dropped from a seeded height."""
        self.physics.restart()
        self.ball.position = (0.0, 0.5 + float(self.np_random.uniform(0.0, 0.5)))


class DropAgent(RLAgent):
    """Nudges the ball sideways (a Box(-1, 1) action); observes its position and velocity."""

    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
    observation_space = spaces.Box(-np.inf, np.inf, (4,), np.float64)

    def __init__(self) -> None:
        super().__init__("Agent")
        self.push = 0.0

    def reset(self, arguments: Any) -> None:
        """No push."""
        self.push = 0.0

    def set_action(self, action: np.ndarray) -> None:
        """Push this much to the right during the action's ticks."""
        self.push = float(action[0])

    def _physics_process(self, delta: float) -> None:
        world = self.environment.world
        assert isinstance(world, DropWorld)
        world.ball.apply_impulse((self.push * delta, 0.0))

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """The ball's position and velocity."""
        world = self.environment.world
        assert isinstance(world, DropWorld)
        ball = world.ball
        return np.array([*ball.position, *ball.velocity], dtype=np.float64)


class DroppedBall(RLEnvironment):
    """A ball dropped on a floor: whether an episode touched it must not change the next."""

    def __init__(self) -> None:
        super().__init__("DroppedBall", repeat_action=4)
        self.add_child(DropAgent())
        self.add_child(DropWorld())
