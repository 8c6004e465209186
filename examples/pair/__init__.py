"""Pair: two seekers in one room, each after its own apple (several agents in one world).

Both agents live in the same pymunk space and bump into each other. Each is done when it
catches its own apple; the episode ends when both are. Observations, rewards and terminations
are keyed by agent name (``Red``, ``Blue``), as PettingZoo expects::

    Pair (PairEnvironment)
    |___PhysicsFramesTimer
    |___Red (PairAgent)      |___Blue (PairAgent)
    |___World (PairWorld)                signal caught(agent name)
        |___Physics (PhysicsWorld)
            |___Walls (StaticBody)
            |___RedDisc, BlueDisc (RigidBody)
            |___RedApple, BlueApple (StaticBody, sensor shapes)

## Action Space
Per agent ``Box(-1, 1, (2,), float32)``: the force on its disc (fraction of 20 N). The joint
space is a ``Dict`` keyed by agent name; an agent whose episode has ended takes no action.

## Observation Space
Per agent ``Box((8,), float32)``: its disc's position and velocity, its apple relative to its
disc, and the other disc relative to its disc.

## Rewards
Per agent: -0.01 per physics tick until it is done, +10 for catching its own apple.

## Episode End
An agent terminates when it catches its apple; the episode ends when both have
(``rlenv/Pair-v0`` truncates after 300 steps).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pymunk
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
from rlenv.signals import Signal

from ..seeker import HALF, RADIUS, greedy, random_spot, room_walls

__all__ = ["NAMES", "TARGET", "PairAgent", "PairEnvironment", "PairWorld", "chase"]

TARGET = f"{__name__}:PairEnvironment"
NAMES = ("Red", "Blue")
_COLORS = {"Red": (200, 50, 50), "Blue": (50, 90, 200)}


chase = greedy
"""Push towards one's own apple, braking a little (the seeker's policy: same first 6 fields)."""


class PairWorld(RLEnvWorld):
    """The room, two discs and two apples; emits ``caught(name)`` when a disc gets its apple."""

    caught = Signal("name")
    """Emitted (inside the physics step) with the name of the agent that caught its apple."""

    def __init__(self) -> None:
        super().__init__("World")
        self.physics: PhysicsWorld | None = None
        self.discs: dict[str, RigidBody] = {}
        self.apples: dict[str, StaticBody] = {}
        self._placing: list[str] = []

    def reset(self, options: Mapping[str, Any]) -> None:
        """Build a fresh room with both apples placed apart."""
        if self.physics is not None:
            self.remove_child(self.physics)
            self.physics.queue_free()
        physics = PhysicsWorld(gravity=(0.0, 0.0), damping=0.5, name="Physics")
        physics.add_child(room_walls())
        for name in NAMES:
            disc = RigidBody(name=f"{name}Disc")
            disc.add_child(
                CollisionShape.circle(RADIUS, mass=1.0, color=_COLORS[name], name="Body")
            )
            apple = StaticBody(position=tuple(random_spot(self.np_random)), name=f"{name}Apple")
            skin = CollisionShape.circle(0.25, sensor=True, color=_COLORS[name], name="Skin")
            skin.collision_started.connect(self._touched(name))
            apple.add_child(skin)
            physics.add_child(disc)
            physics.add_child(apple)
            self.discs[name], self.apples[name] = disc, apple
        self.physics = physics
        self.add_child(physics)
        self._placing = list(NAMES)

    def sample_initial_position(self) -> np.ndarray:
        """A spot for the next agent's disc, 2 m from its apple (agents are placed in order)."""
        name = self._placing.pop(0)
        while True:
            spot = random_spot(self.np_random)
            if np.hypot(*(spot - np.array(self.apples[name].position))) >= 2.0:
                return spot

    def _touched(self, name: str) -> Any:
        def on_contact(other: CollisionShape) -> None:
            if other.body_node is self.discs.get(name):
                self.caught.emit(name)

        return on_contact


class PairAgent(RLAgent):
    """One of the two seekers; knows its disc, its apple and the other disc."""

    action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    observation_space = spaces.Box(
        low=np.array([-HALF, -HALF, -50, -50] + [-2 * HALF] * 4, dtype=np.float32),
        high=np.array([HALF, HALF, 50, 50] + [2 * HALF] * 4, dtype=np.float32),
        dtype=np.float32,
    )

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.force = (0.0, 0.0)
        self._other = next(other for other in NAMES if other != name)
        self._disc: pymunk.Body | None = None  # this episode's bodies, set at reset
        self._apple: StaticBody | None = None
        self._other_disc: RigidBody | None = None

    @property
    def world(self) -> PairWorld:
        """The shared world."""
        world = self.get_node("../World")
        assert isinstance(world, PairWorld)
        return world

    def _ready(self) -> None:
        self.world.caught.connect(self._on_caught)

    def reset(self, arguments: np.ndarray) -> None:
        """Put this agent's disc at the sampled spot, at rest."""
        world = self.world
        self._disc = world.discs[self.name].body
        self._apple, self._other_disc = world.apples[self.name], world.discs[self._other]
        self._disc.position = (float(arguments[0]), float(arguments[1]))
        self._disc.velocity = (0.0, 0.0)
        self.force = (0.0, 0.0)

    def set_action(self, action: np.ndarray) -> None:
        """Remember the force for the ticks of this action."""
        self.force = (float(action[0]) * 20.0, float(action[1]) * 20.0)

    def _physics_process(self, delta: float) -> None:
        if self._disc is not None and not self.terminated:
            self._disc.apply_force_at_world_point(self.force, self._disc.position)

    def _after_physics_tick(self, delta: float) -> None:
        if not self.terminated:
            self.add_reward(-0.01)

    def _on_caught(self, name: str) -> None:
        if name == self.name and not self.terminated:
            self.add_reward(10.0)
            self.set_terminated()
            self.force = (0.0, 0.0)

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Own position and velocity, own apple and the other disc, both relative."""
        disc, apple, other_disc = self._disc, self._apple, self._other_disc
        assert disc is not None and apple is not None and other_disc is not None
        x, y = disc.position
        apple_x, apple_y = apple.position
        other_x, other_y = other_disc.position
        return np.array(
            (x, y, *disc.velocity, apple_x - x, apple_y - y, other_x - x, other_y - y),
            dtype=np.float32,
        )


class PairEnvironment(RLEnvironment):
    """Two agents, one world."""

    render_view = (-HALF - 0.5, -HALF - 0.5, HALF + 0.5, HALF + 0.5)
    render_size = (400, 400)

    def __init__(self) -> None:
        super().__init__("Pair", repeat_action=4)
        for name in NAMES:
            self.add_child(PairAgent(name))
        self.add_child(PairWorld())
