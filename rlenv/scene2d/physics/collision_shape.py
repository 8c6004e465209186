"""CollisionShape: a pymunk shape on its parent body's pymunk body (Godot's CollisionShape2D)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import pymunk

from rlenv.node import Node
from rlenv.scene2d._pymunk_data import copy_shape, number
from rlenv.scene2d.colors import RGB, Color, to_rgb
from rlenv.scene2d.physics._space_owner import SpaceOwner, Vec, world_of
from rlenv.scene2d.physics.body import PhysicsBody
from rlenv.signals import Signal

__all__ = ["CollisionShape"]


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
        self,
        shape: pymunk.Shape,
        *,
        mass: float = 0.0,
        density: float = 0.0,
        friction: float = 0.5,
        elasticity: float = 0.0,
        sensor: bool = False,
        color: Color | None = None,
        name: str | None = None,
    ) -> None:
        super().__init__(name)
        if shape.space is not None:
            raise ValueError(
                f"{self!r}: the shape is in a space already; give each "
                "CollisionShape a shape of its own"
            )
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
        self._world: SpaceOwner | None = None

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
    def box(cls, width: float, height: float, radius: float = 0.0, **kwargs: Any) -> CollisionShape:
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
            raise RuntimeError(
                f"{self!r}: its shape is in a space already (was _enter_tree "
                "called outside the tree's lifecycle?)"
            )
        self.body_node = parent
        self._world = world_of(self)
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
