"""Joint: a pymunk constraint between two body nodes named by path (Godot's Joint2D family)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, cast

import pymunk

from rlenv.node import Node
from rlenv.scene2d._chipmunk import refresh_constraint
from rlenv.scene2d._pymunk_data import ConstraintRecipe, number
from rlenv.scene2d.node2d import frame_of
from rlenv.scene2d.physics._space_owner import SpaceOwner, Vec, world_of
from rlenv.scene2d.physics.body import PhysicsBody

__all__ = ["ConstraintFactory", "Joint"]


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
            :class:`~rlenv.scene2d._pymunk_data.ConstraintRecipe`, or any callable).
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
        self,
        node_a: str,
        node_b: str,
        make: ConstraintFactory,
        *,
        collide_bodies: bool = False,
        max_force: float = float("inf"),
        name: str | None = None,
    ) -> None:
        super().__init__(name)
        self.node_a = node_a
        self.node_b = node_b
        self._make = make
        self._collide_bodies = collide_bodies
        self._max_force = number(max_force, f"joint {name}: max_force", low=0.0, finite=False)
        self.constraint: pymunk.Constraint | None = None
        self._world: SpaceOwner | None = None
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
        cls,
        node_a: str,
        node_b: str,
        groove_a: Vec,
        groove_b: Vec,
        anchor_b: Vec = (0.0, 0.0),
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
        recipe = ConstraintRecipe("groove", groove_a=groove_a, groove_b=groove_b, anchor_b=anchor_b)
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
        cls,
        node_a: str,
        node_b: str,
        anchor_a: Vec,
        anchor_b: Vec,
        rest_length: float,
        stiffness: float,
        damping: float,
        **kwargs: Any,
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
        recipe = ConstraintRecipe(
            "spring",
            anchor_a=anchor_a,
            anchor_b=anchor_b,
            rest_length=rest_length,
            stiffness=stiffness,
            damping=damping,
        )
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
        self._world = world_of(self)
        self._attach(self._world)

    def _ready(self) -> None:
        if self._world is not None and not self._attached:
            self._attach(self._world, required=True)

    def _attach(self, world: SpaceOwner, required: bool = False) -> None:
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
                self.constraint = make.build(
                    bodies[0], bodies[1], None if frame is None else frame._global_pose()
                )
            else:
                self.constraint = make(bodies[0], bodies[1])
            self.constraint.collide_bodies = self._collide_bodies
            self.constraint.max_force = self._max_force
        world.space.add(self.constraint)
        self._attached = True

    def _reattach(self, world: SpaceOwner) -> None:
        """Join ``world``'s new space again, fresh (see :meth:`PhysicsWorld.restart`).

        The constraint is set up again in place, as when it was made, when its bodies are
        those in the space and its kind allows; otherwise a new one is made, as on attaching.
        """
        constraint = self.constraint
        space = world.space
        if (
            constraint is not None
            and constraint.a.space is space
            and constraint.b.space is space
            and refresh_constraint(constraint)
        ):
            space.add(constraint)
            return
        self.constraint = None
        self._attach(world, required=True)

    def _exit_tree(self) -> None:
        if self._world is not None and self._attached:
            # Attached: its constraint is in the world's space.
            self._world.space.remove(cast(pymunk.Constraint, self.constraint))
        self._attached = False
        self._world = None
        self.request_ready()  # on re-entry, attach again once the bodies are back
