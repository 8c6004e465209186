"""Gymnasium spaces on the wire, and checking values against them.

A space travels once, in the hello, as a plain map (its *spec*), like dm_env_rpc's tensor
specs: ``space_from_spec(space_to_spec(s)) == s`` for every supported space. Actions are then
checked against the space with :func:`check`, which names the offending field in its message,
and observations are rebuilt into the space's native types with :func:`from_wire`.

Supported: Box, Discrete, MultiDiscrete, MultiBinary, Tuple and Dict (nested freely).
"""

from __future__ import annotations

import cmath
from collections.abc import Callable, Mapping
from functools import singledispatch
from typing import Any

import numpy as np
from gymnasium import spaces

__all__ = [
    "SpaceMismatch",
    "check",
    "find_non_finite",
    "from_wire",
    "space_from_spec",
    "space_to_spec",
]

Spec = dict[str, Any]


class SpaceMismatch(ValueError):
    """A value does not belong to a space; the message names the offending field."""


# --- specs ---------------------------------------------------------------------------------


@singledispatch
def space_to_spec(space: spaces.Space) -> Spec:
    """Describe ``space`` as a plain map that msgpack can carry.

    Raises:
        TypeError: the space type cannot travel on the wire.
    """
    raise TypeError(f"{type(space).__name__} spaces are not supported on the wire")


@space_to_spec.register
def _(space: spaces.Box) -> Spec:
    return {"type": "Box", "dtype": space.dtype.str, "low": space.low, "high": space.high}


@space_to_spec.register
def _(space: spaces.Discrete) -> Spec:
    return {"type": "Discrete", "n": int(space.n), "start": int(space.start)}


@space_to_spec.register
def _(space: spaces.MultiDiscrete) -> Spec:
    return {"type": "MultiDiscrete", "dtype": space.dtype.str, "nvec": space.nvec,
            "start": space.start}


@space_to_spec.register
def _(space: spaces.MultiBinary) -> Spec:
    n = space.n
    return {"type": "MultiBinary", "n": int(n) if np.ndim(n) == 0 else [int(k) for k in n]}


@space_to_spec.register
def _(space: spaces.Tuple) -> Spec:
    return {"type": "Tuple", "spaces": [space_to_spec(s) for s in space.spaces]}


@space_to_spec.register
def _(space: spaces.Dict) -> Spec:
    return {"type": "Dict", "spaces": {k: space_to_spec(s) for k, s in space.spaces.items()}}


def _box(spec: Spec) -> spaces.Box:
    return spaces.Box(low=spec["low"], high=spec["high"], dtype=np.dtype(spec["dtype"]))


def _multi_discrete(spec: Spec) -> spaces.MultiDiscrete:
    return spaces.MultiDiscrete(spec["nvec"], dtype=np.dtype(spec["dtype"]), start=spec["start"])


_BUILDERS: dict[str, Callable[[Spec], spaces.Space]] = {
    "Box": _box,
    "Discrete": lambda spec: spaces.Discrete(spec["n"], start=spec["start"]),
    "MultiDiscrete": _multi_discrete,
    "MultiBinary": lambda spec: spaces.MultiBinary(spec["n"]),
    "Tuple": lambda spec: spaces.Tuple([space_from_spec(s) for s in spec["spaces"]]),
    "Dict": lambda spec: spaces.Dict({k: space_from_spec(s) for k, s in spec["spaces"].items()}),
}


def space_from_spec(spec: Spec) -> spaces.Space:
    """Rebuild the gymnasium space that :func:`space_to_spec` described.

    Raises:
        ValueError: the spec is not a valid description of a supported space.
    """
    kind = spec.get("type") if isinstance(spec, Mapping) else None
    if not isinstance(kind, str) or kind not in _BUILDERS:
        raise ValueError(f"not a space spec: {spec!r:.200}")
    try:
        return _BUILDERS[kind](spec)
    except (AttributeError, KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"invalid {spec['type']} space spec: {exc}") from exc


# --- checking values -----------------------------------------------------------------------


@singledispatch
def check(space: spaces.Space, value: Any, path: str = "action") -> Any:
    """Check that ``value`` belongs to ``space`` and return it in the space's native form.

    Lists become arrays of the space's dtype, integers become numpy integers, and so on. The
    check is strict: wrong shape, wrong kind of dtype, NaN or infinity, and values out of
    bounds are refused.

    Args:
        space: the space the value must belong to.
        value: the decoded value, as it came off the wire.
        path: how to name the value in error messages, e.g. ``"action"``.

    Raises:
        SpaceMismatch: with a message naming ``path`` (and the index within it) and the rule
            that was broken.
    """
    raise SpaceMismatch(f"{path}: {type(space).__name__} spaces are not supported")


def _as_array(value: Any, path: str) -> np.ndarray:
    if isinstance(value, np.ndarray):
        array = value
    elif isinstance(value, int | float | list | tuple | np.generic):
        try:
            array = np.asarray(value)
        except ValueError as exc:  # ragged nested lists
            raise SpaceMismatch(f"{path} is not a rectangular array: {exc}") from None
    else:
        raise SpaceMismatch(f"{path} must be an array or a number, got {type(value).__name__}")
    if array.dtype.kind not in "biuf":
        raise SpaceMismatch(f"{path} must be numeric, got dtype {array.dtype}")
    return array


def _check_shape(array: np.ndarray, shape: tuple[int, ...], path: str) -> None:
    if array.shape != shape:
        raise SpaceMismatch(f"{path} has shape {array.shape}, expected {shape}")


def _first(mask: np.ndarray) -> str:
    index = tuple(int(i) for i in np.argwhere(mask)[0])
    return "" if not index else "[" + ", ".join(map(str, index)) + "]"


def _check_integers(array: np.ndarray, path: str) -> None:
    if array.dtype.kind == "f":
        raise SpaceMismatch(f"{path} must hold integers, got dtype {array.dtype}")


@check.register
def _(space: spaces.Box, value: Any, path: str = "action") -> np.ndarray:
    array = _as_array(value, path)
    _check_shape(array, space.shape, path)
    if array.dtype.kind == "b" and space.dtype.kind != "b":
        raise SpaceMismatch(f"{path} has dtype bool, expected {space.dtype}")
    if space.dtype.kind in "biu":
        _check_integers(array, path)
        if not ((array >= space.low) & (array <= space.high)).all():
            _check_bounds(array, space, path)  # exactly, before a cast could wrap around
        return array.astype(space.dtype, copy=False)
    if array.dtype == space.dtype:
        cast = array
    else:  # a value too large for the space's dtype becomes inf, refused below with its reason
        with np.errstate(over="ignore"):
            cast = array.astype(space.dtype)
    # The happy path in two ufuncs: NaN is never inside the bounds, and a finite sum rules out
    # infinities that infinite bounds would let through (a huge finite sum may only overflow
    # to inf, which sends us down the careful path).
    if ((cast >= space.low) & (cast <= space.high)).all() and np.isfinite(cast.sum()):
        return cast
    _check_finite(array, path)
    _check_finite(cast, path, f" (too large for {space.dtype})")
    _check_bounds(cast, space, path)
    return cast


def _check_finite(array: np.ndarray, path: str, why: str = "") -> None:
    if array.dtype.kind == "f":
        finite = np.isfinite(array)
        if not finite.all():
            bad = array[~finite].flat[0]
            raise SpaceMismatch(f"{path}{_first(~finite)} is {bad}{why}, expected a finite number")


def _check_bounds(array: np.ndarray, space: spaces.Box, path: str) -> None:
    outside = (array < space.low) | (array > space.high)
    if outside.any():
        flat = int(np.flatnonzero(outside)[0])
        raise SpaceMismatch(
            f"{path}{_first(outside)} is {array.flat[flat]}, outside the bounds "
            f"[{space.low.flat[flat]}, {space.high.flat[flat]}]"
        )


@check.register
def _(space: spaces.Discrete, value: Any, path: str = "action") -> np.integer:
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value[()]
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
        raise SpaceMismatch(f"{path} must be an integer, got {type(value).__name__}")
    if not space.start <= value < space.start + space.n:
        raise SpaceMismatch(
            f"{path} is {value}, outside [{space.start}, {space.start + space.n - 1}]"
        )
    return space.dtype.type(value)


@check.register
def _(space: spaces.MultiDiscrete, value: Any, path: str = "action") -> np.ndarray:
    array = _as_array(value, path)
    _check_shape(array, space.shape, path)
    _check_integers(array, path)
    offset = array - space.start
    outside = (offset < 0) | (offset >= space.nvec)
    if outside.any():
        flat = int(np.flatnonzero(outside)[0])
        raise SpaceMismatch(
            f"{path}{_first(outside)} is {array.flat[flat]}, outside "
            f"[{space.start.flat[flat]}, {space.start.flat[flat] + space.nvec.flat[flat] - 1}]"
        )
    return array.astype(space.dtype, copy=False)


@check.register
def _(space: spaces.MultiBinary, value: Any, path: str = "action") -> np.ndarray:
    array = _as_array(value, path)
    _check_shape(array, space.shape, path)
    _check_integers(array, path)
    outside = (array != 0) & (array != 1)
    if outside.any():
        raise SpaceMismatch(f"{path}{_first(outside)} is {array[outside].flat[0]}, expected 0 or 1")
    return array.astype(space.dtype, copy=False)


@check.register
def _(space: spaces.Tuple, value: Any, path: str = "action") -> tuple[Any, ...]:
    if not isinstance(value, list | tuple) or len(value) != len(space.spaces):
        raise SpaceMismatch(f"{path} must be a sequence of {len(space.spaces)} items")
    pairs = enumerate(zip(space.spaces, value, strict=True))
    return tuple(check(s, v, f"{path}[{i}]") for i, (s, v) in pairs)


@check.register
def _(space: spaces.Dict, value: Any, path: str = "action") -> dict[str, Any]:
    if not isinstance(value, Mapping):
        raise SpaceMismatch(f"{path} must be a map with keys {sorted(space.spaces)}")
    if value.keys() != space.spaces.keys():
        missing = sorted(space.spaces.keys() - value.keys())
        unknown = sorted(map(str, value.keys() - space.spaces.keys()))
        raise SpaceMismatch(f"{path} has missing keys {missing} and unknown keys {unknown}")
    return {k: check(s, value[k], f"{path}[{k!r}]") for k, s in space.spaces.items()}


# --- rebuilding values on the client -------------------------------------------------------


@singledispatch
def from_wire(space: spaces.Space, value: Any) -> Any:
    """Rebuild a decoded wire value in the native form of ``space`` (no bounds checks).

    Arrays come back writable, as gymnasium environments return them: an array decoded in
    place from a frame (read-only) is copied once; anything else is converted.
    """
    return value


def _writable_array(space: spaces.Space, value: Any) -> np.ndarray:
    array = np.asarray(value, dtype=space.dtype)
    return array if array.flags.writeable else array.copy()


from_wire.register(spaces.Box, _writable_array)
from_wire.register(spaces.MultiDiscrete, _writable_array)
from_wire.register(spaces.MultiBinary, _writable_array)


@from_wire.register
def _(space: spaces.Discrete, value: Any) -> np.integer:
    return space.dtype.type(value)


@from_wire.register
def _(space: spaces.Tuple, value: Any) -> tuple[Any, ...]:
    return tuple(from_wire(s, v) for s, v in zip(space.spaces, value, strict=True))


@from_wire.register
def _(space: spaces.Dict, value: Any) -> dict[str, Any]:
    return {k: from_wire(s, value[k]) for k, s in space.spaces.items()}


_WIDE = {"f": np.float64, "c": np.complex128}


def find_non_finite(value: Any, path: str = "") -> str | None:
    """Where ``value`` (arrays, numbers, nested lists, tuples and maps) holds NaN or infinity.

    Returns:
        The path of the first such element, e.g. ``"[2]"`` or ``"['pos'][0]"``, or ``None``.
    """
    if type(value) is np.ndarray:
        kind = value.dtype.kind
        if kind not in "fc":
            return None
        # One reduction on the happy path for narrow floats: their sum in double precision
        # cannot overflow, so it is finite exactly when every element is.
        narrow = value.dtype.itemsize <= (8 if kind == "c" else 4)
        if not (narrow and cmath.isfinite(value.sum(dtype=_WIDE[kind]))):
            finite = np.isfinite(value)
            if not finite.all():
                return path + (_first(~finite) or "")
        return None
    if isinstance(value, float | np.floating):
        return None if np.isfinite(value) else path
    if isinstance(value, Mapping):
        items: Any = ((f"[{k!r}]", v) for k, v in value.items())
    elif isinstance(value, list | tuple):
        items = ((f"[{i}]", v) for i, v in enumerate(value))
    else:
        return None
    for step, item in items:
        found = find_non_finite(item, path + step)
        if found is not None:
            return found
    return None
