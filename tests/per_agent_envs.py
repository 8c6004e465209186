"""A game whose agents differ in their settings (issue 41's reproduction), for the tests.

:class:`ChaseEnvironment`: one ``Chaser`` (a :class:`ChaserAgent`, ``max_force`` 10 N) and two
runners ``Runner1``, ``Runner2`` (:class:`RunnerAgent` s, ``max_force`` 8 N, and ``sight``:
how far a runner sees the chaser), in the seeker's room, the discs placed from the seed. Each
agent pushes its disc with its action times its own ``max_force``, so an episode replayed with
another agent's settings leaves the recording at its first step. A runner the chaser touches
is tagged (terminated); the chaser terminates once both are.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from examples.seeker import HALF, RADIUS, random_spot, room_walls
from rlenv import CollisionShape, PhysicsWorld, RigidBody, RLAgent, RLEnvironment, RLEnvWorld

__all__ = ["NAMES", "ChaseEnvironment", "ChaseWorld", "ChaserAgent", "RunnerAgent"]

NAMES = ("Chaser", "Runner1", "Runner2")
_TAGGED = 2 * RADIUS + 0.05


class ChaseWorld(RLEnvWorld):
    """The room and one disc per agent, at spots drawn from the seed."""

    def __init__(self) -> None:
        super().__init__("World")
        self.physics: PhysicsWorld | None = None
        self.discs: dict[str, RigidBody] = {}

    def reset(self, options: Mapping[str, Any]) -> None:
        """Build the room again with every disc at rest at a random spot."""
        if self.physics is not None:
            self.remove_child(self.physics)
            self.physics.queue_free()
        physics = PhysicsWorld(gravity=(0.0, 0.0), damping=0.5, name="Physics")
        physics.add_child(room_walls())
        for name in NAMES:
            disc = RigidBody(position=tuple(random_spot(self.np_random)), name=f"{name}Disc")
            disc.add_child(CollisionShape.circle(RADIUS, mass=1.0, name="Body"))
            physics.add_child(disc)
            self.discs[name] = disc
        self.physics = physics
        self.add_child(physics)


class _ChaseAgent(RLAgent):
    """What both classes share: a disc pushed by at most ``max_force`` newtons."""

    action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    observation_space = spaces.Box(-2 * HALF, 2 * HALF, (6,), np.float32)
    configurable: tuple[str, ...] = ("max_force",)
    max_force = 8.0

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.force = (0.0, 0.0)

    def disc(self, name: str | None = None) -> RigidBody:
        """This agent's disc (or the disc of the agent called ``name``)."""
        world = self.environment.world
        assert isinstance(world, ChaseWorld)
        return world.discs[name or self.name]

    def set_action(self, action: np.ndarray) -> None:
        """The force for this action's ticks: the action times this agent's ``max_force``."""
        self.force = (float(action[0]) * self.max_force, float(action[1]) * self.max_force)

    def _physics_process(self, delta: float) -> None:
        if not self.terminated:
            body = self.disc().body
            body.apply_force_at_world_point(self.force, body.position)

    def _sees(self, other: str, sight: float) -> np.ndarray:
        own, seen = self.disc(), self.disc(other)
        relative = np.subtract(seen.body.position, own.body.position)
        return np.clip(relative, -sight, sight)

    def _own(self) -> tuple[float, ...]:
        body = self.disc().body
        return (*body.position, *np.clip(body.velocity, -HALF, HALF))


class ChaserAgent(_ChaseAgent):
    """Tags the runners: sees both, relative to itself."""

    max_force = 10.0

    def _after_physics_tick(self, delta: float) -> None:
        runners = [agent for agent in self.environment.agents if isinstance(agent, RunnerAgent)]
        for runner in runners:
            if not runner.terminated and np.hypot(*self._sees(runner.name, 2 * HALF)) < _TAGGED:
                runner.add_reward(-10.0)
                runner.set_terminated()
                self.add_reward(10.0)
        if all(runner.terminated for runner in runners) and not self.terminated:
            self.set_terminated()

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Own position and velocity, then the nearest runner still running, relative."""
        running = [
            a.name
            for a in self.environment.agents
            if isinstance(a, RunnerAgent) and not a.terminated
        ] or ["Runner1"]
        nearest = min(running, key=lambda name: np.hypot(*self._sees(name, 2 * HALF)))
        return np.array((*self._own(), *self._sees(nearest, 2 * HALF)), dtype=np.float32)


class RunnerAgent(_ChaseAgent):
    """Runs from the chaser, which it sees within ``sight`` metres (each axis)."""

    configurable = ("max_force", "sight")

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.sight = 2 * HALF

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Own position and velocity, then the chaser, relative (clipped to ``sight``)."""
        return np.array((*self._own(), *self._sees("Chaser", self.sight)), dtype=np.float32)


class ChaseEnvironment(RLEnvironment):
    """One chaser, two runners; the episode ends when both runners are tagged."""

    def __init__(self) -> None:
        super().__init__("Chase", repeat_action=4)
        self.add_child(ChaserAgent("Chaser"))
        self.add_child(RunnerAgent("Runner1"))
        self.add_child(RunnerAgent("Runner2"))
        self.add_child(ChaseWorld())
