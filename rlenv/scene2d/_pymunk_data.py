"""pymunk objects copied and described as data: what ``duplicate`` and packed scenes need.

- :func:`copy_body` and :func:`copy_shape` make new pymunk objects with the same settings
  (a copy never shares a pymunk object with its original, and simulates as the original
  would: polygon vertices keep their order, masses their exact values);
- :func:`shape_to_data` / :func:`shape_from_data` turn a shape into plain data and back,
  checking every field of untrusted data;
- :class:`ConstraintRecipe` describes a joint's constraint as data (its kind and arguments),
  so that joints can be copied and packed, and builds the constraint when the joint attaches.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import pymunk

from rlenv.scene2d.node2d import Pose, apply

__all__ = [
    "ConstraintRecipe",
    "copy_body",
    "copy_shape",
    "shape_from_data",
    "shape_to_data",
]

MAX_VERTICES = 256
_DEFAULT_FILTER = pymunk.ShapeFilter()


def copy_body(body: pymunk.Body) -> pymunk.Body:
    """A new body like ``body``, in no space (placed where its node enters one).

    It has the kind, mass, moment, centre of gravity and velocities of ``body``.
    """
    kind = body.body_type
    if kind == pymunk.Body.STATIC:
        return pymunk.Body(body_type=kind)
    if kind == pymunk.Body.DYNAMIC:
        copy = pymunk.Body(body.mass, body.moment)
        if body.center_of_gravity != (0.0, 0.0):
            copy.center_of_gravity = body.center_of_gravity
    else:
        copy = pymunk.Body(body_type=kind)
    if body.velocity != (0.0, 0.0):
        copy.velocity = body.velocity
    if body.angular_velocity:
        copy.angular_velocity = body.angular_velocity
    return copy


def copy_shape(shape: pymunk.Shape) -> pymunk.Shape:
    """A new shape like ``shape`` (geometry, mass, material, filter), on no body."""
    copy = _new_shape(shape)
    _copy_material(shape, copy)
    return copy


def _new_shape(shape: pymunk.Shape) -> pymunk.Shape:
    if isinstance(shape, pymunk.Circle):
        return pymunk.Circle(None, shape.radius, shape.offset)
    if isinstance(shape, pymunk.Segment):
        return pymunk.Segment(None, shape.a, shape.b, shape.radius)
    if isinstance(shape, pymunk.Poly):
        return _poly(shape.get_vertices(), shape.radius)
    raise TypeError(f"cannot copy a {type(shape).__name__}")


def _poly(vertices: Sequence[tuple[float, float]], radius: float) -> pymunk.Poly:
    """A polygon with exactly these (convex, counter-clockwise) vertices, in this order.

    pymunk's constructor takes the convex hull, which may start at another vertex (a box's
    does); the order decides the polygon's mass data to the last bit, so it is set back.
    """
    poly = pymunk.Poly(None, vertices, radius=radius)
    poly.unsafe_set_vertices(vertices)
    return poly


def _copy_material(shape: pymunk.Shape, copy: pymunk.Shape) -> None:
    """Every setting of ``shape`` that differs from a new shape's, onto ``copy``."""
    if shape.mass > 0:
        copy.mass = shape.mass
    for name, default in _MATERIAL_DEFAULTS:
        value = getattr(shape, name)
        if value != default:
            setattr(copy, name, value)


_MATERIAL_DEFAULTS = (
    ("friction", 0.0),
    ("elasticity", 0.0),
    ("sensor", False),
    ("collision_type", 0),
    ("filter", pymunk.ShapeFilter()),
    ("surface_velocity", (0.0, 0.0)),
)


# --- shapes as data ----------------------------------------------------------------------------


def shape_to_data(shape: pymunk.Shape) -> dict[str, Any]:
    """``shape`` as plain data: its geometry and its material (defaults left out).

    Raises:
        TypeError: a kind of shape that has no description (only circles, segments and
            polygons do).
    """
    if isinstance(shape, pymunk.Circle):
        data: dict[str, Any] = {
            "kind": "circle",
            "radius": shape.radius,
            "offset": list(shape.offset),
        }
    elif isinstance(shape, pymunk.Segment):
        data = {"kind": "segment", "a": list(shape.a), "b": list(shape.b), "radius": shape.radius}
    elif isinstance(shape, pymunk.Poly):
        data = {
            "kind": "poly",
            "vertices": [list(v) for v in shape.get_vertices()],
            "radius": shape.radius,
        }
    else:
        raise TypeError(f"a {type(shape).__name__} cannot be described as data")
    if shape.mass > 0:
        data["mass"] = shape.mass
    if shape.collision_type:
        data["collision_type"] = shape.collision_type
    if shape.filter != _DEFAULT_FILTER:
        data["filter"] = list(shape.filter)
    if shape.surface_velocity != (0.0, 0.0):
        data["surface_velocity"] = list(shape.surface_velocity)
    return data


_SHAPE_KEYS = {
    "circle": {"radius", "offset"},
    "segment": {"a", "b", "radius"},
    "poly": {"vertices", "radius"},
}
_MATERIAL_KEYS = {"mass", "collision_type", "filter", "surface_velocity"}


def shape_from_data(data: Any) -> pymunk.Shape:
    """The shape :func:`shape_to_data` described, every field checked.

    Friction, elasticity and sensor are the node's: the caller sets them.

    Raises:
        ValueError: the data is not a shape description, naming the field at fault.
    """
    if not isinstance(data, Mapping):
        raise ValueError("a shape is a map with a 'kind'")
    kind = data.get("kind")
    keys = _SHAPE_KEYS.get(kind)  # type: ignore[arg-type]
    if keys is None:
        raise ValueError(f"shape kind {kind!r:.40} is not one of {sorted(_SHAPE_KEYS)}")
    unknown = set(data) - keys - _MATERIAL_KEYS - {"kind"}
    if unknown:
        raise ValueError(f"a {kind} has no {sorted(map(str, unknown))[0]!r:.40}")
    radius = number(data.get("radius", 0.0), "radius", low=0.0)
    if kind == "circle":
        shape: pymunk.Shape = pymunk.Circle(
            None, radius, vector(data.get("offset", (0, 0)), "offset")
        )
    elif kind == "segment":
        shape = pymunk.Segment(None, vector(data.get("a"), "a"), vector(data.get("b"), "b"), radius)
    else:
        shape = _checked_poly(data.get("vertices"), radius)
    if "mass" in data:
        mass = number(data["mass"], "mass", low=0.0)
        if mass:
            shape.mass = mass
    if "collision_type" in data:
        shape.collision_type = integer(data["collision_type"], "collision_type", 0, 2**32 - 1)
    if "filter" in data:
        group, categories, mask = _triple(data["filter"])
        shape.filter = pymunk.ShapeFilter(group, categories, mask)
    if "surface_velocity" in data:
        shape.surface_velocity = vector(data["surface_velocity"], "surface_velocity")
    return shape


def _checked_poly(vertices: Any, radius: float) -> pymunk.Poly:
    if not isinstance(vertices, list | tuple) or not 3 <= len(vertices) <= MAX_VERTICES:
        raise ValueError(f"a poly's vertices are a list of 3 to {MAX_VERTICES} points")
    points = [vector(v, "vertex") for v in vertices]
    hull = [tuple(v) for v in pymunk.Poly(None, points).get_vertices()]
    if len(hull) != len(points) or not _same_cycle(hull, points):
        raise ValueError("a poly's vertices must go counter-clockwise round a convex polygon")
    return _poly(points, radius)


def _same_cycle(hull: list[tuple[float, ...]], points: Sequence[tuple[float, ...]]) -> bool:
    if points[0] not in hull:
        return False
    start = hull.index(points[0])
    return hull[start:] + hull[:start] == points


def _triple(value: Any) -> tuple[int, int, int]:
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise ValueError("a shape's filter is [group, categories, mask]")
    return (
        integer(value[0], "filter group", 0, 2**63 - 1),
        integer(value[1], "filter categories", 0, 2**32 - 1),
        integer(value[2], "filter mask", 0, 2**32 - 1),
    )


# --- checked plain values -----------------------------------------------------------------------


def number(value: Any, what: str, low: float = -math.inf, finite: bool = True) -> float:
    """``value`` as a float, checked: a real number (finite unless not ``finite``), >= ``low``.

    Raises:
        ValueError: naming ``what``.
    """
    if value.__class__ is not float:  # environments set floats at every reset: the short way
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{what} must be a number, got {value!r:.40}")
        value = float(value)
    if not low <= value or (finite and (value == math.inf or value == -math.inf)):  # NaN: not <=
        needs = (["finite"] if finite else []) + ([f">= {low:g}"] if low > -math.inf else [])
        raise ValueError(f"{what} must be a number {' and '.join(needs)}, got {value!r:.40}")
    return value


def integer(value: Any, what: str, low: int, high: int) -> int:
    """``value`` as an int in [low, high], checked.

    Raises:
        ValueError: naming ``what``.
    """
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ValueError(f"{what} must be an integer in [{low}, {high}], got {value!r:.40}")
    return value


def vector(value: Any, what: str) -> tuple[float, float]:
    """``value`` as a pair of finite floats, checked.

    Raises:
        ValueError: naming ``what``.
    """
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ValueError(f"{what} must be two numbers [x, y], got {value!r:.40}")
    return (number(value[0], what), number(value[1], what))


# --- constraints ---------------------------------------------------------------------------------


class ConstraintRecipe:
    """A pymunk constraint as data: a kind and its arguments (what a Joint is built from).

    Calling it with two bodies builds the constraint, so it stands wherever a constraint
    factory does. Points given "in the world" (a pivot's ``anchor``) are in the frame of the
    joint's nearest Node2D ancestor when it has one: copies of a jointed subtree each get
    their own anchor.

    Args:
        kind: ``"pivot"``, ``"groove"``, ``"motor"`` or ``"spring"``.
        **arguments: that kind's arguments (see :attr:`KINDS`).

    Raises:
        ValueError: an unknown kind, or arguments that do not fit it.
    """

    KINDS: ClassVar[dict[str, tuple[tuple[str, str], ...]]] = {
        "pivot": (("anchor", "vector"),),
        "groove": (("groove_a", "vector"), ("groove_b", "vector"), ("anchor_b", "vector")),
        "motor": (("rate", "number"),),
        "spring": (
            ("anchor_a", "vector"),
            ("anchor_b", "vector"),
            ("rest_length", "number"),
            ("stiffness", "number"),
            ("damping", "number"),
        ),
    }
    """Each kind's arguments: name and sort (``vector``: a point; ``number``)."""

    __slots__ = ("arguments", "kind")

    def __init__(self, kind: str, **arguments: Any) -> None:
        spec = self.KINDS.get(kind)
        if spec is None:
            raise ValueError(f"constraint kind {kind!r:.40} is not one of {sorted(self.KINDS)}")
        names = [name for name, _ in spec]
        if set(arguments) != set(names):
            raise ValueError(f"a {kind} constraint takes exactly {', '.join(names)}")
        self.kind = kind
        # Each value as KINDS says: a point (tuple[float, float]) or a number (float).
        self.arguments: dict[str, Any] = {
            name: vector(arguments[name], f"{kind}.{name}")
            if sort == "vector"
            else number(arguments[name], f"{kind}.{name}")
            for name, sort in spec
        }

    def __call__(self, a: pymunk.Body, b: pymunk.Body) -> pymunk.Constraint:
        """The constraint between ``a`` and ``b``, its points in the world's frame."""
        return self.build(a, b, None)

    def build(self, a: pymunk.Body, b: pymunk.Body, frame: Pose | None) -> pymunk.Constraint:
        """The constraint between ``a`` and ``b``; world points are in ``frame`` (if any)."""
        arguments = self.arguments
        kind = self.kind
        if kind == "pivot":
            anchor = arguments["anchor"]
            return pymunk.PivotJoint(a, b, anchor if frame is None else apply(frame, *anchor))
        if kind == "groove":
            return pymunk.GrooveJoint(
                a, b, arguments["groove_a"], arguments["groove_b"], arguments["anchor_b"]
            )
        if kind == "motor":
            return pymunk.SimpleMotor(a, b, arguments["rate"])
        return pymunk.DampedSpring(
            a,
            b,
            arguments["anchor_a"],
            arguments["anchor_b"],
            arguments["rest_length"],
            arguments["stiffness"],
            arguments["damping"],
        )

    def to_data(self) -> dict[str, Any]:
        """``{"kind": ..., argument: value, ...}`` (points as lists)."""
        return {
            "kind": self.kind,
            **{
                name: list(value) if isinstance(value, tuple) else value
                for name, value in self.arguments.items()
            },
        }

    @classmethod
    def from_data(cls, data: Any) -> ConstraintRecipe:
        """The recipe :meth:`to_data` described, checked.

        Raises:
            ValueError: not a recipe, naming what is wrong.
        """
        if not isinstance(data, Mapping) or not isinstance(data.get("kind"), str):
            raise ValueError("a constraint is a map with a 'kind'")
        arguments = {key: value for key, value in data.items() if key != "kind"}
        if not all(isinstance(key, str) for key in arguments):
            raise ValueError("a constraint's arguments are named by strings")
        return cls(data["kind"], **arguments)

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, ConstraintRecipe)
            and other.kind == self.kind
            and other.arguments == self.arguments
        )

    def __hash__(self) -> int:
        return hash((self.kind, tuple(self.arguments.items())))

    def __repr__(self) -> str:
        arguments = ", ".join(f"{name}={value!r}" for name, value in self.arguments.items())
        return f"ConstraintRecipe({self.kind!r}, {arguments})"
