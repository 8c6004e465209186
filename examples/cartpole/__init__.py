"""CartPole in pymunk: blendtorch's remote CartPole, as an rlenv scene.

A cart runs on a horizontal rail; a pole is hinged on top of it. The agent pushes the cart left
or right and must keep the pole upright and the cart on its track::

    CartPole (CartPoleEnvironment)
    |___PhysicsFramesTimer
    |___Agent (CartPoleAgent)          pushes the cart, observes, is rewarded
    |___World (CartPoleWorld)
        |___Physics (PhysicsWorld)     restarted on every reset, so episodes share no state
            |___Track (StaticBody)
            |   |___Line (CollisionShape)      a sensor: drawn, never touched
            |___Cart (RigidBody)
            |   |___Box (CollisionShape)
            |___Pole (RigidBody)
            |   |___Stick (CollisionShape)
            |___Rail (Joint: groove, Track-Cart)
            |___Hinge (Joint: pivot, Cart-Pole)

## Action Space
``Box(-1, 1, (1,), float32)``: the force on the cart as a fraction of ``max_force`` (10 N);
positive pushes towards +x.

## Observation Space
``Box((5,), float32)``:

| index | observation                      | min    | max   |
|-------|----------------------------------|--------|-------|
| 0     | cart position x (m)              | -4.8   | 4.8   |
| 1     | pole centre-of-mass position x (m)| -5.8  | 5.8   |
| 2     | pole angle (rad, + leans to +x)  | -pi    | pi    |
| 3     | cart velocity (m/s)              | -3.4e38| 3.4e38|
| 4     | pole angular velocity (rad/s)    | -3.4e38| 3.4e38|

## Rewards
+1 for every physics tick the pole stays up, so a step of ``repeat_action`` ticks earns up to
``repeat_action``.

## Episode End
Terminated when the pole leans more than 12 degrees or the cart leaves the track
(``|x| > 2.4`` m). There is no time limit inside the environment (the client adds one).

## Physics
pymunk at 60 ticks per second; the space keeps ``damping`` (0.3) of every velocity per second,
like the default damping of Blender's rigid bodies in the seed's scene. The world's
configurable ``gravity`` (default (0, -9.81) m/s²) applies at once when changed, and to every
later episode.

## Starting State
Cart position and velocity, pole angle and angular velocity each uniform in [-0.05, 0.05],
drawn from the episode's seeded generator.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv import (
    CollisionShape,
    Joint,
    PhysicsWorld,
    RigidBody,
    RLAgent,
    RLEnvironment,
    RLEnvWorld,
    StaticBody,
)

__all__ = ["TARGET", "CartPoleAgent", "CartPoleEnvironment", "CartPoleWorld", "controller", "main"]

TARGET = f"{__name__}:CartPoleEnvironment"
"""What ``rlenv serve`` takes to serve this environment."""

POLE_LENGTH = 1.0
GRAVITY = (0.0, -9.81)
_FLOAT32_MAX = float(np.finfo(np.float32).max)
KAPPA = 2.5


def controller(observation: np.ndarray) -> np.ndarray:
    """The seed's proportional controller: push the cart under the pole's centre of mass."""
    x_cart, x_pole = float(observation[0]), float(observation[1])
    return np.array([np.clip((x_pole - x_cart) * KAPPA, -1.0, 1.0)], dtype=np.float32)


class CartPoleWorld(RLEnvWorld):
    """The track, the cart and the pole, rebuilt from scratch at every reset."""

    configurable = ("track_limit", "pole_mass", "cart_mass", "damping", "gravity")

    def __init__(self, name: str = "World") -> None:
        super().__init__(name)
        self.track_limit = 2.4
        self.cart_mass = 1.0
        self.pole_mass = 0.1
        self.damping = 0.3
        self._gravity = GRAVITY
        self.physics: PhysicsWorld | None = None
        self.cart: RigidBody | None = None
        self.pole: RigidBody | None = None
        self._built_for: tuple[float, float, float] | None = None

    def reset(self, options: Mapping[str, Any]) -> None:
        """Start the physics afresh: no solver state survives an episode.

        The same track, cart and pole restart in a new space (cheap); they are rebuilt only
        when their configuration changed.
        """
        built_for = (self.track_limit, self.cart_mass, self.pole_mass)
        if self.physics is not None and self._built_for == built_for:
            self.physics.damping = self.damping
            self.physics.gravity = self._gravity
            self.physics.restart()
            return
        self._built_for = built_for
        if self.physics is not None:
            self.remove_child(self.physics)
            self.physics.queue_free()
        physics = PhysicsWorld(gravity=self._gravity, damping=self.damping, name="Physics")
        track = StaticBody(name="Track")
        track.add_child(
            CollisionShape.segment(  # drawn, never touched
                (-self.track_limit, -0.2),
                (self.track_limit, -0.2),
                0.01,
                sensor=True,
                color=(120, 120, 120),
                name="Line",
            )
        )
        physics.add_child(track)
        self.cart = RigidBody(self.cart_mass, math.inf, name="Cart")
        self.cart.add_child(CollisionShape.box(0.5, 0.25, name="Box"))
        self.pole = RigidBody(name="Pole")
        self.pole.add_child(
            CollisionShape.segment(
                (0.0, 0.0),
                (0.0, POLE_LENGTH),
                0.02,
                mass=self.pole_mass,
                color=(215, 120, 50),
                name="Stick",
            )
        )
        physics.add_child(self.cart)
        physics.add_child(self.pole)
        physics.add_child(
            Joint.groove("../Track", "../Cart", (-100.0, 0.0), (100.0, 0.0), name="Rail")
        )
        physics.add_child(Joint.pivot("../Cart", "../Pole", (0.0, 0.0), name="Hinge"))
        self.physics = physics
        self.add_child(physics)

    @property
    def gravity(self) -> tuple[float, float]:
        """The gravity (m/s²); a change applies at once, and to every later episode."""
        return self._gravity

    @gravity.setter
    def gravity(self, value: tuple[float, float]) -> None:
        self._gravity = (float(value[0]), float(value[1]))
        if self.physics is not None:
            self.physics.gravity = self._gravity

    def sample_initial_position(self) -> np.ndarray:
        """Cart x, cart velocity, pole angle and pole angular velocity, each in +-0.05."""
        return self.np_random.uniform(-0.05, 0.05, size=4)

    def get_data(self, observation_request: Mapping[str, Any]) -> dict[str, Any]:
        """Positions of the cart and the pole tip, for displays."""
        assert self.cart is not None and self.pole is not None
        tip = self.pole.body.local_to_world((0.0, POLE_LENGTH))
        return {"cart": list(self.cart.position), "pole_tip": list(tip)}


class CartPoleAgent(RLAgent):
    """Pushes the cart; rewarded +1 per tick while the pole is up."""

    configurable = ("max_force", "angle_limit")
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
    observation_space = spaces.Box(
        low=np.array([-4.8, -5.8, -math.pi, -_FLOAT32_MAX, -_FLOAT32_MAX], dtype=np.float32),
        high=np.array([4.8, 5.8, math.pi, _FLOAT32_MAX, _FLOAT32_MAX], dtype=np.float32),
        dtype=np.float32,
    )

    def __init__(self, name: str = "Agent") -> None:
        super().__init__(name)
        self.max_force = 10.0
        self.angle_limit = math.radians(12.0)
        self.force = 0.0
        self._cart: RigidBody | None = None
        self._pole: RigidBody | None = None
        self._track_limit = 0.0

    def reset(self, arguments: np.ndarray) -> None:
        """Place this episode's cart and pole in the sampled initial state."""
        world = self.environment.world
        assert isinstance(world, CartPoleWorld) and world.cart and world.pole
        x, velocity, angle, angular_velocity = arguments.tolist()
        self._cart, self._pole = world.cart, world.pole
        self._track_limit = world.track_limit
        cart, pole = world.cart.body, world.pole.body  # placed on the pymunk bodies
        cart.position = (x, 0.0)
        cart.velocity = (velocity, 0.0)
        pole.angle = -angle  # pymunk turns a body about its centre of gravity: angle first
        pole.position = (x, 0.0)
        pole.angular_velocity = -angular_velocity
        pole.velocity = (velocity, 0.0)
        self.force = 0.0

    def set_action(self, action: np.ndarray) -> None:
        """Remember the force to apply on every tick of the action."""
        self.force = float(action[0]) * self.max_force

    def _physics_process(self, delta: float) -> None:
        if self._cart is not None:
            self._cart.apply_central_force((self.force, 0.0))

    def _after_physics_tick(self, delta: float) -> None:
        assert self._cart is not None and self._pole is not None
        if (
            abs(self._pole.rotation) > self.angle_limit
            or abs(self._cart.position.x) > self._track_limit
        ):
            self.set_terminated()
        else:
            self.add_reward(1.0)

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Cart x, pole x, pole angle, cart velocity, pole angular velocity."""
        cart, pole = self._cart, self._pole
        assert cart is not None and pole is not None
        angle = pole.rotation
        x_pole = pole.position.x - POLE_LENGTH / 2 * math.sin(angle)  # the pole's centre
        return np.array(
            (cart.position.x, x_pole, -angle, cart.linear_velocity.x, -pole.angular_velocity),
            dtype=np.float32,
        )


class CartPoleEnvironment(RLEnvironment):
    """The CartPole environment: an agent and a world under one node."""

    render_view = (-3.0, -1.0, 3.0, 1.5)

    def __init__(self) -> None:
        super().__init__("CartPole", repeat_action=4)
        self.add_child(CartPoleAgent())
        self.add_child(CartPoleWorld())


def main() -> None:
    """Serve CartPole: ``python -m examples.cartpole [--port P]``."""
    from rlenv_tools.cli import serve_command

    raise SystemExit(serve_command(TARGET))
