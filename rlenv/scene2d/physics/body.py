"""The bodies: PhysicsBody and its kinds, RigidBody, StaticBody and KinematicBody.

Godot's ``PhysicsBody2D`` family. See :mod:`rlenv.scene2d.physics` for units and frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import pymunk
from pymunk import Vec2d

from rlenv.node import Node
from rlenv.scene2d._chipmunk import (
    angle_of,
    angular_velocity_of,
    apply_force_at_world_point_of,
    center_of_gravity_of,
    handle,
    local_to_world_of,
    place_at_rest,
    position_of,
    set_angular_velocity_of,
    set_velocity_of,
    velocity_of,
)
from rlenv.scene2d._pymunk_data import copy_body
from rlenv.scene2d.colors import RGB, Color
from rlenv.scene2d.node2d import Node2D, Pose, compose, frame_of, relative_pose
from rlenv.scene2d.physics._space_owner import SpaceOwner, Vec, world_of
from rlenv.signals import Signal

__all__ = ["KinematicBody", "PhysicsBody", "RigidBody", "StaticBody"]

_vec2d = tuple.__new__  # a Vec2d from a tuple, without its Python-level __new__


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
        self,
        body: pymunk.Body,
        *,
        position: Vec = (0.0, 0.0),
        angle: float = 0.0,
        rotation: float = 0.0,
        name: str | None = None,
    ) -> None:
        if angle and rotation:
            raise ValueError("give the body's rotation or its angle (the same thing), not both")
        super().__init__(name, position=position, rotation=rotation or angle)
        self.body = body
        self._chipmunk = handle(body)  # what chipmunk's accessors take for the body
        body.position = self._position
        body.angle = self._rotation
        self.world: SpaceOwner | None = None
        self._frame: Node2D | None = None  # the nearest Node2D ancestor, while in a space
        self._built_pose: Pose | None = None  # where it entered its space
        self._frame_pose: Pose | None = None  # where its frame was then

    @property
    def _in_space(self) -> bool:
        return self.world is not None

    def _enter_tree(self) -> None:
        world = world_of(self)
        frame = self._frame = frame_of(self)
        x, y = self._position
        angle = self._rotation
        if frame is not None:
            self._frame_pose = frame._global_pose()
            x, y, angle = compose(self._frame_pose, x, y, angle)
        if self.body.space is not None:
            raise RuntimeError(
                f"{self!r}: its body is in a space already (was _enter_tree "
                "called outside the tree's lifecycle?)"
            )
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
        copy = memo[id(self.body)] = copy_body(self.body)
        memo[id(self._chipmunk)] = handle(copy)  # the copy's own (the body itself without FAST)

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
            position = position_of(self._chipmunk)
            return _vec2d(Vec2d, (position.x, position.y))
        if self.world is None:
            return self._position
        x, y, _ = self._local_pose()
        return Vec2d(x, y)

    @position.setter
    def position(self, value: Sequence[float]) -> None:  # as Node2D's setter takes
        Node2D.position.fset(self, value)  # type: ignore[attr-defined]

    @property
    def rotation(self) -> float:
        """The rotation in radians, relative to the nearest Node2D ancestor."""
        if self._frame is None and self.world is not None:
            return angle_of(self._chipmunk)
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
        velocity = velocity_of(self._chipmunk)
        return _vec2d(Vec2d, (velocity.x, velocity.y))

    @velocity.setter
    def velocity(self, value: Vec) -> None:
        x, y = value
        set_velocity_of(self._chipmunk, (x, y))

    linear_velocity = velocity  # Godot's name (RigidBody2D's): the same property

    @property
    def angular_velocity(self) -> float:
        """The body's angular velocity, in radians per second, counter-clockwise."""
        return angular_velocity_of(self._chipmunk)

    @angular_velocity.setter
    def angular_velocity(self, value: float) -> None:
        set_angular_velocity_of(self._chipmunk, value)

    @property
    def color(self) -> RGB | None:
        """The colour of the body's first collision shape; setting it colours all of them."""
        for child in self._shape_children():
            return child.color
        return None

    @color.setter
    def color(self, value: Color | None) -> None:
        for child in self._shape_children():
            child.color = value

    def _shape_children(self) -> list[Any]:
        """The children holding a pymunk shape: its CollisionShape children."""
        return [
            child
            for child in self._children
            if isinstance(getattr(child, "shape", None), pymunk.Shape)
        ]


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
        self,
        mass: float = 0.0,
        moment: float = 0.0,
        *,
        position: Vec = (0.0, 0.0),
        angle: float = 0.0,
        rotation: float = 0.0,
        name: str | None = None,
    ) -> None:
        super().__init__(
            pymunk.Body(mass, moment), position=position, angle=angle, rotation=rotation, name=name
        )

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
        pointer = self._chipmunk
        apply_force_at_world_point_of(
            pointer, force, local_to_world_of(pointer, center_of_gravity_of(pointer))
        )

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
        self,
        *,
        position: Vec = (0.0, 0.0),
        angle: float = 0.0,
        rotation: float = 0.0,
        name: str | None = None,
    ) -> None:
        super().__init__(
            pymunk.Body(body_type=pymunk.Body.STATIC),
            position=position,
            angle=angle,
            rotation=rotation,
            name=name,
        )


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
        self,
        *,
        position: Vec = (0.0, 0.0),
        angle: float = 0.0,
        rotation: float = 0.0,
        name: str | None = None,
    ) -> None:
        super().__init__(
            pymunk.Body(body_type=pymunk.Body.KINEMATIC),
            position=position,
            angle=angle,
            rotation=rotation,
            name=name,
        )
