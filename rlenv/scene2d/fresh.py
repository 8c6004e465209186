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

from collections.abc import Callable
from typing import Any

import pymunk
from pymunk._chipmunk_cffi import ffi, lib

__all__ = ["Refill", "place_at_rest", "refresh_constraint", "renumber"]

_STATIC = pymunk.Body.STATIC
_ZERO = (0.0, 0.0)


def place_at_rest(body: pymunk.Body, x: float, y: float, angle: float) -> None:
    """Put ``body`` at ``(x, y)`` and ``angle``, with no velocity, force or torque.

    The angle first: Chipmunk turns a body about its centre of gravity, then places it.
    """
    _place_at_rest(body._body, x, y, angle)


def _place_at_rest(pointer: Any, x: float, y: float, angle: float) -> None:
    if lib.cpBodyGetAngle(pointer) != angle:
        lib.cpBodySetAngle(pointer, angle)
    lib.cpBodySetPosition(pointer, (x, y))
    if lib.cpBodyGetType(pointer) != _STATIC:
        lib.cpBodySetVelocity(pointer, _ZERO)
        lib.cpBodySetAngularVelocity(pointer, 0.0)
        lib.cpBodySetForce(pointer, _ZERO)
        lib.cpBodySetTorque(pointer, 0.0)


def _pivot(pointer: Any, a: Any, b: Any) -> None:
    joint = ffi.cast("cpPivotJoint *", pointer)
    lib.cpPivotJointInit(joint, a, b, lib.cpPivotJointGetAnchorA(pointer),
                         lib.cpPivotJointGetAnchorB(pointer))


def _groove(pointer: Any, a: Any, b: Any) -> None:
    joint = ffi.cast("cpGrooveJoint *", pointer)
    lib.cpGrooveJointInit(joint, a, b, lib.cpGrooveJointGetGrooveA(pointer),
                          lib.cpGrooveJointGetGrooveB(pointer),
                          lib.cpGrooveJointGetAnchorB(pointer))


def _motor(pointer: Any, a: Any, b: Any) -> None:
    lib.cpSimpleMotorInit(ffi.cast("cpSimpleMotor *", pointer), a, b,
                          lib.cpSimpleMotorGetRate(pointer))


def _spring(pointer: Any, a: Any, b: Any) -> None:
    force = lib.cpDampedSpringGetSpringForceFunc(pointer)
    lib.cpDampedSpringInit(ffi.cast("cpDampedSpring *", pointer), a, b,
                           lib.cpDampedSpringGetAnchorA(pointer),
                           lib.cpDampedSpringGetAnchorB(pointer),
                           lib.cpDampedSpringGetRestLength(pointer),
                           lib.cpDampedSpringGetStiffness(pointer),
                           lib.cpDampedSpringGetDamping(pointer))
    lib.cpDampedSpringSetSpringForceFunc(pointer, force)


_INIT: dict[type, Callable[[Any, Any, Any], None]] = {
    pymunk.PivotJoint: _pivot, pymunk.GrooveJoint: _groove, pymunk.SimpleMotor: _motor,
    pymunk.DampedSpring: _spring,
}


def refresh_constraint(constraint: pymunk.Constraint) -> bool:
    """Make ``constraint`` as it was when made: no accumulated impulse, its settings kept.

    It must be in no space. Returns ``False``, changing nothing, for a kind of constraint this
    does not know (the caller then makes a new one).
    """
    init = _INIT.get(type(constraint))
    if init is None:
        return False
    _refresh(constraint._constraint, init)
    return True


def _refresh(pointer: Any, init: Callable[[Any, Any, Any], None]) -> None:
    settings = _settings(pointer)
    init(pointer, lib.cpConstraintGetBodyA(pointer), lib.cpConstraintGetBodyB(pointer))
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


class Refill:
    """A space's objects, ready to be put back into it as new, again and again, at Chipmunk's speed.

    :meth:`into` does what ``space.remove`` of everything, :func:`renumber`,
    :func:`place_at_rest` of each body at its pose, ``space.add`` of the bodies and shapes,
    then :func:`refresh_constraint` and ``space.add`` of each constraint do, in that order, with
    Chipmunk's calls alone: pymunk's own records of what the space holds would come out as
    they are, so they are left alone (the bodies are given to pymunk's check before the next
    step, as ``space.add`` does). The bodies themselves stay in the space: without sleeping,
    taking one out and back leaves it in the same place of Chipmunk's lists, and placing it
    wakes it as adding it would. What does not change between restarts (the objects' Chipmunk
    pointers, how to refresh each constraint, the poses) is looked up once, here.

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
        known = all(type(c) in _INIT and c.a in bodies and c.b in bodies for c in constraints)
        self._constraints = [(c._constraint, _INIT[type(c)]) for c in constraints] \
            if known else None

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
        for constraint, _ in constraints:
            lib.cpSpaceRemoveConstraint(pointer, constraint)
        for shape in self._shapes:
            lib.cpSpaceRemoveShape(pointer, shape)
        renumber(space)
        for place in self._places:
            _place_at_rest(*place)
        for shape in self._shapes:
            lib.cpSpaceAddShape(pointer, shape)
        for constraint, init in constraints:
            _refresh(constraint, init)
            lib.cpSpaceAddConstraint(pointer, constraint)
        space._bodies_to_check.update(self.bodies)
        return True
