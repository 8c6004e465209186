"""2D physics nodes over pymunk: a world that owns a space, and the bodies, shapes and joints in it.

A :class:`PhysicsWorld` owns one ``pymunk.Space`` and steps it once per physics tick with the
tree's fixed delta (in its ``_physics_step``, after every node's ``_physics_process`` of that tick,
as a physics server would). Body, shape and joint nodes below it put their pymunk objects into
that space when they enter the tree and take them out when they leave::

    World (PhysicsWorld)
    |___Cart (RigidBody)
    |   |___Box (CollisionShape)
    |___Pole (RigidBody)
    |   |___Stick (CollisionShape)
    |___Hinge (Joint: PivotJoint between Cart and Pole)

Collisions are reported as signals: every shape's ``collision_started`` / ``collision_ended``
and every body's ``body_entered`` / ``body_exited``, emitted from inside the step (the space is
locked; changes to the tree made by handlers are deferred to the end of the tick).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import pymunk

from rlenv.node import Node, ProcessMode
from rlenv.signals import Signal

__all__ = [
    "CollisionShape",
    "Joint",
    "KinematicBody",
    "PhysicsBody",
    "PhysicsWorld",
    "RigidBody",
    "StaticBody",
]

Vec = tuple[float, float]


class PhysicsWorld(Node):
    """Owns a ``pymunk.Space`` and steps it once per physics tick.

    Args:
        gravity: the space's gravity.
        iterations: solver iterations per step (pymunk's default is 10).
        damping: fraction of velocity kept per second (1 keeps all).
        name: the node name.
        process_mode: when the space steps; by default it follows its parent.
    """

    stepped = Signal("delta")
    """Emitted after every step of the space, with the step length."""

    exported: ClassVar[tuple[str, ...]] = ("gravity", "damping")

    def __init__(
        self,
        gravity: Vec = (0.0, -9.81),
        *,
        iterations: int = 10,
        damping: float = 1.0,
        name: str | None = None,
        process_mode: ProcessMode = ProcessMode.INHERIT,
    ) -> None:
        super().__init__(name, process_mode=process_mode)
        self.space = self._new_space(gravity, iterations, damping)
        self._shape_nodes: dict[pymunk.Shape, CollisionShape] = {}

    def _new_space(self, gravity: Vec, iterations: int, damping: float) -> pymunk.Space:
        space = pymunk.Space()
        space.gravity = gravity
        space.iterations = iterations
        space.damping = damping
        space.on_collision(begin=self._on_begin, separate=self._on_separate)
        return space

    def restart(self) -> None:
        """Start the simulation afresh, as a newly built subtree would: cheap episode resets.

        The bodies, shapes and joints below stay (nodes, pymunk objects and their settings),
        but move into a new space (same gravity, iterations and damping) in tree order, as
        they would on entering it: every body back at the position and angle it was built
        with, at rest (velocities, force and torque zero), and every joint with a fresh
        constraint made there (joints such as ``pivot`` read the bodies' pose when made). No
        solver state (joint impulses, cached contacts, the spatial index) survives; contacts
        in progress end, with their signals. Place the bodies for the episode afterwards.
        """
        old = self.space
        old.remove(*old.constraints, *old.shapes, *old.bodies)
        self.space = self._new_space(old.gravity, old.iterations, old.damping)
        bodies, shapes, joints = [], [], []
        for node in self.iter_subtree():
            if isinstance(node, PhysicsBody) and node.world is self:
                node._restart()
                bodies.append(node.body)
            elif isinstance(node, CollisionShape) and node._world is self:
                shapes.append(node.shape)
            elif isinstance(node, Joint) and node._world is self and node._attached:
                joints.append(node)
        self.space.add(*bodies, *shapes)  # in tree order, as they entered
        for joint in joints:  # once every body is back, as joints attach when ready
            joint.constraint = None
            joint._attach(self, required=True)

    @property
    def gravity(self) -> pymunk.Vec2d:
        """The space's gravity."""
        return self.space.gravity

    @gravity.setter
    def gravity(self, value: Vec) -> None:
        self.space.gravity = value

    @property
    def damping(self) -> float:
        """The fraction of velocity bodies keep per second."""
        return self.space.damping

    @damping.setter
    def damping(self, value: float) -> None:
        self.space.damping = value

    def _physics_step(self, delta: float) -> None:
        self.space.step(delta)
        if self._signals:  # someone asked for a signal of this node
            self._emit("stepped", delta)

    def _on_begin(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        self._report(arbiter, "collision_started", "body_entered")

    def _on_separate(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        self._report(arbiter, "collision_ended", "body_exited")

    def _report(self, arbiter: pymunk.Arbiter, shape_signal: str, body_signal: str) -> None:
        first, second = arbiter.shapes
        a = self._shape_nodes.get(first)
        b = self._shape_nodes.get(second)
        if a is None or b is None:  # a shape that left the tree during this step
            return
        a.get_signal(shape_signal).emit(b)
        b.get_signal(shape_signal).emit(a)
        body_a, body_b = a.body_node, b.body_node
        if body_a is not None and body_b is not None and body_a is not body_b:
            body_a.get_signal(body_signal).emit(body_b)
            body_b.get_signal(body_signal).emit(body_a)


def _world_of(node: Node) -> PhysicsWorld:
    ancestor = node.parent
    while ancestor is not None:
        if isinstance(ancestor, PhysicsWorld):
            return ancestor
        ancestor = ancestor.parent
    raise RuntimeError(f"{node!r} must be placed below a PhysicsWorld")


class PhysicsBody(Node):
    """A node holding one ``pymunk.Body``, in the space of the nearest PhysicsWorld above it.

    Args:
        body: the pymunk body this node owns.
        position: initial position of the body.
        angle: initial angle of the body, in radians.
        name: the node name.
    """

    body_entered = Signal("body")
    """Emitted when one of this body's shapes starts touching another body's shape."""

    exported: ClassVar[tuple[str, ...]] = ("position", "velocity", "angle", "angular_velocity")
    body_exited = Signal("body")
    """Emitted when the last contact with another body ends."""

    def __init__(
        self, body: pymunk.Body, *, position: Vec = (0.0, 0.0), angle: float = 0.0,
        name: str | None = None,
    ) -> None:
        super().__init__(name)
        self.body = body
        body.position = position
        body.angle = angle
        self._built_pose = (position, angle)
        self.world: PhysicsWorld | None = None

    def _enter_tree(self) -> None:
        self.world = _world_of(self)
        self.world.space.add(self.body)

    def _exit_tree(self) -> None:
        if self.world is not None and self.body.space is not None:
            self.world.space.remove(self.body)
        self.world = None

    def _restart(self) -> None:
        """Back to the pose the body was built with, at rest (see PhysicsWorld.restart)."""
        body = self.body
        body.angle = self._built_pose[1]
        body.position = self._built_pose[0]
        if body.body_type != pymunk.Body.STATIC:
            body.velocity = (0.0, 0.0)
            body.angular_velocity = 0.0
            body.force = (0.0, 0.0)
            body.torque = 0.0

    # Godot-style accessors, so tree queries can read and set state without reaching into pymunk.

    @property
    def position(self) -> pymunk.Vec2d:
        """The body's position."""
        return self.body.position

    @position.setter
    def position(self, value: Vec) -> None:
        self.body.position = value

    @property
    def velocity(self) -> pymunk.Vec2d:
        """The body's linear velocity."""
        return self.body.velocity

    @velocity.setter
    def velocity(self, value: Vec) -> None:
        self.body.velocity = value

    @property
    def angle(self) -> float:
        """The body's angle, in radians."""
        return self.body.angle

    @angle.setter
    def angle(self, value: float) -> None:
        self.body.angle = value

    @property
    def angular_velocity(self) -> float:
        """The body's angular velocity, in radians per second."""
        return self.body.angular_velocity

    @angular_velocity.setter
    def angular_velocity(self, value: float) -> None:
        self.body.angular_velocity = value


class RigidBody(PhysicsBody):
    """A dynamic body moved by forces, gravity and contacts.

    With the default ``mass=0`` the body takes its mass and moment from the ``mass`` or
    ``density`` of its :class:`CollisionShape` children, as pymunk recommends.

    Args:
        mass: the body's mass, or 0 to sum its shapes'.
        moment: the moment of inertia, or 0 to sum its shapes'; ``float("inf")`` never rotates.
        position: initial position.
        angle: initial angle, in radians.
        name: the node name.
    """

    def __init__(
        self, mass: float = 0.0, moment: float = 0.0, *, position: Vec = (0.0, 0.0),
        angle: float = 0.0, name: str | None = None,
    ) -> None:
        super().__init__(pymunk.Body(mass, moment), position=position, angle=angle, name=name)

    def apply_force(self, force: Vec, at: Vec = (0.0, 0.0)) -> None:
        """Apply ``force`` (world frame) at the local point ``at`` for the coming step."""
        self.body.apply_force_at_world_point(force, self.body.local_to_world(at))

    def apply_impulse(self, impulse: Vec, at: Vec = (0.0, 0.0)) -> None:
        """Apply ``impulse`` (world frame) at the local point ``at`` now."""
        self.body.apply_impulse_at_world_point(impulse, self.body.local_to_world(at))


class StaticBody(PhysicsBody):
    """A body that never moves (walls, floors, tracks); its shapes collide with dynamic bodies."""

    def __init__(
        self, *, position: Vec = (0.0, 0.0), angle: float = 0.0, name: str | None = None
    ) -> None:
        super().__init__(pymunk.Body(body_type=pymunk.Body.STATIC), position=position,
                         angle=angle, name=name)


class KinematicBody(PhysicsBody):
    """A body moved only by setting its velocity; it pushes dynamic bodies but feels nothing."""

    def __init__(
        self, *, position: Vec = (0.0, 0.0), angle: float = 0.0, name: str | None = None
    ) -> None:
        super().__init__(pymunk.Body(body_type=pymunk.Body.KINEMATIC), position=position,
                         angle=angle, name=name)


class CollisionShape(Node):
    """A pymunk shape attached to the body node it is a child of.

    Build one with a constructor such as :meth:`circle`, :meth:`box`, :meth:`segment` or
    :meth:`poly`, or pass any ``pymunk.Shape`` made with ``body=None``.

    Args:
        shape: the pymunk shape, created without a body.
        mass: the shape's mass (gives the body mass and moment when the body's mass is 0).
        density: the shape's density, as an alternative to ``mass``.
        friction: friction coefficient.
        elasticity: bounciness, 0 to 1.
        sensor: a sensor reports contacts but does not collide (like Godot's Area2D).
        color: RGB colour when rendered; by default it follows the body's kind.
        name: the node name.
    """

    collision_started = Signal("shape")
    """Emitted when this shape starts touching another shape."""

    exported: ClassVar[tuple[str, ...]] = ("friction", "elasticity", "sensor")
    collision_ended = Signal("shape")
    """Emitted when this shape stops touching another shape."""

    def __init__(
        self, shape: pymunk.Shape, *, mass: float = 0.0, density: float = 0.0,
        friction: float = 0.5, elasticity: float = 0.0, sensor: bool = False,
        color: tuple[int, int, int] | None = None, name: str | None = None,
    ) -> None:
        super().__init__(name)
        self.shape = shape
        self.color = color
        if mass:
            shape.mass = mass
        if density:
            shape.density = density
        shape.friction = friction
        shape.elasticity = elasticity
        shape.sensor = sensor
        self.body_node: PhysicsBody | None = None
        self._world: PhysicsWorld | None = None

    @property
    def friction(self) -> float:
        """The shape's friction coefficient."""
        return self.shape.friction

    @friction.setter
    def friction(self, value: float) -> None:
        self.shape.friction = value

    @property
    def elasticity(self) -> float:
        """The shape's bounciness, 0 to 1."""
        return self.shape.elasticity

    @elasticity.setter
    def elasticity(self, value: float) -> None:
        self.shape.elasticity = value

    @property
    def sensor(self) -> bool:
        """Whether the shape only reports contacts instead of colliding."""
        return self.shape.sensor

    @sensor.setter
    def sensor(self, value: bool) -> None:
        self.shape.sensor = value

    @classmethod
    def circle(cls, radius: float, offset: Vec = (0.0, 0.0), **kwargs: Any) -> CollisionShape:
        """A circle of ``radius`` centred at ``offset`` in the body's frame."""
        return cls(pymunk.Circle(None, radius, offset), **kwargs)

    @classmethod
    def box(
        cls, width: float, height: float, radius: float = 0.0, **kwargs: Any
    ) -> CollisionShape:
        """A ``width`` x ``height`` box centred on the body."""
        return cls(pymunk.Poly.create_box(None, (width, height), radius), **kwargs)

    @classmethod
    def segment(cls, a: Vec, b: Vec, radius: float = 0.0, **kwargs: Any) -> CollisionShape:
        """A segment from ``a`` to ``b`` (body frame), ``radius`` thick."""
        return cls(pymunk.Segment(None, a, b, radius), **kwargs)

    @classmethod
    def poly(cls, vertices: Sequence[Vec], radius: float = 0.0, **kwargs: Any) -> CollisionShape:
        """A convex polygon through ``vertices`` (body frame)."""
        return cls(pymunk.Poly(None, vertices, radius=radius), **kwargs)

    def _enter_tree(self) -> None:
        parent = self.parent
        if not isinstance(parent, PhysicsBody):
            raise RuntimeError(f"{self!r} must be a child of a body node, not of {parent!r}")
        self.body_node = parent
        self._world = _world_of(self)
        self.shape.body = parent.body
        self._world.space.add(self.shape)
        self._world._shape_nodes[self.shape] = self

    def _exit_tree(self) -> None:
        if self._world is not None:
            if self.shape.space is not None:
                self._world.space.remove(self.shape)  # reports the contacts that end
            self._world._shape_nodes.pop(self.shape, None)
        self._world = None
        self.body_node = None


ConstraintFactory = Callable[[pymunk.Body, pymunk.Body], pymunk.Constraint]


class Joint(Node):
    """A pymunk constraint between the bodies of two body nodes, named by path (Godot's Joint2D).

    The paths are resolved relative to the joint when it enters the tree (a body that has not
    entered yet is looked up again when the joint becomes ready). Use a constructor such as
    :meth:`pivot`, :meth:`groove`, :meth:`motor` or :meth:`spring`, or pass a factory that builds
    any pymunk constraint from the two bodies.

    Args:
        node_a: path to the first body node.
        node_b: path to the second body node.
        make: builds the constraint from the two ``pymunk.Body`` objects.
        collide_bodies: whether the two bodies still collide with each other.
        max_force: the most force the constraint may apply.
        name: the node name.
    """

    def __init__(
        self, node_a: str, node_b: str, make: ConstraintFactory, *,
        collide_bodies: bool = False, max_force: float = float("inf"), name: str | None = None,
    ) -> None:
        super().__init__(name)
        self.node_a = node_a
        self.node_b = node_b
        self._make = make
        self._collide_bodies = collide_bodies
        self._max_force = max_force
        self.constraint: pymunk.Constraint | None = None
        self._world: PhysicsWorld | None = None
        self._attached = False

    @classmethod
    def pivot(cls, node_a: str, node_b: str, anchor: Vec, **kwargs: Any) -> Joint:
        """A hinge at the world point ``anchor``."""
        return cls(node_a, node_b, lambda a, b: pymunk.PivotJoint(a, b, anchor), **kwargs)

    @classmethod
    def groove(
        cls, node_a: str, node_b: str, groove_a: Vec, groove_b: Vec, anchor_b: Vec = (0.0, 0.0),
        **kwargs: Any,
    ) -> Joint:
        """Keeps ``anchor_b`` of body b on the groove ``groove_a``-``groove_b`` of body a."""
        return cls(
            node_a, node_b, lambda a, b: pymunk.GrooveJoint(a, b, groove_a, groove_b, anchor_b),
            **kwargs,
        )

    @classmethod
    def motor(cls, node_a: str, node_b: str, rate: float = 0.0, **kwargs: Any) -> Joint:
        """Drives the relative angular velocity of the two bodies to ``rate``."""
        return cls(node_a, node_b, lambda a, b: pymunk.SimpleMotor(a, b, rate), **kwargs)

    @classmethod
    def spring(
        cls, node_a: str, node_b: str, anchor_a: Vec, anchor_b: Vec, rest_length: float,
        stiffness: float, damping: float, **kwargs: Any,
    ) -> Joint:
        """A damped spring between two local anchors."""
        return cls(
            node_a, node_b,
            lambda a, b: pymunk.DampedSpring(a, b, anchor_a, anchor_b, rest_length, stiffness,
                                             damping),
            **kwargs,
        )

    def _enter_tree(self) -> None:
        self._world = _world_of(self)
        self._attach(self._world)

    def _ready(self) -> None:
        if self._world is not None and not self._attached:
            self._attach(self._world, required=True)

    def _attach(self, world: PhysicsWorld, required: bool = False) -> None:
        bodies = []
        for path in (self.node_a, self.node_b):
            node = self.get_node_or_null(path)
            if not isinstance(node, PhysicsBody) or node.body.space is None:
                if required:
                    raise RuntimeError(f"{self!r}: no body node in the space at path {path!r}")
                return
            bodies.append(node.body)
        if self.constraint is None:
            self.constraint = self._make(bodies[0], bodies[1])
            self.constraint.collide_bodies = self._collide_bodies
            self.constraint.max_force = self._max_force
        world.space.add(self.constraint)
        self._attached = True

    def _exit_tree(self) -> None:
        if self._world is not None and self._attached:
            self._world.space.remove(self.constraint)
        self._attached = False
        self._world = None
        self.request_ready()  # on re-entry, attach again once the bodies are back
