"""Fresh pymunk objects in place, at Chipmunk's speed: what :meth:`PhysicsWorld.restart` needs.

A restart must leave no solver state behind, as if the scene had just been built. Bodies and
shapes are reused as they are (moved into a new space, which numbers their shapes afresh), but
a constraint keeps its accumulated impulses (Chipmunk's warm start) in its C struct, which
pymunk does not expose: making a new pymunk constraint costs more than the rest of a restart.
Chipmunk's own ``cp*Init`` functions set up a constraint's struct in place exactly as when it
was made (impulses zero); :func:`refresh_constraint` calls them with the constraint's own
anchors and parameters, and puts back what ``cpConstraintInit`` resets to its defaults (forces,
biases, collisions, callbacks). pymunk's user data pointer is left as it is.

The functions here call pymunk's Chipmunk binding (``pymunk._chipmunk_cffi``) directly, a step
below pymunk's public API, for the sake of speed; the tests of ``PhysicsWorld.restart`` compare
restarted scenes with newly built ones bit for bit, so a pymunk release that changed what they
rely on would fail them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import pymunk
from pymunk._chipmunk_cffi import ffi, lib

__all__ = ["Refill", "place_at_rest", "refresh_constraint", "renumber"]

_STATIC = pymunk.Body.STATIC
_DYNAMIC = pymunk.Body.DYNAMIC
_ZERO = (0.0, 0.0)


def place_at_rest(body: pymunk.Body, x: float, y: float, angle: float) -> None:
    """Put ``body`` at ``(x, y)`` and ``angle``, with no velocity, force or torque.

    The angle first: Chipmunk turns a body about its centre of gravity, then places it.
    """
    _place_at_rest(body._body, x, y, angle)


def _place_at_rest(pointer: Any, x: float, y: float, angle: float) -> int:
    """:func:`place_at_rest` of a body's Chipmunk pointer; the body's type."""
    if lib.cpBodyGetAngle(pointer) != angle:
        lib.cpBodySetAngle(pointer, angle)
    lib.cpBodySetPosition(pointer, (x, y))
    body_type = lib.cpBodyGetType(pointer)
    if body_type != _STATIC:
        lib.cpBodySetVelocity(pointer, _ZERO)
        lib.cpBodySetAngularVelocity(pointer, 0.0)
        lib.cpBodySetForce(pointer, _ZERO)
        lib.cpBodySetTorque(pointer, 0.0)
    return body_type


# Each sets a constraint's struct up again: its pointer, the same cast to its kind, its bodies.
def _pivot(pointer: Any, joint: Any, a: Any, b: Any) -> None:
    lib.cpPivotJointInit(joint, a, b, lib.cpPivotJointGetAnchorA(pointer),
                         lib.cpPivotJointGetAnchorB(pointer))


def _groove(pointer: Any, joint: Any, a: Any, b: Any) -> None:
    lib.cpGrooveJointInit(joint, a, b, lib.cpGrooveJointGetGrooveA(pointer),
                          lib.cpGrooveJointGetGrooveB(pointer),
                          lib.cpGrooveJointGetAnchorB(pointer))


def _motor(pointer: Any, joint: Any, a: Any, b: Any) -> None:
    lib.cpSimpleMotorInit(joint, a, b, lib.cpSimpleMotorGetRate(pointer))


def _spring(pointer: Any, joint: Any, a: Any, b: Any) -> None:
    force = lib.cpDampedSpringGetSpringForceFunc(pointer)
    lib.cpDampedSpringInit(joint, a, b,
                           lib.cpDampedSpringGetAnchorA(pointer),
                           lib.cpDampedSpringGetAnchorB(pointer),
                           lib.cpDampedSpringGetRestLength(pointer),
                           lib.cpDampedSpringGetStiffness(pointer),
                           lib.cpDampedSpringGetDamping(pointer))
    lib.cpDampedSpringSetSpringForceFunc(pointer, force)


_Init = Callable[[Any, Any, Any, Any], None]
_INIT: dict[type, tuple[str, _Init]] = {
    pymunk.PivotJoint: ("cpPivotJoint *", _pivot),
    pymunk.GrooveJoint: ("cpGrooveJoint *", _groove),
    pymunk.SimpleMotor: ("cpSimpleMotor *", _motor),
    pymunk.DampedSpring: ("cpDampedSpring *", _spring),
}


def refresh_constraint(constraint: pymunk.Constraint) -> bool:
    """Make ``constraint`` as it was when made: no accumulated impulse, its settings kept.

    It must be in no space. Returns ``False``, changing nothing, for a kind of constraint this
    does not know (the caller then makes a new one).
    """
    refresh = _refresher(constraint)
    if refresh is None:
        return False
    _refresh(*refresh)
    return True


def _refresher(constraint: pymunk.Constraint) -> tuple[Any, Any, Any, Any, _Init] | None:
    """What :func:`_refresh` takes to refresh ``constraint`` (``None``: a kind it does not know)."""
    known = _INIT.get(type(constraint))
    if known is None:
        return None
    kind, init = known
    pointer = constraint._constraint
    return (pointer, ffi.cast(kind, pointer), constraint.a._body, constraint.b._body, init)


def _refresh(pointer: Any, joint: Any, a: Any, b: Any, init: _Init) -> None:
    settings = _settings(pointer)
    init(pointer, joint, a, b)
    if settings != _DEFAULTS:  # put back what the init set back to Chipmunk's defaults
        for put, value, default in zip(_SETTERS, settings, _DEFAULTS, strict=True):
            if value != default:
                put(pointer, value)


_SETTERS = (lib.cpConstraintSetMaxForce, lib.cpConstraintSetErrorBias,
            lib.cpConstraintSetMaxBias, lib.cpConstraintSetCollideBodies,
            lib.cpConstraintSetPreSolveFunc, lib.cpConstraintSetPostSolveFunc)


def _settings(pointer: Any) -> tuple[Any, ...]:
    """What ``cpConstraintInit`` sets back to its defaults, in the order of :data:`_SETTERS`."""
    return (lib.cpConstraintGetMaxForce(pointer), lib.cpConstraintGetErrorBias(pointer),
            lib.cpConstraintGetMaxBias(pointer), lib.cpConstraintGetCollideBodies(pointer),
            lib.cpConstraintGetPreSolveFunc(pointer), lib.cpConstraintGetPostSolveFunc(pointer))


_DEFAULTS = _settings(pymunk.SimpleMotor(pymunk.Body(), pymunk.Body(), 0.0)._constraint)
"""The settings ``cpConstraintInit`` gives every constraint, read from a new one."""


def renumber(space: pymunk.Space) -> None:
    """Set an emptied space's counters back as a new space has them.

    Shape ids (Chipmunk numbers shapes as they are added, and orders collision pairs by them),
    the step counter and the previous step's length (warm starts scale by it) start at zero.
    Only counters: a space whose hash tables grew (with contacts cached, say) is not new.
    """
    pointer = space._space
    lib.cpSpaceSetShapeIDCounter(pointer, 0)
    lib.cpSpaceSetTimestamp(pointer, 0)
    lib.cpSpaceSetCurrentTimeStep(pointer, 0.0)


def _valid_mass(pointer: Any) -> bool:
    """What pymunk checks of a dynamic body added to a space before its next step."""
    mass = lib.cpBodyGetMass(pointer)
    return 0 < mass < math.inf and lib.cpBodyGetMoment(pointer) > 0


class Refill:
    """A space's objects, ready to be put back into it as new, again and again, at Chipmunk's speed.

    :meth:`into` does what ``space.remove`` of everything, :func:`renumber`,
    :func:`place_at_rest` of each body at its pose, ``space.add`` of the bodies and shapes,
    then :func:`refresh_constraint` and ``space.add`` of each constraint do, in that order, with
    Chipmunk's calls alone: pymunk's own records of what the space holds would come out as
    they are, so they are left alone. ``space.add`` would have pymunk check every dynamic
    body's mass and moment before the next step (which then takes pymunk's slower
    ``Space.step``): the same check is made here, and only a body that fails it is left to
    pymunk, whose step refuses it as after ``space.add``. The bodies themselves stay in the
    space: without sleeping, taking one out and back leaves it in the same place of Chipmunk's
    lists, and placing it wakes it as adding it would. What does not change between restarts
    (the objects' Chipmunk pointers, how to refresh each constraint, the poses) is looked up
    once, here.

    Args:
        bodies: the space's bodies, in pymunk's order (``space.bodies``).
        shapes: its shapes, in pymunk's order.
        constraints: its constraints, in pymunk's order.
        poses: where each body goes back to: ``(x, y, angle)``.
    """

    def __init__(self, bodies: list[pymunk.Body], shapes: list[pymunk.Shape],
                 constraints: list[pymunk.Constraint],
                 poses: list[tuple[float, float, float]]) -> None:
        self.bodies, self.shapes, self.constraints = bodies, shapes, constraints
        self._places = [(body._body, *pose) for body, pose in zip(bodies, poses, strict=True)]
        self._shapes = [shape._shape for shape in shapes]
        refreshers = [_refresher(c) if c.a in bodies and c.b in bodies else None
                      for c in constraints]
        self._constraints = None if None in refreshers else refreshers

    def into(self, space: pymunk.Space) -> bool:
        """Empty ``space`` of these objects and put them back as new.

        It applies when the space holds exactly these objects, in this order, and every
        constraint is of a kind :func:`refresh_constraint` knows and joins two of these bodies.
        Returns ``False``, changing nothing, otherwise (the caller then goes the long way).
        """
        constraints = self._constraints
        if constraints is None or list(space._bodies) != self.bodies or \
                list(space._shapes) != self.shapes or \
                list(space._constraints) != self.constraints:
            return False
        pointer = space._space
        for constraint, *_ in constraints:
            lib.cpSpaceRemoveConstraint(pointer, constraint)
        for shape in self._shapes:
            lib.cpSpaceRemoveShape(pointer, shape)
        renumber(space)
        types = [_place_at_rest(*place) for place in self._places]
        for shape in self._shapes:
            lib.cpSpaceAddShape(pointer, shape)
        for refresh in constraints:
            _refresh(*refresh)
            lib.cpSpaceAddConstraint(pointer, refresh[0])
        for body, body_type, (body_pointer, *_) in zip(self.bodies, types, self._places,
                                                       strict=True):
            # Once the shapes are back: a body's mass may come from its shapes.
            if body_type == _DYNAMIC and not _valid_mass(body_pointer):
                space._bodies_to_check.add(body)  # pymunk's step refuses it, as after add
        return True
