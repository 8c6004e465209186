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

__all__ = ["place_at_rest", "refresh_constraint", "renumber"]

_STATIC = pymunk.Body.STATIC
_ZERO = (0.0, 0.0)


def place_at_rest(body: pymunk.Body, x: float, y: float, angle: float) -> None:
    """Put ``body`` at ``(x, y)`` and ``angle``, with no velocity, force or torque.

    The angle first: Chipmunk turns a body about its centre of gravity, then places it.
    """
    pointer = body._body
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
    pointer = constraint._constraint
    max_force = lib.cpConstraintGetMaxForce(pointer)
    error_bias = lib.cpConstraintGetErrorBias(pointer)
    max_bias = lib.cpConstraintGetMaxBias(pointer)
    collide = lib.cpConstraintGetCollideBodies(pointer)
    pre_solve = lib.cpConstraintGetPreSolveFunc(pointer)
    post_solve = lib.cpConstraintGetPostSolveFunc(pointer)
    init(pointer, lib.cpConstraintGetBodyA(pointer), lib.cpConstraintGetBodyB(pointer))
    lib.cpConstraintSetMaxForce(pointer, max_force)
    lib.cpConstraintSetErrorBias(pointer, error_bias)
    lib.cpConstraintSetMaxBias(pointer, max_bias)
    lib.cpConstraintSetCollideBodies(pointer, collide)
    lib.cpConstraintSetPreSolveFunc(pointer, pre_solve)
    lib.cpConstraintSetPostSolveFunc(pointer, post_solve)
    return True


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
