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

Collisions are reported as signals: every shape's ``collision_started(shape)`` /
``collision_ended(shape)`` and every body's ``body_entered(body)`` / ``body_exited(body)``, with
the other shape or body node as the argument. They are emitted from inside the step (the space
is locked; changes to the tree made by handlers are deferred to the end of the tick).

Bodies are :class:`~rlenv.scene2d.node2d.Node2D` s: a body below a Node2D frame enters its space
at the pose composed from the frames above it (under plain nodes, its pose is the world's), and
its ``position`` and ``rotation`` read back relative to that frame. Every node here can be
copied (:meth:`~rlenv.node.Node.duplicate`: a copy owns its own pymunk objects) and packed
(:class:`~rlenv.scene2d.packed_scene.PackedScene`).

**Units.** pymunk has none of its own: any consistent set works. rlenv's defaults read as SI
units (gravity ``(0, -9.81)`` in metres per second squared, y up; ``delta`` in seconds), and
the examples use metres, kilograms and seconds: then forces are in newtons, impulses in
newton-seconds, torques in newton-metres. Angles are in radians, counter-clockwise (with y up).

**Frames.** A point or vector is either in *world* coordinates, in a *body's* own frame, whose
origin is the body's position and whose axes turn with its angle, or relative to a Node2D.
Shape geometry (``offset``, box, segment and polygon points) and joint anchors other than
:meth:`Joint.pivot`'s are in the body's frame; a body's :attr:`~PhysicsBody.position` and
:attr:`~PhysicsBody.rotation` are relative to its nearest Node2D ancestor (world coordinates
without one); velocities, gravity, forces and impulses are in world coordinates. Values read
back are ``pymunk.Vec2d`` (a tuple of two floats with vector arithmetic); any ``(x, y)`` pair
sets them.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import pymunk
from pymunk import Vec2d

from rlenv.node import Node, ProcessMode
from rlenv.scene2d.chipmunk import (
    FAST,
    Refill,
    apply_central_force,
    bodies_to_check,
    body_angle,
    body_angular_velocity,
    body_position,
    body_velocity,
    collision_handlers,
    place_at_rest,
    refresh_constraint,
    renumber,
    set_body_angular_velocity,
    set_body_velocity,
    step_space,
)
from rlenv.scene2d.colors import RGB, Color, to_rgb
from rlenv.scene2d.node2d import Node2D, Pose, compose, frame_of, relative_pose
from rlenv.scene2d.pymunk_data import (
    ConstraintRecipe,
    copy_body,
    copy_shape,
    integer,
    number,
    vector,
)
from rlenv.signals import Signal

logger = logging.getLogger(__name__)

__all__ = [
    "CollisionShape",
    "Joint",
    "KinematicBody",
    "PhysicsBody",
    "PhysicsWorld",
    "RigidBody",
    "StaticBody",
    "step_space",
]

Vec = tuple[float, float]

_SPACE_SETTINGS = ("collision_slop", "collision_bias", "collision_persistence",
                   "idle_speed_threshold", "sleep_time_threshold")
"""What a space is set up with besides gravity, iterations and damping (and its handlers)."""


class PhysicsWorld(Node):
    """Owns a ``pymunk.Space`` and steps it once per physics tick.

    The space steps by the tree's fixed ``delta`` in ``_physics_step``, after every node's
    ``_physics_process`` of the tick (so forces applied there act in this tick's step). Bodies,
    shapes and joints anywhere below the world join its space (the nearest world above them).

    Args:
        gravity: the space's gravity, a world vector (acceleration, e.g. metres per second
            squared: the default pulls down along y).
        iterations: solver iterations per step (pymunk's default is 10).
        damping: fraction of velocity kept per second (1 keeps all; 0.9 loses 10% a second).
        name: the node name.
        process_mode: when the space steps; by default it follows its parent.

    Attributes:
        space: the ``pymunk.Space``; :meth:`restart` replaces it with a new one.
    """

    stepped = Signal("delta")
    """``stepped(delta)``: emitted after every step of the space (``delta``: its length, s)."""

    exported: ClassVar[tuple[str, ...]] = ("gravity", "damping")
    _TREE_STATE = Node._TREE_STATE | {"_shape_nodes", "_kept_members", "_touched"}

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
        self.space = self._new_space(vector(gravity, "gravity"),
                                     integer(iterations, "iterations", 1, 2**31 - 1),
                                     number(damping, "damping", low=0.0))
        self._shape_nodes: dict[pymunk.Shape, CollisionShape] = {}
        self._kept_members: tuple[int | None, list[PhysicsBody], list[CollisionShape],
                                  list[Joint], Refill] | None = None  # see _members
        self._touched = False  # a contact began since the space was made or restarted

    def _new_space(self, gravity: Vec, iterations: int, damping: float) -> pymunk.Space:
        space = pymunk.Space()
        space.gravity = gravity
        space.iterations = iterations
        space.damping = damping
        space.on_collision(begin=self._on_begin, separate=self._on_separate)
        return space

    def _space_like(self, old: pymunk.Space) -> pymunk.Space:
        """An empty space set up as ``old``: its settings and every collision handler."""
        space = self._new_space(old.gravity, old.iterations, old.damping)
        for name in _SPACE_SETTINGS:
            setattr(space, name, getattr(old, name))
        for key, handler in collision_handlers(old).items():
            if key != (None, None):  # rlenv's own, set up by _new_space
                space.on_collision(*key, begin=handler.begin, pre_solve=handler.pre_solve,
                                   post_solve=handler.post_solve, separate=handler.separate,
                                   data=handler.data)
        return space

    def restart(self) -> None:
        """Start the simulation afresh, as a newly built subtree would: cheap episode resets.

        The bodies, shapes and joints below stay (nodes, pymunk objects and their settings),
        but start again in a space as new (same gravity, iterations and damping), in tree order,
        as they would on entering it: every body back at the pose it entered its space with
        (composed through its Node2D frames, so each copy of a lattice goes back to its own
        place), at rest (velocities, force and torque zero), and every joint's constraint as
        when it was made (joints such as ``pivot`` read the bodies' pose when made). No solver
        state (joint impulses, cached contacts, the spatial index) survives; contacts in
        progress end, with their signals. Place the bodies for the episode afterwards.

        The space is a new one, unless it can be made exactly as new in place: the same
        bodies, shapes and joints as at the previous restart (the tree below unchanged), no
        contact since then (Chipmunk's contact cache never grew), no collision handler but
        rlenv's and no sleeping; then it is emptied and its counters set back (cheaper).
        """
        old = self.space
        bodies, shapes, joints, refill, unchanged = self._members()
        in_place = FAST and unchanged and not self._touched and \
            len(collision_handlers(old)) == 1 and old.sleep_time_threshold == math.inf
        self._touched = False
        if in_place and refill.into(old):
            return
        old.remove(*old.constraints, *old.shapes, *old.bodies)
        if in_place:
            renumber(old)
        else:
            self.space = self._space_like(old)
        for body in bodies:
            body._restart()
        self.space.add(*[body.body for body in bodies], *[shape.shape for shape in shapes])
        for joint in joints:  # once every body is back, as joints attach when ready
            joint._reattach(self)

    def _members(self) -> tuple[list[PhysicsBody], list[CollisionShape], list[Joint], Refill,
                                bool]:
        """The bodies, shapes and joints in this world's space, in tree order, and their Refill.

        Kept while the tree's structure stays the same; the last item says whether it did since
        the previous call.
        """
        tree = self._tree
        version = None if tree is None else tree.structure_version
        members = self._kept_members
        if members is not None and version is not None and members[0] == version:
            return members[1], members[2], members[3], members[4], True
        bodies, shapes, joints = [], [], []
        for node in self.iter_subtree():
            if isinstance(node, PhysicsBody) and node.world is self:
                bodies.append(node)
            elif isinstance(node, CollisionShape) and node._world is self:
                shapes.append(node)
            elif isinstance(node, Joint) and node._world is self and node._attached:
                joints.append(node)
        refill = Refill([body.body for body in bodies], [shape.shape for shape in shapes],
                        [joint.constraint for joint in joints],
                        [body._built_pose for body in bodies])
        self._kept_members = (version, bodies, shapes, joints, refill)
        return bodies, shapes, joints, refill, False

    @property
    def iterations(self) -> int:
        """Solver iterations per step."""
        return self.space.iterations

    def _duplicate_resources(self, memo: dict[int, Any]) -> None:
        space = self.space
        memo[id(space)] = self._space_like(space)

    def _duplicated(self, original: Node) -> None:
        self._shape_nodes = {}
        self._kept_members = None
        self._touched = False

    @property
    def gravity(self) -> pymunk.Vec2d:
        """The space's gravity, a world vector; clients may read and set it (exported)."""
        return self.space.gravity

    @gravity.setter
    def gravity(self, value: Vec) -> None:
        self.space.gravity = vector(value, f"{self!r}: gravity")

    @property
    def damping(self) -> float:
        """The fraction of velocity bodies keep per second; exported."""
        return self.space.damping

    @damping.setter
    def damping(self, value: float) -> None:
        self.space.damping = number(value, f"{self!r}: damping", low=0.0)

    def _enter_tree(self) -> None:
        parent = self.parent
        others = [node.name for node in parent.get_children()
                  if node is not self and isinstance(node, PhysicsWorld)] if parent else []
        if others:
            logger.warning("%r enters beside %s: each PhysicsWorld simulates a space of its own. "
                           "Left from an earlier reset? Remove the old one first", self,
                           ", ".join(others))

    def _physics_step(self, delta: float) -> None:
        if bodies_to_check(self.space):  # added since the last step: pymunk checks them
            self._check_masses()
        step_space(self.space, delta)
        if self._signals:  # someone asked for a signal of this node
            self._emit("stepped", delta)

    def _check_masses(self) -> None:
        """Refuse, naming the node, a dynamic body without a positive, finite mass and moment."""
        for body in bodies_to_check(self.space):
            if body.body_type == pymunk.Body.DYNAMIC and not (
                    0 < body.mass < math.inf and body.moment > 0):
                node = next((node for node in self.iter_subtree()
                             if isinstance(node, PhysicsBody) and node.body is body), body)
                raise ValueError(f"{node!r} has mass {body.mass} and moment {body.moment}: give "
                                 "it a mass and moment, or its CollisionShape children a mass "
                                 "or density")

    def _on_begin(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        self._touched = True
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


class PhysicsBody(Node2D):
    """A Node2D holding one ``pymunk.Body``, in the space of the nearest PhysicsWorld above it.

    Outside a space the node keeps its pose (local, as any Node2D's; the pymunk body's own
    pose is only meaningful in a space). When it enters the tree, its body is placed at the
    pose composed from its Node2D ancestors (the world's pose when it has none), which is also
    the pose :meth:`PhysicsWorld.restart` puts it back to;
    from then on the simulation moves it, and :attr:`position` and :attr:`rotation` read and
    set the body's pose relative to the frame above. When it leaves, it keeps the pose it had,
    relative to that frame.

    The base of :class:`RigidBody`, :class:`StaticBody` and :class:`KinematicBody`: build those.
    The body joins the space when the node enters the tree (it must be below a
    :class:`PhysicsWorld`) and leaves it when the node leaves. Its shapes are its
    :class:`CollisionShape` children. Its state (:attr:`position`, :attr:`velocity`,
    :attr:`angle`, :attr:`angular_velocity`) is exported: clients may read and set it.

    Args:
        body: the pymunk body this node owns.
        position: initial position of the body's origin, relative to the nearest Node2D
            ancestor (in world coordinates without one).
        angle: initial angle in radians, counter-clockwise (the same as ``rotation``; give one
            of them).
        rotation: initial rotation in radians, relative to that frame.
        name: the node name.

    Attributes:
        body: the ``pymunk.Body``, for what these properties do not cover.
        world: the :class:`PhysicsWorld` whose space holds the body (``None`` outside a tree).
    """

    body_entered = Signal("body")
    """``body_entered(body)``: a shape of this body started touching a shape of ``body``, the
    other body node.

    Emitted once per pair of shapes that touch (two of this body's shapes touching ``body``
    emit it twice), for sensors too, and on both bodies: the other one emits it with this one.
    """

    exported: ClassVar[tuple[str, ...]] = ("position", "velocity", "angle", "angular_velocity")
    _TREE_STATE = Node2D._TREE_STATE | {"world", "_frame", "_built_pose", "_frame_pose"}
    body_exited = Signal("body")
    """``body_exited(body)``: a shape of this body stopped touching a shape of ``body``.

    Emitted once per pair of shapes, like :attr:`body_entered`: when one of several contacts
    with ``body`` ends, the others go on. Also emitted when a shape in contact leaves the space
    (it left the tree, or :meth:`PhysicsWorld.restart`).
    """

    def __init__(
        self, body: pymunk.Body, *, position: Vec = (0.0, 0.0), angle: float = 0.0,
        rotation: float = 0.0, name: str | None = None,
    ) -> None:
        if angle and rotation:
            raise ValueError("give the body's rotation or its angle (the same thing), not both")
        super().__init__(name, position=position, rotation=rotation or angle)
        self.body = body
        body.position = self._position
        body.angle = self._rotation
        self.world: PhysicsWorld | None = None
        self._frame: Node2D | None = None  # the nearest Node2D ancestor, while in a space
        self._built_pose: Pose | None = None  # where it entered its space
        self._frame_pose: Pose | None = None  # where its frame was then

    @property
    def _in_space(self) -> bool:
        return self.world is not None

    def _enter_tree(self) -> None:
        world = _world_of(self)
        frame = self._frame = frame_of(self)
        x, y = self._position
        angle = self._rotation
        if frame is not None:
            self._frame_pose = frame._global_pose()
            x, y, angle = compose(self._frame_pose, x, y, angle)
        if self.body.space is not None:
            raise RuntimeError(f"{self!r}: its body is in a space already (was _enter_tree "
                               "called outside the tree's lifecycle?)")
        self._built_pose = (x, y, angle)
        self._set_body_pose(x, y, angle)
        self.world = world
        world.space.add(self.body)

    def _exit_tree(self) -> None:
        if self.world is not None:
            x, y, angle = self._local_pose()
            self._position = Vec2d(x, y)
            self._rotation = angle
            if self.body.space is not None:
                self.world.space.remove(self.body)
        self.world = None
        self._frame = None
        self._frame_pose = None

    def _restart(self) -> None:
        """Back to the pose the body was built with, at rest (see PhysicsWorld.restart)."""
        assert self._built_pose is not None
        place_at_rest(self.body, *self._built_pose)

    def _set_body_pose(self, x: float, y: float, angle: float) -> None:
        """Angle first: pymunk turns a body about its centre of gravity, then places it."""
        body = self.body
        if body.angle != angle:
            body.angle = angle
        body.position = (x, y)

    # --- Node2D in a space: the body is the pose -----------------------------------------------

    def _global_pose(self) -> Pose:
        if self.world is None:
            return super()._global_pose()
        x, y = self.body.position
        return (x, y, self.body.angle)

    def _local_pose(self) -> Pose:
        """The pose in the frame (in a space), exactly as placed while neither has moved."""
        body = self.body
        x, y = body.position
        pose = (x, y, body.angle)
        frame = self._frame
        if frame is None:
            return pose
        frame_pose = frame._global_pose()
        if pose == self._built_pose and frame_pose == self._frame_pose:
            return (self._position.x, self._position.y, self._rotation)
        return relative_pose(frame_pose, pose)

    def _store_pose(self, x: float, y: float, rotation: float) -> None:
        if self.world is None:  # outside a space the node keeps its pose, placed on entry
            super()._store_pose(x, y, rotation)
            return
        if self._frame is not None:
            x, y, rotation = compose(self._frame._global_pose(), x, y, rotation)
        self._place((x, y, rotation))

    def _place(self, pose: Pose) -> None:
        """Put the body at ``pose`` (in the world) now, its velocities kept."""
        self._set_body_pose(*pose)
        body = self.body
        if body.body_type == pymunk.Body.STATIC and body.space is not None:
            body.space.reindex_shapes_for_body(body)  # pymunk's rule for moved static bodies

    def _duplicate_resources(self, memo: dict[int, Any]) -> None:
        memo[id(self.body)] = copy_body(self.body)

    def _duplicated(self, original: Node) -> None:
        assert isinstance(original, PhysicsBody)
        if original.world is not None:  # where the original is now, relative to its frame
            x, y, angle = original._local_pose()
            self._position = Vec2d(x, y)
            self._rotation = angle
        self.world = None
        self._frame = None
        self._built_pose = None
        self._frame_pose = None

    # Godot-style accessors, so tree queries can read and set state without reaching into pymunk.

    @property
    def position(self) -> Vec2d:
        """Where the body's origin is, relative to the nearest Node2D ancestor.

        In world coordinates without one. The origin is the point its shapes' geometry is
        measured from.
        """
        if self._frame is None and self.world is not None:  # the body's pose is the pose
            return body_position(self.body)
        if self.world is None:
            return self._position
        x, y, _ = self._local_pose()
        return Vec2d(x, y)

    @position.setter
    def position(self, value: Vec) -> None:
        Node2D.position.fset(self, value)  # type: ignore[attr-defined]

    @property
    def rotation(self) -> float:
        """The rotation in radians, relative to the nearest Node2D ancestor."""
        if self._frame is None and self.world is not None:
            return body_angle(self.body)
        if self.world is None:
            return self._rotation
        return self._local_pose()[2]

    @rotation.setter
    def rotation(self, value: float) -> None:
        Node2D.rotation.fset(self, value)  # type: ignore[attr-defined]

    @property
    def angle(self) -> float:
        """The body's angle in radians: its :attr:`rotation`."""
        return self.rotation

    @angle.setter
    def angle(self, value: float) -> None:
        self.rotation = value

    @property
    def velocity(self) -> pymunk.Vec2d:
        """The body's linear velocity, in world coordinates (units per second)."""
        return body_velocity(self.body)

    @velocity.setter
    def velocity(self, value: Vec) -> None:
        x, y = value
        set_body_velocity(self.body, x, y)

    linear_velocity = velocity  # Godot's name (RigidBody2D's): the same property

    @property
    def angular_velocity(self) -> float:
        """The body's angular velocity, in radians per second, counter-clockwise."""
        return body_angular_velocity(self.body)

    @angular_velocity.setter
    def angular_velocity(self, value: float) -> None:
        set_body_angular_velocity(self.body, value)

    @property
    def color(self) -> RGB | None:
        """The colour of the body's first collision shape; setting it colours all of them."""
        for child in self._children:
            if isinstance(child, CollisionShape):
                return child.color
        return None

    @color.setter
    def color(self, value: Color | None) -> None:
        for child in self._children:
            if isinstance(child, CollisionShape):
                child.color = value


class RigidBody(PhysicsBody):
    """A dynamic body moved by forces, gravity and contacts (Godot's RigidBody2D).

    Give it mass in one of two ways. As pymunk recommends, leave ``mass`` and ``moment`` at 0
    and give its :class:`CollisionShape` children a ``mass`` or ``density``: the body's mass,
    moment of inertia and centre of gravity are then computed from its shapes. Or give the body
    ``mass`` and ``moment`` and its shapes none (a shape with a mass or density replaces both,
    as in pymunk); ``moment=math.inf`` makes a body that never rotates (the CartPole cart).

    Push it with :meth:`apply_central_force` or :meth:`apply_force` every tick (in
    ``_physics_process``), kick it with :meth:`apply_impulse`, or set its
    :attr:`~PhysicsBody.linear_velocity` directly.

    Args:
        mass: the body's mass, or 0 to sum its shapes' (as pymunk recommends).
        moment: its moment of inertia (mass times length squared), or 0 to sum its shapes';
            ``math.inf`` never rotates.
        position: initial position of its origin, relative to the nearest Node2D ancestor (in
            world coordinates without one).
        angle: initial angle, in radians, counter-clockwise (or ``rotation``: the same).
        rotation: initial rotation, in radians.
        name: the node name.
    """

    def __init__(
        self, mass: float = 0.0, moment: float = 0.0, *, position: Vec = (0.0, 0.0),
        angle: float = 0.0, rotation: float = 0.0, name: str | None = None,
    ) -> None:
        super().__init__(pymunk.Body(mass, moment), position=position, angle=angle,
                         rotation=rotation, name=name)

    def apply_force(self, force: Vec, at: Vec = (0.0, 0.0)) -> None:
        """Push the body with ``force`` during the coming step of the space.

        Forces add up until the space steps, and pymunk clears them after every step: apply
        a steady force again every tick, in ``_physics_process`` (which runs before the step).
        A force away from the centre of gravity also turns the body.

        Args:
            force: the force, in world coordinates (e.g. newtons): ``(0, 10)`` pushes up
                whatever the body's angle.
            at: where it acts, a point in the body's own frame (it turns with the body); the
                body's origin by default.
        """
        self.body.apply_force_at_world_point(force, self.body.local_to_world(at))

    def apply_central_force(self, force: Vec) -> None:
        """Push the body with ``force`` at its centre of gravity: it does not turn the body.

        Godot's ``apply_central_force``. As with :meth:`apply_force`, pymunk clears forces
        after every step: apply it again every tick.

        Args:
            force: the force, in world coordinates.
        """
        apply_central_force(self.body, force)

    def apply_impulse(self, impulse: Vec, at: Vec = (0.0, 0.0)) -> None:
        """Change the body's velocity at once by ``impulse`` (divided by its mass).

        Args:
            impulse: the impulse, in world coordinates (force times time, e.g. newton-seconds).
            at: where it acts, a point in the body's own frame; the body's origin by default.
        """
        self.body.apply_impulse_at_world_point(impulse, self.body.local_to_world(at))


class StaticBody(PhysicsBody):
    """A body that never moves: walls, floors, tracks (Godot's StaticBody2D).

    Gravity, forces and contacts do not move it: rigid bodies collide with its shapes as with
    something infinitely heavy. Place it with ``position`` and ``rotation`` when building it.
    Its ``body_entered`` / ``body_exited`` signals report what touches it.

    Args:
        position: where its origin is, relative to the nearest Node2D ancestor (in world
            coordinates without one).
        angle: its angle, in radians, counter-clockwise (or ``rotation``: the same).
        rotation: its rotation, in radians.
        name: the node name.
    """

    def __init__(
        self, *, position: Vec = (0.0, 0.0), angle: float = 0.0, rotation: float = 0.0,
        name: str | None = None,
    ) -> None:
        super().__init__(pymunk.Body(body_type=pymunk.Body.STATIC), position=position,
                         angle=angle, rotation=rotation, name=name)


class KinematicBody(PhysicsBody):
    """A body moved only by its own velocity: platforms, doors, scripted movers.

    It keeps the :attr:`~PhysicsBody.velocity` and :attr:`~PhysicsBody.angular_velocity` you
    set (gravity, forces and contacts do not change them) and pushes rigid bodies as if it were
    infinitely heavy.

    Args:
        position: initial position of its origin, relative to the nearest Node2D ancestor (in
            world coordinates without one).
        angle: initial angle, in radians, counter-clockwise (or ``rotation``: the same).
        rotation: initial rotation, in radians.
        name: the node name.
    """

    def __init__(
        self, *, position: Vec = (0.0, 0.0), angle: float = 0.0, rotation: float = 0.0,
        name: str | None = None,
    ) -> None:
        super().__init__(pymunk.Body(body_type=pymunk.Body.KINEMATIC), position=position,
                         angle=angle, rotation=rotation, name=name)


class CollisionShape(Node):
    """A pymunk shape attached to the body node it is a child of (Godot's CollisionShape2D).

    Build one with :meth:`circle`, :meth:`box`, :meth:`segment` or :meth:`poly`, which take the
    geometry in the body's own frame plus this constructor's keywords, or pass any
    ``pymunk.Shape`` made with ``body=None``::

        cart.add_child(CollisionShape.box(0.5, 0.3, mass=1.0, friction=0.8, name="Box"))
        floor.add_child(CollisionShape.segment((-5, 0), (5, 0), radius=0.02))

    The shape joins the space when the node enters the tree, on its parent's body (the parent
    must be a :class:`RigidBody`, :class:`StaticBody` or :class:`KinematicBody`). Its
    :attr:`friction`, :attr:`elasticity` and :attr:`sensor` are exported: clients may read and
    set them.

    Args:
        shape: the pymunk shape, created without a body.
        mass: the shape's mass; a shape with a mass or density sets its body's mass, moment
            and centre of gravity (summed over the body's shapes).
        density: mass per unit of area, instead of ``mass``.
        friction: friction coefficient (a contact's friction is the product of its two
            shapes'); 0 is frictionless.
        elasticity: bounciness, 0 (none) to 1 (a perfect bounce); a contact's elasticity is the
            product of its two shapes'.
        sensor: a sensor reports contacts (its signals and its body's) but does not collide,
            like Godot's Area2D.
        color: its colour when rendered (a CSS name, ``"#rrggbb"`` or an RGB triple, 0-255
            each); by default the colour of the body's kind.
        name: the node name.

    Attributes:
        shape: the ``pymunk.Shape``.
        color: the colour it is drawn in, or ``None`` for its body's kind's.
        body_node: the body node it is attached to (``None`` outside a tree).
    """

    collision_started = Signal("shape")
    """``collision_started(shape)``: this shape started touching ``shape``, the other
    CollisionShape node (sensors included; emitted on both shapes)."""

    exported: ClassVar[tuple[str, ...]] = ("friction", "elasticity", "sensor")
    _TREE_STATE = Node._TREE_STATE | {"body_node", "_world"}
    collision_ended = Signal("shape")
    """``collision_ended(shape)``: this shape stopped touching ``shape`` (or one of the two left
    the space)."""

    def __init__(
        self, shape: pymunk.Shape, *, mass: float = 0.0, density: float = 0.0,
        friction: float = 0.5, elasticity: float = 0.0, sensor: bool = False,
        color: Color | None = None, name: str | None = None,
    ) -> None:
        super().__init__(name)
        if shape.space is not None:
            raise ValueError(f"{self!r}: the shape is in a space already; give each "
                             "CollisionShape a shape of its own")
        number(shape.radius, f"{self!r}: radius", low=0.0)
        self.shape = shape
        self.color = color
        if mass:
            shape.mass = number(mass, f"{self!r}: mass", low=0.0)
        if density:
            shape.density = number(density, f"{self!r}: density", low=0.0)
        self.friction = friction
        self.elasticity = elasticity
        shape.sensor = sensor
        self.body_node: PhysicsBody | None = None
        self._world: PhysicsWorld | None = None

    @property
    def color(self) -> RGB | None:
        """The RGB colour the shape is drawn in (``None``: its body's kind decides).

        Set it to a CSS name, ``"#rrggbb"`` or an RGB triple (see :func:`~rlenv.scene2d
        .colors.to_rgb`); it reads back as an RGB triple.
        """
        return self._color

    @color.setter
    def color(self, value: Color | None) -> None:
        self._color = None if value is None else to_rgb(value)

    def _duplicate_resources(self, memo: dict[int, Any]) -> None:
        memo[id(self.shape)] = copy_shape(self.shape)

    def _duplicated(self, original: Node) -> None:
        self.body_node = None
        self._world = None

    @property
    def friction(self) -> float:
        """The shape's friction coefficient (a contact uses the product of both shapes')."""
        return self.shape.friction

    @friction.setter
    def friction(self, value: float) -> None:
        self.shape.friction = number(value, f"{self!r}: friction", low=0.0)

    @property
    def elasticity(self) -> float:
        """The shape's bounciness, 0 to 1 (a contact uses the product of both shapes')."""
        return self.shape.elasticity

    @elasticity.setter
    def elasticity(self, value: float) -> None:
        self.shape.elasticity = number(value, f"{self!r}: elasticity", low=0.0)

    @property
    def sensor(self) -> bool:
        """Whether the shape only reports contacts instead of colliding."""
        return self.shape.sensor

    @sensor.setter
    def sensor(self, value: bool) -> None:
        self.shape.sensor = value

    @classmethod
    def circle(cls, radius: float, offset: Vec = (0.0, 0.0), **kwargs: Any) -> CollisionShape:
        """A circle (Godot's CircleShape2D), e.g. ``CollisionShape.circle(0.1, mass=1.0)``.

        Args:
            radius: its radius (e.g. metres).
            offset: its centre, in the body's frame; the body's origin by default.
            **kwargs: the constructor's keywords: ``mass``, ``density``, ``friction``,
                ``elasticity``, ``sensor``, ``color``, ``name``.
        """
        return cls(pymunk.Circle(None, radius, offset), **kwargs)

    @classmethod
    def box(
        cls, width: float, height: float, radius: float = 0.0, **kwargs: Any
    ) -> CollisionShape:
        """A rectangle centred on the body's origin, aligned with its axes (RectangleShape2D).

        Example: ``CollisionShape.box(0.5, 0.3, mass=1.0)``. For a box off the origin, use
        :meth:`poly` with its four corners.

        Args:
            width: its size along the body's x axis (e.g. metres).
            height: its size along the body's y axis.
            radius: rounds the corners: the box grows by ``radius`` on every side.
            **kwargs: the constructor's keywords: ``mass``, ``density``, ``friction``,
                ``elasticity``, ``sensor``, ``color``, ``name``.
        """
        return cls(pymunk.Poly.create_box(None, (width, height), radius), **kwargs)

    @classmethod
    def segment(cls, a: Vec, b: Vec, radius: float = 0.0, **kwargs: Any) -> CollisionShape:
        """A line from ``a`` to ``b``, with round ends (SegmentShape2D): floors, walls, rods.

        Example: ``CollisionShape.segment((-5, 0), (5, 0), radius=0.02)`` on a
        :class:`StaticBody`.

        Args:
            a: one end, in the body's frame.
            b: the other end, in the body's frame.
            radius: its thickness: every point within ``radius`` of the line belongs to it
                (0 is infinitely thin, which fast bodies may pass through).
            **kwargs: the constructor's keywords: ``mass``, ``density``, ``friction``,
                ``elasticity``, ``sensor``, ``color``, ``name``.
        """
        return cls(pymunk.Segment(None, a, b, radius), **kwargs)

    @classmethod
    def poly(cls, vertices: Sequence[Vec], radius: float = 0.0, **kwargs: Any) -> CollisionShape:
        """A convex polygon (ConvexPolygonShape2D): the convex hull of ``vertices``.

        Args:
            vertices: its corners, in the body's frame, in any order (pymunk takes their convex
                hull, so a concave outline needs several shapes).
            radius: rounds the corners: the polygon grows by ``radius`` on every side.
            **kwargs: the constructor's keywords: ``mass``, ``density``, ``friction``,
                ``elasticity``, ``sensor``, ``color``, ``name``.
        """
        return cls(pymunk.Poly(None, vertices, radius=radius), **kwargs)

    def _enter_tree(self) -> None:
        parent = self.parent
        if not isinstance(parent, PhysicsBody):
            raise RuntimeError(f"{self!r} must be a child of a body node, not of {parent!r}")
        if self.shape.space is not None:
            raise RuntimeError(f"{self!r}: its shape is in a space already (was _enter_tree "
                               "called outside the tree's lifecycle?)")
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

    The paths are relative to the joint (``../Cart`` for a sibling of the joint) and are
    resolved when it enters the tree; a body that has not entered yet is looked up again when
    the joint becomes ready, and then it must be there. So a copy of a subtree holding a joint
    and its bodies joins the copied bodies. The constraint is made at that moment, from the
    bodies' poses then: build and place the bodies first. Use a constructor such as
    :meth:`pivot`, :meth:`groove`, :meth:`motor` or :meth:`spring` (their constraints are data:
    they can be packed in a :class:`~rlenv.scene2d.packed_scene.PackedScene`), or pass a
    factory that builds any pymunk constraint from the two bodies::

        physics.add_child(Joint.pivot("../Cart", "../Pole", (0.0, 0.0), name="Hinge"))

    Args:
        node_a: path to the first body node (body a).
        node_b: path to the second body node (body b).
        make: builds the constraint from the two ``pymunk.Body`` objects, a's first (a
            :class:`~rlenv.scene2d.pymunk_data.ConstraintRecipe`, or any callable).
        collide_bodies: whether the two bodies still collide with each other.
        max_force: the most force the constraint may apply (for a motor, the most torque).
        name: the node name.

    Attributes:
        node_a: the path to body a.
        node_b: the path to body b.
        constraint: the ``pymunk.Constraint`` once made (``None`` before).
    """

    _TREE_STATE = Node._TREE_STATE | {"constraint", "_world", "_attached"}

    def __init__(
        self, node_a: str, node_b: str, make: ConstraintFactory, *,
        collide_bodies: bool = False, max_force: float = float("inf"), name: str | None = None,
    ) -> None:
        super().__init__(name)
        self.node_a = node_a
        self.node_b = node_b
        self._make = make
        self._collide_bodies = collide_bodies
        self._max_force = number(max_force, f"joint {name}: max_force", low=0.0, finite=False)
        self.constraint: pymunk.Constraint | None = None
        self._world: PhysicsWorld | None = None
        self._attached = False

    @classmethod
    def pivot(cls, node_a: str, node_b: str, anchor: Vec, **kwargs: Any) -> Joint:
        """A hinge: the two bodies turn freely about a shared point (PinJoint2D).

        Args:
            node_a: path to body a.
            node_b: path to body b.
            anchor: the hinge, a point in the frame of the joint's nearest Node2D ancestor (in
                world coordinates without one) when the joint attaches; it then moves with the
                bodies.
            **kwargs: ``collide_bodies``, ``max_force``, ``name``.
        """
        return cls(node_a, node_b, ConstraintRecipe("pivot", anchor=anchor), **kwargs)

    @classmethod
    def groove(
        cls, node_a: str, node_b: str, groove_a: Vec, groove_b: Vec, anchor_b: Vec = (0.0, 0.0),
        **kwargs: Any,
    ) -> Joint:
        """A slot: the point ``anchor_b`` of body b slides along a groove of body a (GrooveJoint2D).

        Args:
            node_a: path to body a, which holds the groove.
            node_b: path to body b.
            groove_a: one end of the groove, in body a's frame.
            groove_b: the other end, in body a's frame.
            anchor_b: the point of body b held on the groove, in body b's frame.
            **kwargs: ``collide_bodies``, ``max_force``, ``name``.
        """
        recipe = ConstraintRecipe("groove", groove_a=groove_a, groove_b=groove_b,
                                  anchor_b=anchor_b)
        return cls(node_a, node_b, recipe, **kwargs)

    @classmethod
    def motor(cls, node_a: str, node_b: str, rate: float = 0.0, **kwargs: Any) -> Joint:
        """A motor: keeps ``a.angular_velocity - b.angular_velocity`` at ``rate``.

        As pymunk's SimpleMotor: with a static body a, body b turns at ``-rate``. Limit its
        torque with ``max_force`` (unlimited by default), and usually add a :meth:`pivot`.

        Args:
            node_a: path to body a.
            node_b: path to body b.
            rate: the relative angular velocity, in radians per second; change it later
                through :attr:`constraint` (its ``rate``).
            **kwargs: ``collide_bodies``, ``max_force``, ``name``.
        """
        return cls(node_a, node_b, ConstraintRecipe("motor", rate=rate), **kwargs)

    @classmethod
    def spring(
        cls, node_a: str, node_b: str, anchor_a: Vec, anchor_b: Vec, rest_length: float,
        stiffness: float, damping: float, **kwargs: Any,
    ) -> Joint:
        """A damped spring between a point of each body (DampedSpringJoint2D).

        Args:
            node_a: path to body a.
            node_b: path to body b.
            anchor_a: where it is fixed on body a, in body a's frame.
            anchor_b: where it is fixed on body b, in body b's frame.
            rest_length: the length at which it pulls and pushes with no force.
            stiffness: force per unit of stretch (e.g. newtons per metre).
            damping: force per unit of stretching speed (e.g. newton-seconds per metre).
            **kwargs: ``collide_bodies``, ``max_force``, ``name``.
        """
        recipe = ConstraintRecipe("spring", anchor_a=anchor_a, anchor_b=anchor_b,
                                  rest_length=rest_length, stiffness=stiffness, damping=damping)
        return cls(node_a, node_b, recipe, **kwargs)

    @property
    def recipe(self) -> ConstraintRecipe | None:
        """The constraint as data, when the joint was made from one (``None``: a factory)."""
        return self._make if isinstance(self._make, ConstraintRecipe) else None

    def _duplicated(self, original: Node) -> None:
        self.constraint = None
        self._world = None
        self._attached = False

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
            make = self._make
            if isinstance(make, ConstraintRecipe):
                frame = frame_of(self)
                self.constraint = make.build(bodies[0], bodies[1],
                                             None if frame is None else frame._global_pose())
            else:
                self.constraint = make(bodies[0], bodies[1])
            self.constraint.collide_bodies = self._collide_bodies
            self.constraint.max_force = self._max_force
        world.space.add(self.constraint)
        self._attached = True

    def _reattach(self, world: PhysicsWorld) -> None:
        """Join ``world``'s new space again, fresh (see :meth:`PhysicsWorld.restart`).

        The constraint is set up again in place, as when it was made, when its bodies are
        those in the space and its kind allows; otherwise a new one is made, as on attaching.
        """
        constraint = self.constraint
        space = world.space
        if constraint is not None and constraint.a.space is space and \
                constraint.b.space is space and refresh_constraint(constraint):
            space.add(constraint)
            return
        self.constraint = None
        self._attach(world, required=True)

    def _exit_tree(self) -> None:
        if self._world is not None and self._attached:
            self._world.space.remove(self.constraint)
        self._attached = False
        self._world = None
        self.request_ready()  # on re-entry, attach again once the bodies are back
