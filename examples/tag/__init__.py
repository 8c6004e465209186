"""Tag: one chaser, two runners, the seeker's room (agents that differ: two roles, two classes).

The chaser is faster and wants to touch the runners; each runner wants to stay untouched. The
roles differ in their spaces, their settings and their rewards, as a game's agents do::

    Tag (TagEnvironment)
    |___PhysicsFramesTimer
    |___Chaser (Chaser)    |___Runner1, Runner2 (Runner)
    |___World (TagWorld)                 signal tagged(runner name)
        |___Physics (PhysicsWorld)
            |___Walls (StaticBody)
            |___ChaserDisc, Runner1Disc, Runner2Disc (RigidBody)

## Action Space
Per agent ``Box(-1, 1, (2,), float32)``: the force on its disc, as a fraction of its class's
``max_force`` (configurable per agent: the chaser's 10 N, a runner's 8 N). The joint space is a
``Dict`` keyed by agent name; an agent whose episode has ended takes no action.

## Observation Space
- Chaser: ``Box((10,), float32)``: its disc's position and velocity, then for each runner its
  position relative to the chaser and whether it is still running (1) or tagged (0).
- Runner: ``Box((8,), float32)``: its disc's position and velocity, the chaser's position
  relative to it and the chaser's velocity.

## Rewards
- Chaser: -0.01 per physics tick while a runner runs, +10 for each runner it tags.
- Runner: +0.01 per physics tick while it runs, -10 when it is tagged.

## Episode End
A runner terminates when the chaser's disc touches its disc (its disc stays where it was
tagged, as an obstacle). The chaser terminates when both runners are tagged, so the episode
ends then; ``rlenv/Tag-v0`` truncates after 300 steps.

Each class has a ``heuristic``: the chaser runs at the nearest runner still running, a runner
runs away from the chaser and from the walls, so any agent can be left to the server
(``rlenv serve examples.tag:TagEnvironment --policy Runner1=heuristic``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pymunk
from gymnasium import spaces

from rlenv import CollisionShape, PhysicsWorld, RigidBody, RLAgent, RLEnvironment, RLEnvWorld
from rlenv.signals import Signal

from ..seeker import HALF, RADIUS, random_spot, room_walls

__all__ = [
    "CHASER",
    "RUNNERS",
    "TARGET",
    "Chaser",
    "Runner",
    "TagAgent",
    "TagEnvironment",
    "TagWorld",
]

TARGET = f"{__name__}:TagEnvironment"
CHASER = "Chaser"
RUNNERS = ("Runner1", "Runner2")
_COLORS = {CHASER: (200, 50, 50), "Runner1": (50, 90, 200), "Runner2": (40, 160, 90)}
_SPEED = 50.0  # the observation's bound on a velocity


class TagWorld(RLEnvWorld):
    """The room and the three discs; emits ``tagged(name)`` when the chaser touches a runner."""

    tagged = Signal("name")
    """Emitted (inside the physics step) with the name of the runner the chaser touched."""

    def __init__(self) -> None:
        super().__init__("World")
        self.physics: PhysicsWorld | None = None
        self.discs: dict[str, RigidBody] = {}
        self._spots: list[np.ndarray] = []

    def reset(self, options: Mapping[str, Any]) -> None:
        """Build a fresh room with the three discs (placed by their agents)."""
        if self.physics is not None:
            self.remove_child(self.physics)
            self.physics.queue_free()
        physics = PhysicsWorld(gravity=(0.0, 0.0), damping=0.5, name="Physics")
        physics.add_child(room_walls(elasticity=0.5))
        self.discs = {}
        for name in (CHASER, *RUNNERS):
            disc = RigidBody(name=f"{name}Disc")
            skin = CollisionShape.circle(
                RADIUS, mass=1.0, elasticity=0.5, color=_COLORS[name], name="Body"
            )
            disc.add_child(skin)
            physics.add_child(disc)
            self.discs[name] = disc
            if name == CHASER:
                skin.collision_started.connect(self._on_chaser_contact)
        self.physics = physics
        self.add_child(physics)
        self._spots = self._place()

    def sample_initial_position(self) -> np.ndarray:
        """The next agent's spot (agents are placed in order, the chaser first)."""
        return self._spots.pop(0)

    def _place(self) -> list[np.ndarray]:
        """Spots for the three discs, each runner at least 3 m from the chaser."""
        chaser = random_spot(self.np_random)
        spots = [chaser]
        while len(spots) < 1 + len(RUNNERS):
            spot = random_spot(self.np_random)
            if np.hypot(*(spot - chaser)) >= 3.0:
                spots.append(spot)
        return spots

    def _on_chaser_contact(self, other: CollisionShape) -> None:
        for name in RUNNERS:
            if other.body_node is self.discs.get(name):
                self.tagged.emit(name)


class TagAgent(RLAgent):
    """What both roles share: a disc pushed by a force of at most ``max_force``."""

    action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    configurable = ("max_force",)
    max_force = 8.0

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.force = (0.0, 0.0)
        self._disc: pymunk.Body | None = None  # this episode's body, set at reset

    @property
    def world(self) -> TagWorld:
        """The shared world."""
        world = self.get_node("../World")
        assert isinstance(world, TagWorld)
        return world

    def _ready(self) -> None:
        self.world.tagged.connect(self._on_tagged)

    def reset(self, arguments: np.ndarray) -> None:
        """Put this agent's disc at the sampled spot, at rest."""
        self._disc = self.world.discs[self.name].body
        self._disc.position = (float(arguments[0]), float(arguments[1]))
        self._disc.velocity = (0.0, 0.0)
        self.force = (0.0, 0.0)

    def set_action(self, action: np.ndarray) -> None:
        """Remember the force for the ticks of this action."""
        self.force = (float(action[0]) * self.max_force, float(action[1]) * self.max_force)

    def _physics_process(self, delta: float) -> None:
        if self._disc is not None and not self.terminated:
            self._disc.apply_force_at_world_point(self.force, self._disc.position)

    def _on_tagged(self, name: str) -> None:
        """What a tag means to this agent (each role says)."""

    def _own(self) -> tuple[np.ndarray, np.ndarray]:
        disc = self._disc
        assert disc is not None
        return np.array(disc.position), np.array(disc.velocity)


class Chaser(TagAgent):
    """The chaser: faster, rewarded for each runner it tags."""

    max_force = 10.0
    observation_space = spaces.Box(
        low=np.array(
            [-HALF, -HALF, -_SPEED, -_SPEED] + [-2 * HALF, -2 * HALF, 0.0] * 2, dtype=np.float32
        ),
        high=np.array(
            [HALF, HALF, _SPEED, _SPEED] + [2 * HALF, 2 * HALF, 1.0] * 2, dtype=np.float32
        ),
        dtype=np.float32,
    )

    def __init__(self, name: str = CHASER) -> None:
        super().__init__(name)
        self.running: dict[str, bool] = dict.fromkeys(RUNNERS, True)

    def reset(self, arguments: np.ndarray) -> None:
        """Place the disc; every runner runs again."""
        super().reset(arguments)
        self.running = dict.fromkeys(RUNNERS, True)

    def _after_physics_tick(self, delta: float) -> None:
        if not self.terminated:
            self.add_reward(-0.01)

    def _on_tagged(self, name: str) -> None:
        if self.running[name] and not self.terminated:
            self.running[name] = False
            self.add_reward(10.0)
            if not any(self.running.values()):
                self.set_terminated()
                self.force = (0.0, 0.0)

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Own position and velocity; each runner relative to the chaser, and whether it runs."""
        position, velocity = self._own()
        values = [*position, *velocity]
        for name in RUNNERS:
            runner = np.array(self.world.discs[name].body.position) - position
            values += [*runner, 1.0 if self.running[name] else 0.0]
        return np.array(values, dtype=np.float32)

    def heuristic(self, observation: np.ndarray) -> np.ndarray:
        """Run at the nearest runner still running, braking a little."""
        velocity = observation[2:4]
        targets = [
            observation[4 + 3 * i : 6 + 3 * i]
            for i in range(len(RUNNERS))
            if observation[6 + 3 * i] > 0.5
        ]
        if not targets:
            return np.zeros(2, np.float32)
        nearest = min(targets, key=lambda relative: float(np.hypot(*relative)))
        return np.clip(2.0 * nearest - 0.3 * velocity, -1.0, 1.0).astype(np.float32)


class Runner(TagAgent):
    """A runner: rewarded for every tick it stays untagged."""

    observation_space = spaces.Box(
        low=np.array(
            [-HALF, -HALF, -_SPEED, -_SPEED, -2 * HALF, -2 * HALF, -_SPEED, -_SPEED],
            dtype=np.float32,
        ),
        high=np.array(
            [HALF, HALF, _SPEED, _SPEED, 2 * HALF, 2 * HALF, _SPEED, _SPEED], dtype=np.float32
        ),
        dtype=np.float32,
    )

    def _after_physics_tick(self, delta: float) -> None:
        if not self.terminated:
            self.add_reward(0.01)

    def _on_tagged(self, name: str) -> None:
        if name == self.name and not self.terminated:
            self.add_reward(-10.0)
            self.set_terminated()
            self.force = (0.0, 0.0)

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Own position and velocity; the chaser relative to this runner, and its velocity."""
        position, velocity = self._own()
        chaser = self.world.discs[CHASER].body
        return np.array(
            (*position, *velocity, *(np.array(chaser.position) - position), *chaser.velocity),
            dtype=np.float32,
        )

    def heuristic(self, observation: np.ndarray) -> np.ndarray:
        """Run away from the chaser, and away from the walls when close to one."""
        position, chaser = observation[0:2], observation[4:6]
        away = -chaser / max(float(np.hypot(*chaser)), 1e-6)
        walls = -np.sign(position) * (np.abs(position) > HALF - 1.5)
        return np.clip(away + walls, -1.0, 1.0).astype(np.float32)


class TagEnvironment(RLEnvironment):
    """One chaser and two runners in one world."""

    render_view = (-HALF - 0.5, -HALF - 0.5, HALF + 0.5, HALF + 0.5)
    render_size = (400, 400)

    def __init__(self) -> None:
        super().__init__("Tag", repeat_action=4)
        self.add_child(Chaser())
        for name in RUNNERS:
            self.add_child(Runner(name))
        self.add_child(TagWorld())
