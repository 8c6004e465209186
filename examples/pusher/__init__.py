"""Pusher: push a puck onto a goal, written the Godot seed's way (it hosts itself).

The environment is built as the seed's RLEnvironment page shows it: ``_ready`` takes the World
and the Agent by path and starts the server (``communication.start_server``); ``_reset`` resets
the world, then the agent at a position the world samples; ``_step`` adds its own logic around
``super()._step``; ``_after_send_response`` clears what the world recorded for the answer (the
puck's trail during the last action, sent as world data). Run it as a Godot project runs::

    python -m examples.pusher [PORT]          # hosts itself (rlenv.run), 9090 by default
    rlenv serve examples.pusher:PusherEnvironment --port 0   # rlenv serve's address wins

::

    Pusher (PusherEnvironment)
    |___PhysicsFramesTimer
    |___Agent (PusherAgent)           pushes the puck, observes, is rewarded
    |___World (PusherWorld)           the table, the puck, the goal, the puck's trail
        |___Physics (PhysicsWorld)    seen from above: no gravity, some drag
            |___Puck (RigidBody)

## Action Space
``Box(-1, 1, (2,), float32)``: the force on the puck, as a fraction of ``max_force`` (10 N), in
x and y.

## Observation Space
``Box((4,), float32)``: the puck's position relative to the goal, x and y (m, within [-4, 4]),
and its velocity, x and y (m/s).

## Rewards
Per physics tick, how much closer the puck came to the goal (m); +5 when it reaches it.

## Episode End
Terminated when the puck is within 0.2 m of the goal; truncated by the client's time limit
otherwise. World data: ``{"goal": [x, y], "trail": [[x, y], ...]}``, the puck's positions
during the last action.

## Starting State
The goal and the puck at independent uniform positions on the table, from the seeded
generator; the puck at rest.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

import rlenv
from rlenv import CollisionShape, PhysicsWorld, RigidBody, RLAgent, RLEnvironment, RLEnvWorld

__all__ = ["TARGET", "PusherAgent", "PusherEnvironment", "PusherWorld", "main", "towards_goal"]

TARGET = f"{__name__}:PusherEnvironment"
HALF = 2.0  # the table spans [-HALF, HALF] in x and y
GOAL_RADIUS = 0.2


def towards_goal(observation: np.ndarray) -> np.ndarray:
    """Push towards the goal, braking: a policy that reaches it."""
    return np.clip(-observation[:2] - 0.6 * observation[2:], -1.0, 1.0).astype(np.float32)


class PusherWorld(RLEnvWorld):
    """The table, the puck and the goal; records the puck's trail during an action."""

    configurable = ("damping",)

    def __init__(self) -> None:
        super().__init__("World")
        self.damping = 0.3
        self.physics = PhysicsWorld(gravity=(0.0, 0.0), damping=self.damping, name="Physics")
        self.puck = RigidBody(name="Puck")
        self.puck.add_child(CollisionShape.circle(0.1, mass=1.0, name="Disc"))
        self.physics.add_child(self.puck)
        self.add_child(self.physics)
        self.goal = np.zeros(2)
        self.trail: list[list[float]] = []

    def reset(self, options: Mapping[str, Any]) -> None:
        """A fresh space (no solver state survives an episode) and a new goal."""
        self.physics.damping = self.damping
        self.physics.restart()
        self.goal = self.np_random.uniform(-HALF, HALF, size=2)
        self.trail = []

    def sample_initial_position(self) -> np.ndarray:
        """Where the puck starts."""
        return self.np_random.uniform(-HALF, HALF, size=2)

    def _physics_process(self, delta: float) -> None:
        self.trail.append([float(self.puck.position.x), float(self.puck.position.y)])

    def get_data(self, observation_request: Mapping[str, Any]) -> dict[str, Any]:
        """The goal, and the puck's trail since the previous answer."""
        return {"goal": self.goal.tolist(), "trail": self.trail}


class PusherAgent(RLAgent):
    """Pushes the puck; rewarded for every metre it gains towards the goal."""

    configurable = ("max_force",)
    action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    observation_space = spaces.Box(-2 * HALF, 2 * HALF, (4,), np.float32)

    def __init__(self) -> None:
        super().__init__("Agent")
        self.max_force = 10.0
        self.force = (0.0, 0.0)
        self.distance = 0.0

    def reset(self, arguments: np.ndarray) -> None:
        """Put the puck at the sampled position, at rest."""
        puck = self.environment.world.puck
        puck.position = (float(arguments[0]), float(arguments[1]))
        puck.velocity = (0.0, 0.0)
        self.force = (0.0, 0.0)
        self.distance = self._distance()

    def set_action(self, action: np.ndarray) -> None:
        """Remember the force for the ticks of this action."""
        self.force = (float(action[0]) * self.max_force, float(action[1]) * self.max_force)

    def _physics_process(self, delta: float) -> None:
        self.environment.world.puck.apply_force(self.force)

    def _after_physics_tick(self, delta: float) -> None:
        distance = self._distance()
        self.add_reward(self.distance - distance)
        self.distance = distance
        if distance < GOAL_RADIUS:
            self.add_reward(5.0)
            self.set_terminated()

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """The puck's position relative to the goal, and its velocity."""
        world = self.environment.world
        relative = np.array(world.puck.position) - world.goal
        velocity = np.array(world.puck.velocity)
        return np.clip(np.concatenate([relative, velocity]), -2 * HALF, 2 * HALF).astype(np.float32)

    def _distance(self) -> float:
        world = self.environment.world
        return float(np.hypot(*(np.array(world.puck.position) - world.goal)))


class PusherEnvironment(RLEnvironment):
    """The seed's RLEnvironment: it finds its World and Agent and starts its own server.

    Args:
        port: where ``_ready`` asks the communication to listen (under ``rlenv serve``, the
            server's own address wins).
    """

    def __init__(self, port: int = 9090) -> None:
        super().__init__("Pusher", repeat_action=4)
        self.port = port
        self.actions = 0
        self.add_child(PusherAgent())
        self.add_child(PusherWorld())

    def _ready(self) -> None:
        self.world = self.get_node("World")
        self.agent = self.get_node("Agent")
        self.communication.start_server(self.port, "127.0.0.1")

    def _reset(self, options: Mapping[str, Any]) -> None:
        self.world.reset(options)
        self.agent.reset(self.world.sample_initial_position())
        self.actions = 0

    def _step(self, action: Any, frames: int | None = None) -> None:
        self.actions += 1  # logic around the action, before and after its ticks
        super()._step(action, frames)

    def _get_info(self) -> dict[str, Any]:
        return {"actions": self.actions}

    def _after_send_response(self) -> None:
        self.world.trail = []  # sent: the next answer carries the next action's trail


def main() -> None:
    """Host the pusher itself: ``python -m examples.pusher [PORT]`` (9090 by default)."""
    rlenv.run(PusherEnvironment(int(sys.argv[1]) if len(sys.argv) > 1 else 9090))
