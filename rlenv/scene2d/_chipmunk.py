"""Every reach below pymunk's public API, in one place, and only on the versions it was tested on.

rlenv calls Chipmunk through pymunk's binding (``pymunk._chipmunk_cffi``) and reads pymunk's
private records where its public API costs too much for a step of a small scene, or has no
way at all:

- :func:`step_space`: ``Space.step`` without its Python work when nothing is pending;
- :func:`handle`, :data:`position_of` and the other body accessors, read every tick;
- restarts at Chipmunk's speed (:class:`Refill`, :func:`refresh_constraint`,
  :func:`renumber`, :func:`place_at_rest`): :meth:`PhysicsWorld.restart` reuses the bodies,
  shapes and constraints as new, where pymunk would have them made again;
- :func:`bodies_to_check` and :func:`collision_handlers`: what pymunk keeps and does not show.

A restart must leave no solver state behind, as if the scene had just been built. Bodies and
shapes are reused as they are (moved into a new space, which numbers their shapes afresh, and
has no cached arbiters), each body placed at rest with its bias velocities, the solver's push
out of overlaps, back to zero (:func:`place_at_rest`). A constraint keeps its accumulated
impulses (Chipmunk's warm start) in its C struct, which pymunk does not expose: making a new
pymunk constraint costs more than the rest of a restart.
Chipmunk's own ``cp*Init`` functions set up a constraint's struct in place exactly as when it
was made (impulses zero); :func:`refresh_constraint` calls them with the constraint's own
anchors and parameters, and puts back what ``cpConstraintInit`` resets to its defaults (forces,
biases, collisions, callbacks). pymunk's user data pointer is left as it is.

**Versions.** What pymunk keeps privately changes between releases (7.0.0 kept
``Space._remove_later`` as a set, and a handler removing a body during a step then broke every
tick). So the private ways are taken only on the pymunk versions the test suite passed on,
:data:`TESTED` (the tests compare them with pymunk's public ways bit for bit); on any other
version :data:`FAST` is false and each function here takes pymunk's public API instead, the
same simulation more slowly, and a warning says so once.
"""

from __future__ import annotations

import logging
import math
import operator
from collections.abc import Callable, Collection, Mapping
from typing import Any

import pymunk
from pymunk._chipmunk_cffi import ffi, lib

__all__ = [
    "FAST",
    "TESTED",
    "Refill",
    "angle_of",
    "angular_velocity_of",
    "apply_force_at_world_point_of",
    "bodies_to_check",
    "center_of_gravity_of",
    "collision_handlers",
    "handle",
    "local_to_world_of",
    "place_at_rest",
    "position_of",
    "refresh_constraint",
    "renumber",
    "set_angular_velocity_of",
    "set_velocity_of",
    "step_space",
    "velocity_of",
]

logger = logging.getLogger(__name__)

TESTED = ((7, 0, 1), (7, 3, 1))
"""The first and last pymunk versions whose internals this module was tested with."""


def _version(text: str) -> tuple[int, ...]:
    return tuple(int(part) for part in text.split(".")[:3] if part.isdigit())


FAST = TESTED[0] <= _version(pymunk.version) <= TESTED[1]
"""Whether the private ways are taken (pymunk's version is in :data:`TESTED`)."""
if not FAST:
    logger.warning(
        "pymunk %s is not a version rlenv was tested with (%s to %s): rlenv uses "
        "pymunk's public API only, which is slower",
        pymunk.version,
        *(".".join(map(str, version)) for version in TESTED),
    )

_STATIC = pymunk.Body.STATIC
_DYNAMIC = pymunk.Body.DYNAMIC
_ZERO = (0.0, 0.0)


def place_at_rest(body: pymunk.Body, x: float, y: float, angle: float) -> None:
    """Put ``body`` at ``(x, y)`` and ``angle``, with no velocity, force or torque.

    Its bias velocities go back to zero too: the solver's push out of overlaps, which Chipmunk
    keeps in the body from one step's contacts to the next step's move (with
    ``collision_slop`` 0 a resting body always has some) and which a new body does not have.
    ``cpBodyUpdatePosition`` over no time sets them to zero and moves nothing (the velocities
    are zero by then); it is pymunk's public ``Body.update_position``. The angle before the
    position: Chipmunk turns a body about its centre of gravity, then places it.
    """
    if FAST:
        _place_at_rest(body._body, x, y, angle)
        return
    if body.body_type != _STATIC:
        body.velocity = _ZERO
        body.angular_velocity = 0.0
        pymunk.Body.update_position(body, 0.0)  # no bias velocity left from the last contacts
        body.force = _ZERO
        body.torque = 0.0
    if body.angle != angle:
        body.angle = angle
    body.position = (x, y)


def _place_at_rest(pointer: Any, x: float, y: float, angle: float) -> int:
    """:func:`place_at_rest` of a body's Chipmunk pointer; the body's type."""
    body_type = lib.cpBodyGetType(pointer)
    if body_type != _STATIC:
        lib.cpBodySetVelocity(pointer, _ZERO)
        lib.cpBodySetAngularVelocity(pointer, 0.0)
        lib.cpBodyUpdatePosition(pointer, 0.0)  # no bias velocity left from the last contacts
        lib.cpBodySetForce(pointer, _ZERO)
        lib.cpBodySetTorque(pointer, 0.0)
    if lib.cpBodyGetAngle(pointer) != angle:
        lib.cpBodySetAngle(pointer, angle)
    lib.cpBodySetPosition(pointer, (x, y))
    return body_type


# Each sets a constraint's struct up again: its pointer, the same cast to its kind, its bodies.
def _pivot(pointer: Any, joint: Any, a: Any, b: Any) -> None:
    lib.cpPivotJointInit(
        joint, a, b, lib.cpPivotJointGetAnchorA(pointer), lib.cpPivotJointGetAnchorB(pointer)
    )


def _groove(pointer: Any, joint: Any, a: Any, b: Any) -> None:
    lib.cpGrooveJointInit(
        joint,
        a,
        b,
        lib.cpGrooveJointGetGrooveA(pointer),
        lib.cpGrooveJointGetGrooveB(pointer),
        lib.cpGrooveJointGetAnchorB(pointer),
    )


def _motor(pointer: Any, joint: Any, a: Any, b: Any) -> None:
    lib.cpSimpleMotorInit(joint, a, b, lib.cpSimpleMotorGetRate(pointer))


def _spring(pointer: Any, joint: Any, a: Any, b: Any) -> None:
    force = lib.cpDampedSpringGetSpringForceFunc(pointer)
    lib.cpDampedSpringInit(
        joint,
        a,
        b,
        lib.cpDampedSpringGetAnchorA(pointer),
        lib.cpDampedSpringGetAnchorB(pointer),
        lib.cpDampedSpringGetRestLength(pointer),
        lib.cpDampedSpringGetStiffness(pointer),
        lib.cpDampedSpringGetDamping(pointer),
    )
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
    does not know, or without :data:`FAST` (the caller then makes a new one).
    """
    refresh = _refresher(constraint) if FAST else None
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


_SETTERS = (
    lib.cpConstraintSetMaxForce,
    lib.cpConstraintSetErrorBias,
    lib.cpConstraintSetMaxBias,
    lib.cpConstraintSetCollideBodies,
    lib.cpConstraintSetPreSolveFunc,
    lib.cpConstraintSetPostSolveFunc,
)


def _settings(pointer: Any) -> tuple[Any, ...]:
    """What ``cpConstraintInit`` sets back to its defaults, in the order of :data:`_SETTERS`."""
    return (
        lib.cpConstraintGetMaxForce(pointer),
        lib.cpConstraintGetErrorBias(pointer),
        lib.cpConstraintGetMaxBias(pointer),
        lib.cpConstraintGetCollideBodies(pointer),
        lib.cpConstraintGetPreSolveFunc(pointer),
        lib.cpConstraintGetPostSolveFunc(pointer),
    )


_DEFAULTS = _settings(pymunk.SimpleMotor(pymunk.Body(), pymunk.Body(), 0.0)._constraint)
"""The settings ``cpConstraintInit`` gives every constraint, read from a new one."""


def renumber(space: pymunk.Space) -> None:
    """Set an emptied space's counters back as a new space has them (only with :data:`FAST`).

    Shape ids (Chipmunk numbers shapes as they are added, and orders collision pairs by them),
    the step counter and the previous step's length (warm starts scale by it) start at zero.
    Only counters: a space whose hash tables grew (with contacts cached, say) is not new.
    """
    assert FAST, "a space is renumbered only on the tested versions"
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

    def __init__(
        self,
        bodies: list[pymunk.Body],
        shapes: list[pymunk.Shape],
        constraints: list[pymunk.Constraint],
        poses: list[tuple[float, float, float]],
    ) -> None:
        self.bodies, self.shapes, self.constraints = bodies, shapes, constraints
        self._places = [(body._body, *pose) for body, pose in zip(bodies, poses, strict=True)]
        self._shapes = [shape._shape for shape in shapes]
        refreshers = [
            _refresher(c) if FAST and c.a in bodies and c.b in bodies else None for c in constraints
        ]
        known = [refresher for refresher in refreshers if refresher is not None]
        self._constraints = known if len(known) == len(refreshers) else None

    def into(self, space: pymunk.Space) -> bool:
        """Empty ``space`` of these objects and put them back as new.

        It applies when the space holds exactly these objects, in this order, and every
        constraint is of a kind :func:`refresh_constraint` knows and joins two of these bodies.
        Returns ``False``, changing nothing, otherwise (the caller then goes the long way), and
        always without :data:`FAST`.
        """
        constraints = self._constraints
        if (
            not FAST
            or constraints is None
            or list(space._bodies) != self.bodies
            or list(space._shapes) != self.shapes
            or list(space._constraints) != self.constraints
        ):
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
        for body, body_type, (body_pointer, *_) in zip(
            self.bodies, types, self._places, strict=True
        ):
            # Once the shapes are back: a body's mass may come from its shapes.
            if body_type == _DYNAMIC and not _valid_mass(body_pointer):
                space._bodies_to_check.add(body)  # pymunk's step refuses it, as after add
        return True


# --- what pymunk keeps and does not show ---------------------------------------------------------


def bodies_to_check(space: pymunk.Space) -> Collection[pymunk.Body]:
    """The bodies pymunk checks before the next step (those added since the last).

    Empty without :data:`FAST`, where pymunk checks them all the same.
    """
    return space._bodies_to_check if FAST else ()


def collision_handlers(space: pymunk.Space) -> Mapping[tuple[int | None, int | None], Any]:
    """The space's collision handlers, by their pair of collision types.

    ``(None, None)`` is the wildcard; each handler has ``begin``, ``pre_solve``, ``post_solve``,
    ``separate`` and ``data``.

    pymunk has no public way to list them (a restart copies them into a new space), so this
    reads its record on every version.
    """
    return space._handlers


# --- stepping ------------------------------------------------------------------------------------


_cp_space_step = lib.cpSpaceStep


def step_space(
    space: pymunk.Space, delta: float, before_checks: Callable[[], None] | None = None
) -> None:
    """``space.step(delta)``, without pymunk's Python work around Chipmunk's step when it has none.

    ``Space.step`` checks the bodies added since the last step, then steps (Chipmunk's
    ``cpSpaceStep``) with the space locked, and then adds and removes what callbacks asked for
    during the step and runs the post-step callbacks. With nothing to check before the step,
    this calls Chipmunk's step itself, and does the work after it only when there is some: the
    same step (``tests/test_step_space.py`` compares them bit for bit, with collision handlers that
    add and remove in their callbacks), with a tenth of the Python work of ``Space.step`` when
    nothing is pending (measured: 0.07 against 0.63 us around a 1 us CartPole step). A threaded
    space, bodies to check, or a pymunk version not in :data:`TESTED` take ``Space.step``.
    ``before_checks`` runs first when there are bodies to check (:func:`bodies_to_check`): one
    test per step for both.
    """
    if not FAST or space._bodies_to_check or space.threaded:
        if before_checks is not None and FAST and space._bodies_to_check:
            before_checks()
        space.step(delta)
        return
    try:
        space._locked = True
        _cp_space_step(space._space, delta)
        if space._removed_shapes:  # shapes removed since the last step, kept alive through it
            space._removed_shapes.clear()
    finally:
        space._locked = False
    if space._add_later or space._remove_later or space._post_step_callbacks:
        _after_step(space)


def _after_step(space: pymunk.Space) -> None:
    """What ``Space.step`` does after Chipmunk's step: the deferred adds, removals, callbacks."""
    space.add(*space._add_later)
    space._add_later.clear()
    removed = set()
    while space._remove_later:
        item, _ = space._remove_later.popitem()
        if item not in removed:
            removed.add(item)
            space._remove(item)
    callbacks = space._post_step_callbacks
    for key in callbacks:
        callbacks[key](space)
    callbacks.clear()


# --- a body's state, read and set every tick -----------------------------------------------------
# A body node reads and pushes its body several times a tick (CartPole: ~15 calls per env-step),
# so it calls these itself, with no Python function of this module in between (a call frame
# costs about what the read does): it takes its body's handle once, when it enters a space
# (:func:`handle`), and each function below is one Chipmunk call on it. Chipmunk's functions
# straight cost several times less than pymunk's properties. Without :data:`FAST` the handle is
# the pymunk body and each function is pymunk's public API, with the same arguments and results
# (a vector read has ``x`` and ``y``).

if FAST:

    def handle(body: pymunk.Body) -> Any:
        """What the functions below take for ``body``: its Chipmunk body (``cpBody *``)."""
        return body._body

    position_of = lib.cpBodyGetPosition
    angle_of = lib.cpBodyGetAngle
    velocity_of = lib.cpBodyGetVelocity
    angular_velocity_of = lib.cpBodyGetAngularVelocity
    set_velocity_of = lib.cpBodySetVelocity  # (handle, (x, y))
    set_angular_velocity_of = lib.cpBodySetAngularVelocity
    center_of_gravity_of = lib.cpBodyGetCenterOfGravity
    local_to_world_of = lib.cpBodyLocalToWorld  # (handle, point): the point in the world
    apply_force_at_world_point_of = lib.cpBodyApplyForceAtWorldPoint  # (handle, force, point)
else:

    def handle(body: pymunk.Body) -> Any:  # noqa: D103
        return body

    position_of = operator.attrgetter("position")
    angle_of = operator.attrgetter("angle")
    velocity_of = operator.attrgetter("velocity")
    angular_velocity_of = operator.attrgetter("angular_velocity")
    center_of_gravity_of = operator.attrgetter("center_of_gravity")
    local_to_world_of = pymunk.Body.local_to_world
    apply_force_at_world_point_of = pymunk.Body.apply_force_at_world_point

    def set_velocity_of(body: pymunk.Body, velocity: tuple[float, float]) -> None:  # noqa: D103
        body.velocity = velocity

    def set_angular_velocity_of(body: pymunk.Body, value: float) -> None:  # noqa: D103
        body.angular_velocity = value
