"""Reacher: a two-link arm with motors reaching a random target (gym-kraby's one leg, in 2D).

Seen from above (no gravity): a base, an upper link hinged on it, a lower link hinged on the upper
one, each hinge driven by a motor that holds the speed the agent asks for, with a limited torque::

    Reacher (ReacherEnvironment)
    |___PhysicsFramesTimer
    |___Agent (ReacherAgent)           sets the motor speeds, observes, is rewarded
    |___World (ReacherWorld)           rebuilds its physics every reset; places the target
        |___Physics (PhysicsWorld)
            |___Base (StaticBody)      |___Hub (a sensor, drawn only)
            |___Upper (RigidBody)      |___Bone (CollisionShape)
            |___Lower (RigidBody)      |___Bone, |___Fingertip (CollisionShape)
            |___Target (StaticBody)    |___Mark (a sensor, drawn only)
            |___Shoulder, Elbow (Joint: pivots)
            |___ShoulderMotor, ElbowMotor (Joint: motors)

## Action Space
``Box(-1, 1, (2,), float32)``: the speed of the shoulder and the elbow, as a fraction of
``max_speed`` (4 rad/s); counter-clockwise is positive.

## Observation Space
``Box((10,), float32)``: cos and sin of the shoulder and elbow angles (4), the target's x and y
(2), the shoulder's and elbow's angular velocities (2), and the fingertip-to-target vector (2).

## Rewards
Each physics tick: ``-delta * (distance + 0.1 * |action|^2)``, with ``distance`` from the
fingertip to the target in metres: the reward of a step is the time integral over its ticks, so
it does not depend on ``repeat_action``.

## Episode End
Never by itself; ``rlenv/Reacher-v0`` truncates after 200 steps of 4 ticks.

## Starting State
Both hinge angles uniform in [-0.1, 0.1] rad, at rest; the target uniform in the ring of radius
0.2 to 0.9 m around the base (the arm reaches 1 m).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pymunk
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

__all__ = ["TARGET", "ReacherAgent", "ReacherEnvironment", "ReacherWorld", "main", "reach"]

TARGET = f"{__name__}:ReacherEnvironment"
LINK = 0.5  # length of each link, in metres


def reach(observation: np.ndarray) -> np.ndarray:
    """A hand-made policy: resolved-rate control of the fingertip towards the target."""
    cos1, sin1, cos2, sin2 = observation[:4]
    error = -observation[8:10]  # target minus fingertip
    angle1 = math.atan2(sin1, cos1)
    angle12 = angle1 + math.atan2(sin2, cos2)
    jacobian = np.array(
        [
            [-LINK * math.sin(angle1) - LINK * math.sin(angle12), -LINK * math.sin(angle12)],
            [LINK * math.cos(angle1) + LINK * math.cos(angle12), LINK * math.cos(angle12)],
        ]
    )
    speeds = np.linalg.pinv(jacobian, rcond=0.05) @ (3.0 * error)
    return np.clip(speeds / 4.0, -1.0, 1.0).astype(np.float32)


class ReacherWorld(RLEnvWorld):
    """The arm and the target; rebuilt from scratch every reset."""

    configurable = ("max_torque",)

    def __init__(self) -> None:
        super().__init__("World")
        self.max_torque = 5.0
        self.physics: PhysicsWorld | None = None
        self.upper: RigidBody | None = None
        self.lower: RigidBody | None = None
        self.target: StaticBody | None = None
        self.motors: tuple[Joint, Joint] | None = None

    def reset(self, options: Mapping[str, Any]) -> None:
        """Build the arm straight along x and put the target somewhere in its reach."""
        if self.physics is not None:
            self.remove_child(self.physics)
            self.physics.queue_free()
        physics = PhysicsWorld(gravity=(0.0, 0.0), damping=0.9, name="Physics")
        base = StaticBody(name="Base")
        base.add_child(CollisionShape.circle(0.06, sensor=True, color=(90, 90, 90), name="Hub"))
        physics.add_child(base)
        self.upper = RigidBody(name="Upper")
        self.upper.add_child(CollisionShape.segment((0, 0), (LINK, 0), 0.03, mass=0.5, name="Bone"))
        self.lower = RigidBody(position=(LINK, 0.0), name="Lower")
        self.lower.add_child(CollisionShape.segment((0, 0), (LINK, 0), 0.03, mass=0.5, name="Bone"))
        self.lower.add_child(
            CollisionShape.circle(0.04, (LINK, 0), mass=0.05, color=(40, 40, 40), name="Fingertip")
        )
        radius = self.np_random.uniform(0.2, 0.9)
        bearing = self.np_random.uniform(-math.pi, math.pi)
        self.target = StaticBody(
            position=(radius * math.cos(bearing), radius * math.sin(bearing)), name="Target"
        )
        self.target.add_child(
            CollisionShape.circle(0.05, sensor=True, color=(200, 40, 40), name="Mark")
        )
        for node in (self.upper, self.lower, self.target):
            physics.add_child(node)
        physics.add_child(Joint.pivot("../Base", "../Upper", (0.0, 0.0), name="Shoulder"))
        physics.add_child(Joint.pivot("../Upper", "../Lower", (LINK, 0.0), name="Elbow"))
        shoulder = Joint.motor(
            "../Base", "../Upper", max_force=self.max_torque, name="ShoulderMotor"
        )
        elbow = Joint.motor("../Upper", "../Lower", max_force=self.max_torque, name="ElbowMotor")
        physics.add_child(shoulder)
        physics.add_child(elbow)
        self.motors = (shoulder, elbow)
        self.physics = physics
        self.add_child(physics)

    def sample_initial_position(self) -> np.ndarray:
        """Shoulder and elbow angles, each uniform in [-0.1, 0.1] rad."""
        return self.np_random.uniform(-0.1, 0.1, size=2)

    def get_data(self, observation_request: Mapping[str, Any]) -> dict[str, Any]:
        """The target's position, for displays."""
        assert self.target is not None
        return {"target": list(self.target.position)}


class ReacherAgent(RLAgent):
    """Drives the two motors; rewarded for a fingertip close to the target, cheaply."""

    configurable = ("max_speed", "control_cost")
    action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    observation_space = spaces.Box(-10.0, 10.0, (10,), np.float32)

    def __init__(self) -> None:
        super().__init__("Agent")
        self.max_speed = 4.0
        self.control_cost = 0.1
        self.action = np.zeros(2, np.float32)
        self._world: ReacherWorld | None = None

    def reset(self, arguments: np.ndarray) -> None:
        """Bend the arm to the sampled angles, at rest.

        Angles are set before positions: pymunk turns a body about its centre of gravity.
        """
        world = self.environment.world
        assert isinstance(world, ReacherWorld) and world.upper and world.lower
        self._world = world
        shoulder, elbow = (float(a) for a in arguments)
        upper, lower = world.upper.body, world.lower.body
        upper.angle = shoulder
        upper.position = (0.0, 0.0)
        lower.angle = shoulder + elbow
        lower.position = upper.local_to_world((LINK, 0.0))
        self.action = np.zeros(2, np.float32)
        self._apply()

    def set_action(self, action: np.ndarray) -> None:
        """Set the motor speeds for the ticks of this action."""
        self.action = action
        self._apply()

    def _apply(self) -> None:
        assert self._world is not None and self._world.motors is not None
        for motor, speed in zip(self._world.motors, self.action, strict=True):
            assert motor.constraint is not None
            motor.constraint.rate = -float(speed) * self.max_speed  # pymunk: b turns at -rate

    def _after_physics_tick(self, delta: float) -> None:
        distance = float(np.hypot(*self._fingertip_to_target()))
        effort = float(np.dot(self.action, self.action))
        self.add_reward(-delta * (distance + self.control_cost * effort))

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Joint angles (as cos, sin), target, joint speeds, fingertip-to-target."""
        assert self._world is not None and self._world.upper and self._world.lower
        assert self._world.target is not None
        upper, lower = self._world.upper.body, self._world.lower.body
        shoulder, elbow = upper.angle, lower.angle - upper.angle
        return np.array(
            (
                math.cos(shoulder),
                math.sin(shoulder),
                math.cos(elbow),
                math.sin(elbow),
                *self._world.target.position,
                upper.angular_velocity,
                lower.angular_velocity - upper.angular_velocity,
                *self._fingertip_to_target(),
            ),
            dtype=np.float32,
        )

    def _fingertip_to_target(self) -> pymunk.Vec2d:
        assert self._world is not None and self._world.lower and self._world.target
        return self._world.lower.body.local_to_world((LINK, 0.0)) - self._world.target.position


class ReacherEnvironment(RLEnvironment):
    """The reacher: an agent and a world under one node."""

    render_view = (-1.1, -1.1, 1.1, 1.1)
    render_size = (400, 400)

    def __init__(self) -> None:
        super().__init__("Reacher", repeat_action=4)
        self.add_child(ReacherAgent())
        self.add_child(ReacherWorld())


def main() -> None:
    """Serve the reacher: ``python -m examples.reacher [--port P]``."""
    from rlenv_tools.cli import serve_command

    raise SystemExit(serve_command(TARGET))
