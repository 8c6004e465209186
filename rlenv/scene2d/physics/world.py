"""PhysicsWorld: the node that owns a pymunk space and steps it (Godot's physics server).

See :mod:`rlenv.scene2d.physics` for the family, units and frames.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any, ClassVar, cast

import pymunk

from rlenv.node import Node, ProcessMode
from rlenv.scene2d._chipmunk import (
    FAST,
    Refill,
    bodies_to_check,
    collision_handlers,
    renumber,
    step_space,
)
from rlenv.scene2d._pymunk_data import integer, number, vector
from rlenv.scene2d.physics._space_owner import SpaceOwner, Vec
from rlenv.scene2d.physics.body import PhysicsBody
from rlenv.scene2d.physics.collision_shape import CollisionShape
from rlenv.scene2d.physics.joint import Joint
from rlenv.signals import Signal

__all__ = ["PhysicsWorld"]

logger = logging.getLogger(__name__)

_SPACE_SETTINGS = (
    "collision_slop",
    "collision_bias",
    "collision_persistence",
    "idle_speed_threshold",
    "sleep_time_threshold",
)
"""What a space is set up with besides gravity, iterations and damping (and its handlers)."""

_PHASES = ("begin", "pre_solve", "post_solve", "separate")
_CATCH_ALL = (None, None)
_Callback = Callable[[pymunk.Arbiter, pymunk.Space, Any], Any]


class _Space(pymunk.Space):
    """A world's ``pymunk.Space``, whose catch-all collision handler rlenv shares with its user.

    rlenv reports contacts to the nodes (``collision_started``, ``body_entered``...) from the
    ``begin`` and ``separate`` of the catch-all handler, the one ``on_collision`` sets up
    without collision types. A ``begin`` or ``separate`` that a user sets there (pymunk would
    replace rlenv's with it, and the signals would stop) runs after rlenv's instead, with the
    user's ``data``; ``pymunk.empty_callback`` removes it again. Everything else is pymunk's.

    A space of a world that monitors no contacts (``begin`` and ``separate`` ``None``) has no
    handler of rlenv's: the user's catch-all is pymunk's, as in any space.

    Args:
        begin: rlenv's ``begin``, or ``None``.
        separate: rlenv's ``separate``, or ``None``.
    """

    def __init__(self, begin: _Callback | None, separate: _Callback | None) -> None:
        super().__init__()
        self.own: dict[str, _Callback] = (
            {} if begin is None or separate is None else {"begin": begin, "separate": separate}
        )
        self.theirs: dict[str, tuple[_Callback, Any]] = {}  # the user's, and their data
        if self.own:
            super().on_collision(begin=self._begin, separate=self._separate)

    def on_collision(
        self,
        collision_type_a: int | None = None,
        collision_type_b: int | None = None,
        begin: _Callback | None = None,
        pre_solve: _Callback | None = None,
        post_solve: _Callback | None = None,
        separate: _Callback | None = None,
        data: Any = None,
    ) -> None:
        """Set up a collision handler as pymunk does; one without types runs beside rlenv's."""
        if collision_type_a is None and collision_type_b is None and self.own:
            for phase, callback in (("begin", begin), ("separate", separate)):
                if callback is pymunk.empty_callback:
                    self.theirs.pop(phase, None)
                elif callback is not None:
                    self.theirs[phase] = (callback, data)
            begin = separate = None  # rlenv's stay, and call the user's
        super().on_collision(
            collision_type_a, collision_type_b, begin, pre_solve, post_solve, separate, data
        )

    def rlenv_alone(self) -> bool:
        """Whether no collision handler but rlenv's is set up."""
        handlers = collision_handlers(self)
        if not self.own:
            return not handlers
        catch_all = handlers[_CATCH_ALL]
        return (
            len(handlers) == 1
            and not self.theirs
            and catch_all.pre_solve is None
            and catch_all.post_solve is None
        )

    def copy_handlers(self, into: _Space) -> None:
        """Set up this space's collision handlers of the user's again in ``into``."""
        for key, handler in collision_handlers(self).items():
            for phase in _PHASES:
                if key == _CATCH_ALL and phase in self.own:
                    callback, data = self.theirs.get(phase, (None, None))
                else:
                    callback, data = getattr(handler, phase), handler.data.get(phase)
                if callback is not None:
                    handler_of_phase: dict[str, Any] = {phase: callback}
                    into.on_collision(*key, **handler_of_phase, data=data)

    def _begin(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        self.own["begin"](arbiter, space, data)
        theirs = self.theirs.get("begin")
        if theirs is not None:
            theirs[0](arbiter, space, theirs[1])

    def _separate(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        self.own["separate"](arbiter, space, data)
        theirs = self.theirs.get("separate")
        if theirs is not None:
            theirs[0](arbiter, space, theirs[1])


class PhysicsWorld(SpaceOwner):
    """Owns a ``pymunk.Space`` and steps it once per physics tick.

    The space steps by the tree's fixed ``delta`` in ``_physics_step``, after every node's
    ``_physics_process`` of the tick (so forces applied there act in this tick's step). Bodies,
    shapes and joints anywhere below the world join its space (the nearest world above them).

    Args:
        gravity: the space's gravity, a world vector (acceleration, e.g. metres per second
            squared: the default pulls down along y).
        iterations: solver iterations per step (pymunk's default is 10).
        damping: fraction of velocity kept per second (1 keeps all; 0.9 loses 10% a second).
        contact_monitor: whether the world reports contacts to its nodes, as the collision
            signals of its shapes and bodies (``collision_started``, ``body_entered`` ...).
            Godot's ``RigidBody2D.contact_monitor``, for the whole world. ``False`` sets up no
            collision handler of rlenv's in the space, so that contacts cost pymunk's step alone
            (a swarm of many discs touching, whose nodes listen to no contact), and emits no
            collision signal; the simulation is the same.
        name: the node name.
        process_mode: when the space steps; by default it follows its parent.

    Attributes:
        space: the ``pymunk.Space``; :meth:`restart` replaces it with a new one. Its collision
            handlers are the user's to set up (``space.on_collision``); one without collision
            types runs beside rlenv's own, which emits the collision signals, and does not
            replace it (without :attr:`contact_monitor` it is pymunk's own).
    """

    space: _Space

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
        contact_monitor: bool = True,
        name: str | None = None,
        process_mode: ProcessMode = ProcessMode.INHERIT,
    ) -> None:
        super().__init__(name, process_mode=process_mode)
        self._contact_monitor = bool(contact_monitor)
        self.space = self._new_space(
            vector(gravity, "gravity"),
            integer(iterations, "iterations", 1, 2**31 - 1),
            number(damping, "damping", low=0.0),
        )
        self._shape_nodes: dict[pymunk.Shape, CollisionShape] = {}
        self._kept_members: (
            tuple[int | None, list[PhysicsBody], list[CollisionShape], list[Joint], Refill] | None
        ) = None  # see _members
        self._touched = False  # a contact began since the space was made or restarted

    @property
    def contact_monitor(self) -> bool:
        """Whether the world reports contacts to its nodes (see the class; set when made)."""
        return self._contact_monitor

    def _new_space(self, gravity: Vec, iterations: int, damping: float) -> _Space:
        if self._contact_monitor:
            space = _Space(self._on_begin, self._on_separate)
        else:
            space = _Space(None, None)
        space.gravity = gravity
        space.iterations = iterations
        space.damping = damping
        return space

    def _space_like(self, old: _Space) -> _Space:
        """An empty space set up as ``old``: its settings and every collision handler."""
        space = self._new_space(old.gravity, old.iterations, old.damping)
        for name in _SPACE_SETTINGS:
            setattr(space, name, getattr(old, name))
        old.copy_handlers(space)
        return space

    def restart(self) -> None:
        """Start the simulation afresh, as a newly built subtree would: cheap episode resets.

        The bodies, shapes and joints below stay (nodes, pymunk objects and their settings),
        but start again in a space as new (same gravity, iterations and damping), in tree order,
        as they would on entering it: every body back at the pose it entered its space with
        (composed through its Node2D frames, so each copy of a lattice goes back to its own
        place), at rest (velocities, force and torque zero), and every joint's constraint as
        when it was made (joints such as ``pivot`` read the bodies' pose when made). No solver
        state (joint impulses, cached contacts, the bodies' bias velocities, the spatial index)
        survives, whatever the space's settings (``collision_slop`` 0 included); contacts in
        progress end, with their signals. Place the bodies for the episode afterwards.

        The space is a new one, unless it can be made exactly as new in place: the same
        bodies, shapes and joints as at the previous restart (the tree below unchanged), no
        contact since then (Chipmunk's contact cache never grew), no collision handler but
        rlenv's and no sleeping; then it is emptied and its counters set back (cheaper).
        """
        old = self.space
        bodies, shapes, joints, refill, unchanged = self._members()
        in_place = (
            FAST
            and unchanged
            and self._contact_monitor  # else a contact leaves no trace in _touched
            and not self._touched
            and old.rlenv_alone()
            and old.sleep_time_threshold == math.inf
        )
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

    def _members(self) -> tuple[list[PhysicsBody], list[CollisionShape], list[Joint], Refill, bool]:
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
        # An attached joint has its constraint, and a body in the space the pose it entered with.
        refill = Refill(
            [body.body for body in bodies],
            [shape.shape for shape in shapes],
            cast(list[pymunk.Constraint], [joint.constraint for joint in joints]),
            cast(list[tuple[float, float, float]], [body._built_pose for body in bodies]),
        )
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
        if self.space.own:  # not the original's
            self.space.own = {"begin": self._on_begin, "separate": self._on_separate}
        self._shape_nodes = {}
        self._kept_members = None
        self._touched = False

    @property
    def gravity(self) -> pymunk.Vec2d:
        """The space's gravity, a world vector; clients may read and set it (exported)."""
        return self.space.gravity

    @gravity.setter
    def gravity(self, value: Vec) -> None:
        try:
            self.space.gravity = vector(value, "gravity")
        except ValueError as error:
            raise self._refusal(error) from None

    @property
    def damping(self) -> float:
        """The fraction of velocity bodies keep per second; exported."""
        return self.space.damping

    @damping.setter
    def damping(self, value: float) -> None:
        try:
            self.space.damping = number(value, "damping", low=0.0)
        except ValueError as error:
            raise self._refusal(error) from None

    def _refusal(self, error: ValueError) -> ValueError:
        """``error``, naming this node.

        Built only for a refusal, and the setters check inline: environments set gravity and
        damping at every reset.
        """
        return ValueError(f"{self!r}: {error}")

    def _enter_tree(self) -> None:
        parent = self.parent
        others = (
            [
                node.name
                for node in parent.get_children()
                if node is not self and isinstance(node, PhysicsWorld)
            ]
            if parent
            else []
        )
        if others:
            logger.warning(
                "%r enters beside %s: each PhysicsWorld simulates a space of its own. "
                "Left from an earlier reset? Remove the old one first",
                self,
                ", ".join(others),
            )

    def _physics_step(self, delta: float) -> None:
        step_space(self.space, delta, self._check_masses)  # before pymunk checks new bodies
        if self._signals:  # someone asked for a signal of this node
            self._emit("stepped", delta)

    def _check_masses(self) -> None:
        """Refuse, naming the node, a dynamic body without a positive, finite mass and moment."""
        for body in bodies_to_check(self.space):
            if body.body_type == pymunk.Body.DYNAMIC and not (
                0 < body.mass < math.inf and body.moment > 0
            ):
                node = next(
                    (
                        node
                        for node in self.iter_subtree()
                        if isinstance(node, PhysicsBody) and node.body is body
                    ),
                    body,
                )
                raise ValueError(
                    f"{node!r} has mass {body.mass} and moment {body.moment}: give "
                    "it a mass and moment, or its CollisionShape children a mass "
                    "or density"
                )

    def _on_begin(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        self._touched = True
        if self._shape_nodes:  # else no shape has a node to tell (bare pymunk shapes, a swarm's)
            self._report(arbiter, "collision_started", "body_entered")

    def _on_separate(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        if self._shape_nodes:
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
