"""Hunt: one hunter, prey that appear and are caught (agents that come and go, two paces).

The hunter chases the prey around the seeker's room. Prey appear during the episode, up to
eight, and leave it when caught; the hunter decides every 4 ticks, each prey every 8, the prey
staggered, so answers hold the agents due to decide::

    Hunt (HuntEnvironment)          possible_agents: Hunter, Prey1 .. Prey8
    |___PhysicsFramesTimer
    |___Hunter (Hunter)             decision_period 4
    |___Prey1, Prey2, ... (Prey)    decision_period 8, decision_offset 0, 2, 4, 6, 0, ...
    |___World (HuntWorld)           signal caught(prey name)
        |___Physics (PhysicsWorld)
            |___Walls (StaticBody)
            |___HunterDisc (RigidBody), Prey1Disc, ... (each prey's own, added by it)

## Action Space
Per agent ``Box(-1, 1, (2,), float32)``: the force on its disc, as a fraction of its class's
``max_force`` (the hunter's 10 N, a prey's 8 N; configurable per agent). The joint space is a
``Dict`` keyed by every possible agent's name; an action needs entries only for the agents
that decide at this answer.

## Observation Space
- Hunter: ``Box((13,), float32)``: its disc's position and velocity, then for the three
  nearest prey in play, nearest first, its position relative to the hunter and 1 (0 and 0, 0
  for an empty slot).
- Prey: ``Box((8,), float32)``: its disc's position and velocity, the hunter's position
  relative to it and the hunter's velocity.

## Rewards
- Hunter: -0.005 per physics tick, +1 for each prey it catches.
- Prey: +0.01 per physics tick in play, -1 when caught.

## Episode End
A prey is caught when the hunter's disc touches its disc: it leaves the tree
(``queue_free``), which ends its episode as terminated, its last observation and reward
delivered in that answer. Two prey start; one more appears every 90 ticks (1.5 s) while fewer
than three are in play, eight in all. The episode terminates when the eighth prey is caught
(the hunter terminates then), and is truncated after 1,200 ticks (20 s) for every agent still
in play.

Each class has a ``heuristic``: the hunter runs at the nearest prey, a prey runs away from the
hunter and from the walls. ``rlenv serve examples.hunt:HuntEnvironment --policy
Prey1=heuristic ... --policy Prey8=heuristic`` leaves every prey to the server: the hunter is
then the one agent a client acts for (``benchmarks/train_hunt.py`` trains it so).

## Trained
``benchmarks/train_hunt.py`` trains the hunter with SB3's PPO (``n_steps`` 512, ``batch_size``
256, otherwise SB3's defaults; 4 envs of one server each), the prey driven by their heuristic in
the servers: 200,704 decisions took 416 s on the 2-core development VM (a busy one). Its
deterministic policy against the scripted hunter (the ``heuristic``), over the same 20 seeds
(1000 to 1019): return per episode mean 1.32 against 0.99 (min -1.00 and -1.00, median 1.00
and 1.00); prey caught per episode mean 7.00 against 6.75 (min 5 and 5, median 7 and 7).
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

__all__ = ["HUNTER", "PREY", "TARGET", "Hunter", "HuntEnvironment", "HuntWorld", "Prey"]

TARGET = f"{__name__}:HuntEnvironment"
HUNTER = "Hunter"
PREY = tuple(f"Prey{number}" for number in range(1, 9))
STARTING_PREY = 2
IN_PLAY = 3  # a prey appears while fewer are in play
SPAWN_TICKS = 90
EPISODE_TICKS = 1200
NEAREST = 3  # prey slots in the hunter's observation
_SPEED = 50.0  # the observation's bound on a velocity


class HuntWorld(RLEnvWorld):
    """The room and the hunter's disc; emits ``caught(name)`` when the hunter touches a prey."""

    caught = Signal("name")
    """Emitted (inside the physics step) with the name of the prey the hunter touched."""

    def __init__(self) -> None:
        super().__init__("World")
        self.physics: PhysicsWorld | None = None
        self.hunter_disc: RigidBody | None = None
        self.prey_discs: dict[str, RigidBody] = {}

    def reset(self, options: Mapping[str, Any]) -> None:
        """Build a fresh room with the hunter's disc; the prey bring their own."""
        if self.physics is not None:
            self.remove_child(self.physics)
            self.physics.queue_free()
        physics = PhysicsWorld(gravity=(0.0, 0.0), damping=0.5, name="Physics")
        physics.add_child(room_walls(elasticity=0.5))
        self.hunter_disc = _disc(HUNTER, (200, 50, 50))
        self.hunter_disc.get_node("Body").collision_started.connect(self._on_hunter_contact)
        physics.add_child(self.hunter_disc)
        self.prey_discs = {}
        self.physics = physics
        self.add_child(physics)

    def spot_away_from(self, position: np.ndarray) -> np.ndarray:
        """A random spot at least 3 m from ``position`` (where a prey appears)."""
        while True:
            spot = random_spot(self.np_random)
            if np.hypot(*(spot - position)) >= 3.0:
                return spot

    def _on_hunter_contact(self, other: CollisionShape) -> None:
        for name, disc in self.prey_discs.items():
            if other.body_node is disc:
                self.caught.emit(name)


def _disc(name: str, color: tuple[int, int, int]) -> RigidBody:
    disc = RigidBody(name=f"{name}Disc")
    disc.add_child(
        CollisionShape.circle(RADIUS, mass=1.0, elasticity=0.5, color=color, name="Body")
    )
    return disc


class _Mover(RLAgent):
    """What both roles share: a disc pushed by a force of at most ``max_force``."""

    action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    configurable = ("max_force",)
    max_force = 8.0

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.force = (0.0, 0.0)

    @property
    def world(self) -> HuntWorld:
        """The shared world."""
        world = self.get_node("../World")
        assert isinstance(world, HuntWorld)
        return world

    @property
    def body(self) -> pymunk.Body:
        """This agent's pymunk body."""
        raise NotImplementedError

    def set_action(self, action: np.ndarray) -> None:
        """Remember the force for the ticks until the next decision."""
        self.force = (float(action[0]) * self.max_force, float(action[1]) * self.max_force)

    def _physics_process(self, delta: float) -> None:
        body = self.body
        body.apply_force_at_world_point(self.force, body.position)

    def _own(self) -> tuple[np.ndarray, np.ndarray]:
        body = self.body
        return np.array(body.position), np.array(body.velocity)


class Hunter(_Mover):
    """The hunter: faster, rewarded for each prey it catches."""

    max_force = 10.0
    decision_period = 4
    observation_space = spaces.Box(
        low=np.array(
            [-HALF, -HALF, -_SPEED, -_SPEED] + [-2 * HALF, -2 * HALF, 0.0] * NEAREST,
            dtype=np.float32,
        ),
        high=np.array(
            [HALF, HALF, _SPEED, _SPEED] + [2 * HALF, 2 * HALF, 1.0] * NEAREST, dtype=np.float32
        ),
        dtype=np.float32,
    )

    def __init__(self, name: str = HUNTER) -> None:
        super().__init__(name)

    @property
    def body(self) -> pymunk.Body:
        """The hunter's disc's body."""
        disc = self.world.hunter_disc
        assert disc is not None
        return disc.body

    def reset(self, arguments: np.ndarray) -> None:
        """Put the disc at the sampled spot, at rest."""
        self.body.position = (float(arguments[0]), float(arguments[1]))
        self.body.velocity = (0.0, 0.0)
        self.force = (0.0, 0.0)

    def _ready(self) -> None:
        self.world.caught.connect(self._on_caught)

    def _after_physics_tick(self, delta: float) -> None:
        self.add_reward(-0.005)

    def _on_caught(self, name: str) -> None:
        self.add_reward(1.0)

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Own position and velocity; the three nearest prey, relative to the hunter."""
        position, velocity = self._own()
        others = sorted(
            (np.array(disc.body.position) - position for disc in self.world.prey_discs.values()),
            key=lambda relative: float(np.hypot(*relative)),
        )[:NEAREST]
        values = [*position, *velocity]
        for slot in range(NEAREST):
            values += [*others[slot], 1.0] if slot < len(others) else [0.0, 0.0, 0.0]
        return np.clip(
            np.array(values, dtype=np.float32),
            self.observation_space.low,
            self.observation_space.high,
        )

    def heuristic(self, observation: np.ndarray) -> np.ndarray:
        """Run at the nearest prey, braking a little."""
        if observation[6] < 0.5:
            return np.zeros(2, np.float32)
        velocity, nearest = observation[2:4], observation[4:6]
        return np.clip(2.0 * nearest - 0.3 * velocity, -1.0, 1.0).astype(np.float32)


class Prey(_Mover):
    """A prey: rewarded for every tick in play; it brings its own disc and leaves when caught."""

    decision_period = 8
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

    def __init__(self, name: str, spot: np.ndarray) -> None:
        super().__init__(name)
        self.decision_offset = 2 * (PREY.index(name) % 4)  # the prey decide at staggered ticks
        self.spot = spot
        self.disc: RigidBody | None = None

    @property
    def body(self) -> pymunk.Body:
        """This prey's disc's body."""
        assert self.disc is not None
        return self.disc.body

    def _ready(self) -> None:
        world = self.world
        physics = world.physics
        assert physics is not None
        self.disc = _disc(self.name, (50, 90, 200))
        self.disc.position = (float(self.spot[0]), float(self.spot[1]))
        physics.add_child(self.disc)
        world.prey_discs[self.name] = self.disc
        world.caught.connect(self._on_caught)

    def _exit_tree(self) -> None:
        world = self.world
        world.caught.disconnect(self._on_caught)
        if world.prey_discs.pop(self.name, None) is self.disc and self.disc is not None:
            self.disc.queue_free()

    def _after_physics_tick(self, delta: float) -> None:
        self.add_reward(0.01)

    def _on_caught(self, name: str) -> None:
        if name == self.name and not self.is_queued_for_deletion():
            self.add_reward(-1.0)
            self.queue_free()

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Own position and velocity; the hunter relative to this prey, and its velocity."""
        position, velocity = self._own()
        hunter = self.world.hunter_disc
        assert hunter is not None
        values = np.array(
            (
                *position,
                *velocity,
                *(np.array(hunter.body.position) - position),
                *hunter.body.velocity,
            ),
            dtype=np.float32,
        )
        return np.clip(values, self.observation_space.low, self.observation_space.high)

    def heuristic(self, observation: np.ndarray) -> np.ndarray:
        """Run away from the hunter, and away from the walls when close to one."""
        position, hunter = observation[0:2], observation[4:6]
        away = -hunter / max(float(np.hypot(*hunter)), 1e-6)
        walls = -np.sign(position) * (np.abs(position) > HALF - 1.5)
        return np.clip(away + walls, -1.0, 1.0).astype(np.float32)


class HuntEnvironment(RLEnvironment):
    """One hunter and the prey that appear and are caught in one room."""

    possible_agents = {HUNTER: Hunter, **dict.fromkeys(PREY, Prey)}
    render_view = (-HALF - 0.5, -HALF - 0.5, HALF + 0.5, HALF + 0.5)
    render_size = (400, 400)

    def __init__(self) -> None:
        super().__init__("Hunt", repeat_action=4)
        self.hunter = Hunter()
        self.add_child(self.hunter)
        self.world_node = HuntWorld()
        self.add_child(self.world_node)
        self.ticks = 0
        self.spawned = 0

    def _reset(self, options: Mapping[str, Any]) -> None:
        """A fresh room: the hunter at a random spot, two prey away from it."""
        for node in self.get_children():
            if isinstance(node, Prey):
                self.remove_child(node)
                node.queue_free()
        self.world_node.reset(options)
        spot = random_spot(self.np_random)
        self.hunter.reset(spot)
        self.ticks = self.spawned = 0
        for _ in range(STARTING_PREY):
            self._spawn()

    def _physics_process(self, delta: float) -> None:
        self.ticks += 1
        in_play = sum(isinstance(node, Prey) for node in self.get_children())
        if self.spawned < len(PREY) and in_play < IN_PLAY and self.ticks % SPAWN_TICKS == 0:
            self._spawn()
        if self.ticks >= EPISODE_TICKS:
            for agent in self.agents:
                agent.set_truncated()
        elif self.spawned == len(PREY) and in_play == 0:
            self.hunter.set_terminated()

    def _spawn(self) -> None:
        name = PREY[self.spawned]
        self.spawned += 1
        self.add_child(
            Prey(name, self.world_node.spot_away_from(np.array(self.hunter.body.position)))
        )
