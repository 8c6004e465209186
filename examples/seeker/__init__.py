"""Seeker: the Godot seed's apple seeker, in 2D — reach the apple in a walled room.

The agent is a disc pushed by a force; the world places an apple at a random spot each episode.
A pymunk collision handler reports the catch: the apple's sensor shape emits
``collision_started``, the world turns it into its own ``apple_caught`` signal, and the agent,
connected to that signal, is rewarded and the episode ends::

    Seeker (SeekerEnvironment)
    |___PhysicsFramesTimer
    |___Agent (SeekerAgent)            pushes the disc, observes, is rewarded on apple_caught
    |___World (SeekerWorld)            signal apple_caught; rebuilds its physics every reset
        |___Eye (Camera)               only in SeekerPixels: the agent's eyes, 64x64
        |___Physics (PhysicsWorld)     no gravity (seen from above), some drag
            |___Walls (StaticBody)     four segments around the room
            |___Disc (RigidBody)       the agent's body
            |___Apple (StaticBody)     a sensor circle, in group "apples"

## Action Space
``Box(-1, 1, (2,), float32)``: the force on the disc, as a fraction of ``max_force`` (20 N) in x
and y.

## Observation Space
``Box((6,), float32)``: disc position x, y (m), disc velocity x, y (m/s), and the apple's
position relative to the disc, x and y (m). Positions are within the room, [-5, 5].

## Rewards
-0.01 per physics tick (hurry), +10 when the disc touches the apple.

## Episode End
Terminated when the apple is caught; otherwise the client's time limit truncates it
(``rlenv/Seeker-v0``: 250 steps of 4 ticks).

## Starting State
Disc and apple at independent uniform positions at least 2 m apart, from the seeded generator.
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
from rlenv.scene2d.camera import Camera
from rlenv.signals import Signal

__all__ = [
    "PIXELS_TARGET",
    "TARGET",
    "PixelSeekerAgent",
    "SeekerAgent",
    "SeekerEnvironment",
    "SeekerPixelsEnvironment",
    "SeekerWorld",
    "greedy",
    "main",
    "random_spot",
    "room_walls",
]

TARGET = f"{__name__}:SeekerEnvironment"
PIXELS_TARGET = f"{__name__}:SeekerPixelsEnvironment"
HALF = 5.0  # the room spans [-HALF, HALF] in x and y
RADIUS = 0.3


def greedy(observation: np.ndarray) -> np.ndarray:
    """Push towards the apple, braking a little: a policy that catches it."""
    relative, velocity = observation[4:6], observation[2:4]
    return np.clip(relative - 0.5 * velocity, -1.0, 1.0).astype(np.float32)


def room_walls(**shape_options: Any) -> StaticBody:
    """The room's four walls: segments of one static body (``shape_options`` for each)."""
    walls = StaticBody(name="Walls")
    corners = [(-HALF, -HALF), (HALF, -HALF), (HALF, HALF), (-HALF, HALF)]
    for index, (a, b) in enumerate(zip(corners, corners[1:] + corners[:1], strict=True)):
        walls.add_child(CollisionShape.segment(a, b, 0.05, name=f"Wall{index}", **shape_options))
    return walls


def random_spot(rng: np.random.Generator) -> np.ndarray:
    """A random spot in the room where a disc fits, clear of the walls."""
    margin = HALF - RADIUS - 0.2
    return rng.uniform(-margin, margin, size=2)


class SeekerWorld(RLEnvWorld):
    """The room, the disc and the apple; emits ``apple_caught`` when the disc touches it."""

    apple_caught = Signal()
    """Emitted (from inside the physics step) when the disc touches the apple."""

    configurable = ("damping",)

    def __init__(self) -> None:
        super().__init__("World")
        self.damping = 0.5
        self.physics: PhysicsWorld | None = None
        self.disc: RigidBody | None = None
        self.apple: StaticBody | None = None

    def reset(self, options: Mapping[str, Any]) -> None:
        """Build a fresh room and put the apple somewhere in it."""
        if self.physics is not None:
            self.remove_child(self.physics)
            self.physics.queue_free()
        physics = PhysicsWorld(gravity=(0.0, 0.0), damping=self.damping, name="Physics")
        physics.add_child(room_walls(elasticity=0.5))
        self.disc = RigidBody(name="Disc")
        self.disc.add_child(CollisionShape.circle(RADIUS, mass=1.0, elasticity=0.5, name="Body"))
        physics.add_child(self.disc)
        self.apple = StaticBody(position=tuple(random_spot(self.np_random)), name="Apple")
        self.apple.add_to_group("apples")
        skin = CollisionShape.circle(0.25, sensor=True, color=(200, 40, 40), name="Skin")
        skin.collision_started.connect(self._on_apple_touched)
        self.apple.add_child(skin)
        physics.add_child(self.apple)
        self.physics = physics
        self.add_child(physics)

    def sample_initial_position(self) -> np.ndarray:
        """A spot for the disc at least 2 m from the apple."""
        assert self.apple is not None
        while True:
            spot = random_spot(self.np_random)
            if np.hypot(*(spot - np.array(self.apple.position))) >= 2.0:
                return spot

    def get_data(self, observation_request: Mapping[str, Any]) -> dict[str, Any]:
        """The apple's position, for displays."""
        assert self.apple is not None
        return {"apple": list(self.apple.position)}

    def _on_apple_touched(self, other: CollisionShape) -> None:
        if other.body_node is self.disc:
            self.apple_caught.emit()


class SeekerAgent(RLAgent):
    """Pushes the disc towards the apple; rewarded when the world says it is caught."""

    configurable = ("max_force",)
    action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    observation_space = spaces.Box(
        low=np.array([-HALF, -HALF, -50, -50, -2 * HALF, -2 * HALF], dtype=np.float32),
        high=np.array([HALF, HALF, 50, 50, 2 * HALF, 2 * HALF], dtype=np.float32),
        dtype=np.float32,
    )

    def __init__(self) -> None:
        super().__init__("Agent")
        self.max_force = 20.0
        self.force = (0.0, 0.0)
        self._disc: pymunk.Body | None = None

    def _ready(self) -> None:
        # Children are ready before their parent, so the environment has not set its world
        # yet: find it by path, as a Godot script would.
        self.get_node("../World").get_signal("apple_caught").connect(self._on_apple_caught)

    def reset(self, arguments: np.ndarray) -> None:
        """Put this episode's disc at the sampled spot, at rest."""
        world = self.environment.world
        assert isinstance(world, SeekerWorld) and world.disc is not None
        self._disc = world.disc.body
        self._disc.position = (float(arguments[0]), float(arguments[1]))
        self._disc.velocity = (0.0, 0.0)
        self.force = (0.0, 0.0)

    def set_action(self, action: np.ndarray) -> None:
        """Remember the force for the ticks of this action."""
        self.force = (float(action[0]) * self.max_force, float(action[1]) * self.max_force)

    def _physics_process(self, delta: float) -> None:
        if self._disc is not None:
            self._disc.apply_force_at_world_point(self.force, self._disc.position)

    def _after_physics_tick(self, delta: float) -> None:
        self.add_reward(-0.01)

    def _on_apple_caught(self) -> None:
        self.add_reward(10.0)
        self.set_terminated()

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Disc position and velocity, and where the apple is from the disc."""
        world = self.environment.world
        assert isinstance(world, SeekerWorld) and world.apple is not None
        disc = self._disc
        assert disc is not None
        x, y = disc.position
        apple_x, apple_y = world.apple.position
        return np.array((x, y, *disc.velocity, apple_x - x, apple_y - y), dtype=np.float32)


class PixelSeekerAgent(SeekerAgent):
    """The same seeker, seeing the room only through a 64x64 camera (``rlenv/SeekerPixels-v0``).

    Its observation space is ``Box(0, 255, (64, 64, 3), uint8)``: the whole room from above,
    the disc blue and the apple red. Actions, rewards and episode end are the seeker's.
    """

    observation_space = spaces.Box(0, 255, (64, 64, 3), np.uint8)

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """What the camera sees."""
        camera = self.get_node("../World/Eye")
        assert isinstance(camera, Camera)
        return camera.capture()


class SeekerEnvironment(RLEnvironment):
    """The apple seeker: an agent and a world under one node."""

    render_view = (-HALF - 0.5, -HALF - 0.5, HALF + 0.5, HALF + 0.5)
    render_size = (400, 400)

    def __init__(self) -> None:
        super().__init__("Seeker", repeat_action=4)
        self.add_child(SeekerAgent())
        self.add_child(SeekerWorld())


class SeekerPixelsEnvironment(SeekerEnvironment):
    """The apple seeker observed from pixels: a camera above the room feeds the agent."""

    def __init__(self) -> None:
        RLEnvironment.__init__(self, "SeekerPixels", repeat_action=4)
        self.add_child(PixelSeekerAgent())
        world = SeekerWorld()
        world.add_child(Camera(view=self.render_view, size=(64, 64), name="Eye"))
        self.add_child(world)


def main() -> None:
    """Serve the seeker: ``python -m examples.seeker [--port P]``."""
    from rlenv_tools.cli import serve_command

    raise SystemExit(serve_command(TARGET))
