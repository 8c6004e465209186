"""Gymnasium spaces on the wire: specs, checks, and the packed form of values.

Everything rlenv knows about one kind of gymnasium space is one record, a :class:`SpaceKind`,
registered in :data:`KINDS` (to support a new kind of space, add one record there):

- its **spec**: the space described once, in the hello, as a plain map (like dm_env_rpc's
  tensor specs); ``space_from_spec(space_to_spec(s)) == s``;
- its **check**: whether a value (an action, as it came off the wire) belongs to the space,
  with a message naming the offending field; :func:`check` is the careful, general check, and
  :func:`compile_check` prepares once per space a checker whose common case costs a fraction of
  a microsecond;
- its **packed form**: how values of the space travel once the hello has fixed their dtype and
  shape. Box, MultiDiscrete and MultiBinary values travel as raw bytes in the space's dtype, C
  order (no header, no ext type); Discrete values as integers; Tuple values as lists and Dict
  values as maps of packed values. :func:`codec_for` prepares a :class:`Codec` per space: the
  server packs observations with it, the client unpacks them, and a batch of K values packs as
  one value of gymnasium's ``batch_space(space, K)``.

Supported: Box, Discrete, MultiDiscrete, MultiBinary, Tuple and Dict (nested freely).
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces

from rlenv.protocol._moved_names import moved_name

__all__ = [
    "KINDS",
    "Codec",
    "SpaceKind",
    "SpaceMismatch",
    "check",
    "codec_for",
    "compile_check",
    "find_non_finite",
    "space_from_spec",
    "space_to_spec",
]

Spec = dict[str, Any]
Checker = Callable[[Any], Any]

_SMALL = 32
"""Arrays up to this many elements are checked element by element in Python (cheaper than
numpy's reductions at this size); larger ones with numpy."""


class SpaceMismatch(ValueError):
    """A value does not belong to a space; the message names the offending field."""


class Codec:
    """Packs and unpacks the values of one space (see the module docstring).

    Built by :func:`codec_for`; each kind of space has its own.
    """

    def pack(self, value: Any) -> Any:
        """``value`` in packed form, converted to the space's dtype.

        Raises:
            SpaceMismatch: the value does not have the space's structure or shape, or holds NaN
                or infinity (the message starts with where: ``"[1] is not finite"``).
        """
        raise NotImplementedError

    def pack_exact(self, value: Any) -> Any:
        """``value`` in packed form if it already has the space's exact dtype and shape.

        Anything else is returned as it is, for the receiver to check (and refuse with a
        precise message, or convert).
        """
        raise NotImplementedError

    def unpack(self, wire: Any, writable: bool = True) -> Any:
        """A packed value (or an array-like, for robustness) in the space's native form.

        With ``writable`` arrays are the caller's own (as gymnasium environments return them);
        otherwise they may be read-only views of the received bytes.
        """
        raise NotImplementedError

    def join(self, packed: list[Any]) -> Any:
        """K packed values of this space as one packed value of ``batch_space(space, K)``."""
        raise NotImplementedError


class SpaceKind:
    """Everything rlenv does with one class of gymnasium space; see the module docstring."""

    space_class: ClassVar[type[spaces.Space]]

    def to_spec(self, space: Any) -> Spec:
        """Describe ``space`` as a plain map that msgpack can carry."""
        raise NotImplementedError

    def from_spec(self, spec: Spec) -> spaces.Space:
        """Rebuild the space :meth:`to_spec` described (the spec's ``type`` is this kind)."""
        raise NotImplementedError

    def check(self, space: Any, value: Any, path: str) -> Any:
        """The general check (see :func:`check`)."""
        raise NotImplementedError

    def checker(self, space: Any, path: str) -> Checker:
        """A check prepared for ``space`` (see :func:`compile_check`)."""
        return lambda value: self.check(space, value, path)

    def codec(self, space: Any) -> Codec:
        """The codec of ``space``'s packed form."""
        raise NotImplementedError


# --- arrays: Box, MultiDiscrete, MultiBinary ---------------------------------------------------


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


def _check_finite(array: np.ndarray, path: str, why: str = "") -> None:
    if array.dtype.kind == "f":
        finite = np.isfinite(array)
        if not finite.all():
            bad = array[~finite].flat[0]
            raise SpaceMismatch(f"{path}{_first(~finite)} is {bad}{why}, expected a finite number")


def _check_bounds(array: np.ndarray, low: np.ndarray, high: np.ndarray, path: str) -> None:
    outside = (array < low) | (array > high)
    if outside.any():
        flat = int(np.flatnonzero(outside)[0])
        raise SpaceMismatch(
            f"{path}{_first(outside)} is {array.flat[flat]}, outside the bounds "
            f"[{low.flat[flat]}, {high.flat[flat]}]"
        )


class _ArrayKind(SpaceKind):
    """The kinds whose values are arrays of a fixed dtype and shape."""

    def bounds(self, space: Any) -> tuple[np.ndarray, np.ndarray]:
        """The inclusive (low, high) bounds of every element, in the space's shape."""
        raise NotImplementedError

    def checker(self, space: Any, path: str) -> Checker:
        """Packed bytes or an array of the exact dtype and shape, checked in-bounds at once.

        Anything else, and anything out of bounds, goes to the careful :meth:`check`, which
        converts it or names what is wrong.
        """
        dtype, shape = space.dtype, space.shape
        nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        in_bounds = _bounds_test(*self.bounds(space), dtype)
        careful = self.check
        flat = len(shape) == 1  # frombuffer's own shape

        def check_value(value: Any) -> Any:
            kind = value.__class__
            if kind is bytes:
                if len(value) != nbytes:
                    raise SpaceMismatch(
                        f"{path} is {len(value)} bytes, expected {nbytes}: the "
                        f"packed form of shape {shape} and dtype {dtype}"
                    )
                value = np.frombuffer(value, dtype)
                if not flat:
                    value = value.reshape(shape)
            elif not (kind is np.ndarray and value.dtype == dtype and value.shape == shape):
                return careful(space, value, path)
            if in_bounds(value):
                return value
            return careful(space, value, path)

        return check_value

    def codec(self, space: Any) -> Codec:
        return _ArrayCodec(space.dtype, space.shape)


def _bounds_test(low: np.ndarray, high: np.ndarray, dtype: np.dtype) -> Callable[[Any], bool]:
    """A test that an array of ``dtype`` lies within [low, high] and is finite.

    NaN fails every comparison and infinities fail finite bounds, so finiteness is tested
    separately only where a bound is infinite.
    """
    lows, highs = low.reshape(-1).tolist(), high.reshape(-1).tolist()
    floats = dtype.kind == "f"
    test_finite = floats and not all(math.isfinite(b) for b in lows + highs)
    if len(lows) == 1:
        lo, hi = lows[0], highs[0]

        def one(array: np.ndarray) -> bool:
            v = array.item()
            return lo <= v <= hi and not (test_finite and not math.isfinite(v))

        return one
    if len(lows) <= _SMALL:
        bounds = list(zip(lows, highs, strict=True))

        def few(array: np.ndarray) -> bool:
            values = array.reshape(-1).tolist()
            if test_finite and not math.isfinite(sum(values)):
                return False
            return all(lo <= v <= hi for v, (lo, hi) in zip(values, bounds, strict=True))

        return few

    def many(array: np.ndarray) -> bool:
        if test_finite and not np.isfinite(array.sum(dtype=np.float64)):
            return False
        return bool(((array >= low) & (array <= high)).all())

    return many


class _Box(_ArrayKind):
    space_class = spaces.Box

    def to_spec(self, space: spaces.Box) -> Spec:
        return {"type": "Box", "dtype": space.dtype.str, "low": space.low, "high": space.high}

    def from_spec(self, spec: Spec) -> spaces.Box:
        return spaces.Box(low=spec["low"], high=spec["high"], dtype=np.dtype(spec["dtype"]))

    def bounds(self, space: spaces.Box) -> tuple[np.ndarray, np.ndarray]:
        return space.low, space.high

    def check(self, space: spaces.Box, value: Any, path: str) -> np.ndarray:
        array = _as_array(value, path)
        _check_shape(array, space.shape, path)
        if array.dtype.kind == "b" and space.dtype.kind != "b":
            raise SpaceMismatch(f"{path} has dtype bool, expected {space.dtype}")
        if space.dtype.kind in "biu":
            _check_integers(array, path)
            if not ((array >= space.low) & (array <= space.high)).all():
                _check_bounds(array, space.low, space.high, path)  # before a cast could wrap
            return array.astype(space.dtype, copy=False)
        if array.dtype == space.dtype:
            cast = array
        else:  # a value too large for the space's dtype becomes inf, refused below with its reason
            with np.errstate(over="ignore"):
                cast = array.astype(space.dtype)
        # NaN is never inside the bounds, and a finite sum rules out infinities that infinite
        # bounds would let through (a huge finite sum may only overflow to inf, which sends us
        # down the careful path).
        with np.errstate(over="ignore", invalid="ignore"):  # the careful path says why
            if ((cast >= space.low) & (cast <= space.high)).all() and np.isfinite(cast.sum()):
                return cast
        _check_finite(array, path)
        _check_finite(cast, path, f" (too large for {space.dtype})")
        _check_bounds(cast, space.low, space.high, path)
        return cast


class _MultiDiscrete(_ArrayKind):
    space_class = spaces.MultiDiscrete

    def to_spec(self, space: spaces.MultiDiscrete) -> Spec:
        return {
            "type": "MultiDiscrete",
            "dtype": space.dtype.str,
            "nvec": space.nvec,
            "start": space.start,
        }

    def from_spec(self, spec: Spec) -> spaces.MultiDiscrete[Any]:  # of the dtype spec names
        if not (np.asarray(spec["nvec"]) > 0).all():
            raise ValueError(f"nvec (counts) must be positive, got {spec['nvec']!r:.80}")
        return spaces.MultiDiscrete(
            spec["nvec"], dtype=np.dtype(spec["dtype"]), start=spec["start"]
        )

    def bounds(self, space: spaces.MultiDiscrete) -> tuple[np.ndarray, np.ndarray]:
        return space.start, space.start + space.nvec - 1

    def check(self, space: spaces.MultiDiscrete, value: Any, path: str) -> np.ndarray:
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


class _MultiBinary(_ArrayKind):
    space_class = spaces.MultiBinary

    def to_spec(self, space: spaces.MultiBinary) -> Spec:
        n = space.n
        return {
            "type": "MultiBinary",
            "n": int(n) if isinstance(n, int | np.integer) else [int(k) for k in n],
        }

    def from_spec(self, spec: Spec) -> spaces.MultiBinary:
        return spaces.MultiBinary(spec["n"])

    def bounds(self, space: spaces.MultiBinary) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(space.shape, space.dtype), np.ones(space.shape, space.dtype)

    def check(self, space: spaces.MultiBinary, value: Any, path: str) -> np.ndarray:
        array = _as_array(value, path)
        _check_shape(array, space.shape, path)
        _check_integers(array, path)
        outside = (array != 0) & (array != 1)
        if outside.any():
            raise SpaceMismatch(
                f"{path}{_first(outside)} is {array[outside].flat[0]}, expected 0 or 1"
            )
        return array.astype(space.dtype, copy=False)


class _ArrayCodec(Codec):
    """Arrays of one dtype and shape as raw bytes."""

    def __init__(self, dtype: np.dtype, shape: tuple[int, ...]) -> None:
        self.dtype, self.shape = dtype, shape
        self.size = int(np.prod(shape, dtype=np.int64))
        self.nbytes = self.size * dtype.itemsize
        self.floats = dtype.kind in "fc"
        # Small arrays of narrow floats are checked by one Python sum, no numpy reduction.
        self.narrow = dtype.kind == "f" and dtype.itemsize <= 4 and self.size <= _SMALL
        self.flat = len(shape) == 1  # frombuffer's own shape

    def pack(self, value: Any) -> bytes:
        if (
            value.__class__ is np.ndarray
            and value.dtype == self.dtype
            and value.shape == self.shape
        ):
            array = value
        else:
            try:
                array = np.asarray(value, dtype=self.dtype)
            except (TypeError, ValueError, OverflowError) as exc:
                raise SpaceMismatch(f"is not an array of {self.dtype}: {exc}") from None
            if array.shape != self.shape:
                raise SpaceMismatch(f"has shape {array.shape}, its space declares {self.shape}")
        if self.floats:
            if self.narrow:  # a double-precision sum of narrow floats cannot overflow
                flat = array if self.flat else array.reshape(-1)
                finite = math.isfinite(sum(flat.tolist()))
            else:
                finite = find_non_finite(array) is None
            if not finite:
                where = find_non_finite(array)
                raise SpaceMismatch(f"{where} is not finite" if where else "is not finite")
        return array.tobytes()

    def pack_exact(self, value: Any) -> Any:
        if (
            value.__class__ is np.ndarray
            and value.dtype == self.dtype
            and value.shape == self.shape
        ):
            return value.tobytes()
        return value

    def unpack(self, wire: Any, writable: bool = True) -> np.ndarray:
        if wire.__class__ is bytes and len(wire) == self.nbytes:
            array = np.frombuffer(bytearray(wire) if writable else wire, self.dtype)
            return array if self.flat else array.reshape(self.shape)
        array = np.asarray(wire, dtype=self.dtype)
        return array.copy() if writable and not array.flags.writeable else array

    def join(self, packed: list[Any]) -> bytes:
        return b"".join(packed)


# --- Discrete -------------------------------------------------------------------------------


class _Discrete(SpaceKind):
    space_class = spaces.Discrete

    def to_spec(self, space: spaces.Discrete) -> Spec:
        return {
            "type": "Discrete",
            "n": int(space.n),
            "start": int(space.start),
            "dtype": space.dtype.str,
        }

    def from_spec(self, spec: Spec) -> spaces.Discrete[Any]:  # of the dtype spec names
        return spaces.Discrete(spec["n"], start=spec["start"], dtype=np.dtype(spec["dtype"]))

    def check(self, space: spaces.Discrete, value: Any, path: str) -> np.integer:
        if isinstance(value, np.ndarray) and value.shape == ():
            value = value[()]
        if isinstance(value, np.ndarray):
            raise SpaceMismatch(
                f"{path} must be an integer (a Discrete value is one integer, "
                f"not an array), got an array of shape {value.shape} and dtype "
                f"{value.dtype}"
            )
        if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
            raise SpaceMismatch(f"{path} must be an integer, got {type(value).__name__}")
        if not space.start <= value < space.start + space.n:
            raise SpaceMismatch(
                f"{path} is {value}, outside [{space.start}, {space.start + space.n - 1}]"
            )
        return space.dtype.type(value)

    def checker(self, space: spaces.Discrete, path: str) -> Checker:
        first, end, native = int(space.start), int(space.start + space.n), space.dtype.type

        def check_value(value: Any) -> Any:
            if value.__class__ is int and first <= value < end:
                return native(value)
            return self.check(space, value, path)

        return check_value

    def codec(self, space: spaces.Discrete) -> Codec:
        return _IntegerCodec(space.dtype)


class _IntegerCodec(Codec):
    """Integers as msgpack integers; K of them as raw bytes of the space's dtype.

    (gymnasium's ``batch_space`` of a Discrete is a MultiDiscrete of that dtype.)
    """

    def __init__(self, dtype: np.dtype) -> None:
        self.dtype, self.native = dtype, dtype.type

    def pack(self, value: Any) -> int:
        if (
            isinstance(value, bool | np.bool_)
            or not isinstance(value, int | np.integer)
            and not (
                isinstance(value, np.ndarray) and value.shape == () and value.dtype.kind in "iu"
            )
        ):
            raise SpaceMismatch(f"is not an integer: {value!r:.40}")
        return int(value)

    def pack_exact(self, value: Any) -> Any:
        if isinstance(value, np.integer):
            return int(value)
        return value

    def unpack(self, wire: Any, writable: bool = True) -> np.integer:
        return self.native(wire)

    def join(self, packed: list[Any]) -> bytes:
        return np.array(packed, self.dtype).tobytes()


# --- Tuple and Dict ---------------------------------------------------------------------------


class _Tuple(SpaceKind):
    space_class = spaces.Tuple

    def to_spec(self, space: spaces.Tuple) -> Spec:
        return {"type": "Tuple", "spaces": [space_to_spec(s) for s in space.spaces]}

    def from_spec(self, spec: Spec) -> spaces.Tuple:
        return spaces.Tuple([space_from_spec(s) for s in spec["spaces"]])

    def check(self, space: spaces.Tuple, value: Any, path: str) -> tuple[Any, ...]:
        if not isinstance(value, list | tuple) or len(value) != len(space.spaces):
            raise SpaceMismatch(f"{path} must be a sequence of {len(space.spaces)} items")
        pairs = enumerate(zip(space.spaces, value, strict=True))
        return tuple(check(s, v, f"{path}[{i}]") for i, (s, v) in pairs)

    def checker(self, space: spaces.Tuple, path: str) -> Checker:
        items = [compile_check(s, f"{path}[{i}]") for i, s in enumerate(space.spaces)]

        def check_value(value: Any) -> Any:
            if value.__class__ not in (list, tuple) or len(value) != len(items):
                return self.check(space, value, path)
            return tuple(item(v) for item, v in zip(items, value, strict=True))

        return check_value

    def codec(self, space: spaces.Tuple) -> Codec:
        return _TupleCodec([codec_for(s) for s in space.spaces])


class _TupleCodec(Codec):
    def __init__(self, items: list[Codec]) -> None:
        self.items = items

    def pack(self, value: Any) -> list[Any]:
        if not isinstance(value, list | tuple) or len(value) != len(self.items):
            raise SpaceMismatch(f"is not a sequence of {len(self.items)} items")
        packed = []
        for index, (item, v) in enumerate(zip(self.items, value, strict=True)):
            try:
                packed.append(item.pack(v))
            except SpaceMismatch as error:
                raise SpaceMismatch(f"[{index}]{_joined(error)}") from None
        return packed

    def pack_exact(self, value: Any) -> Any:
        if isinstance(value, list | tuple) and len(value) == len(self.items):
            return [item.pack_exact(v) for item, v in zip(self.items, value, strict=True)]
        return value

    def unpack(self, wire: Any, writable: bool = True) -> tuple[Any, ...]:
        return tuple(item.unpack(v, writable) for item, v in zip(self.items, wire, strict=True))

    def join(self, packed: list[Any]) -> list[Any]:
        return [item.join([row[index] for row in packed]) for index, item in enumerate(self.items)]


class _Dict(SpaceKind):
    space_class = spaces.Dict

    def to_spec(self, space: spaces.Dict) -> Spec:
        return {"type": "Dict", "spaces": {k: space_to_spec(s) for k, s in space.spaces.items()}}

    def from_spec(self, spec: Spec) -> spaces.Dict:
        return spaces.Dict({k: space_from_spec(s) for k, s in spec["spaces"].items()})

    def check(self, space: spaces.Dict, value: Any, path: str) -> dict[str, Any]:
        if not isinstance(value, Mapping):
            raise SpaceMismatch(f"{path} must be a map with keys {sorted(space.spaces)}")
        if value.keys() != space.spaces.keys():
            missing = sorted(space.spaces.keys() - value.keys())
            unknown = sorted(map(str, value.keys() - space.spaces.keys()))
            raise SpaceMismatch(f"{path} has missing keys {missing} and unknown keys {unknown}")
        return {k: check(s, value[k], f"{path}[{k!r}]") for k, s in space.spaces.items()}

    def checker(self, space: spaces.Dict, path: str) -> Checker:
        items = {k: compile_check(s, f"{path}[{k!r}]") for k, s in space.spaces.items()}
        keys = space.spaces.keys()

        def check_value(value: Any) -> Any:
            if value.__class__ is not dict or value.keys() != keys:
                return self.check(space, value, path)
            return {k: item(value[k]) for k, item in items.items()}

        return check_value

    def codec(self, space: spaces.Dict) -> Codec:
        return _DictCodec({k: codec_for(s) for k, s in space.spaces.items()})


class _DictCodec(Codec):
    def __init__(self, items: dict[str, Codec]) -> None:
        self.items = items

    def pack(self, value: Any) -> dict[str, Any]:
        if not isinstance(value, Mapping) or value.keys() != self.items.keys():
            raise SpaceMismatch(f"is not a map with the keys {sorted(self.items)}")
        packed = {}
        for key, item in self.items.items():
            try:
                packed[key] = item.pack(value[key])
            except SpaceMismatch as error:
                raise SpaceMismatch(f"[{key!r}]{_joined(error)}") from None
        return packed

    def pack_exact(self, value: Any) -> Any:
        if isinstance(value, Mapping) and value.keys() == self.items.keys():
            return {k: item.pack_exact(value[k]) for k, item in self.items.items()}
        return value

    def unpack(self, wire: Any, writable: bool = True) -> dict[str, Any]:
        return {k: item.unpack(wire[k], writable) for k, item in self.items.items()}

    def join(self, packed: list[Any]) -> dict[str, Any]:
        return {k: item.join([row[k] for row in packed]) for k, item in self.items.items()}


def _joined(error: SpaceMismatch) -> str:
    """The message of a nested mismatch, after the index that locates it."""
    message = str(error)
    return message if message.startswith("[") else " " + message


# --- the table and the public functions -------------------------------------------------------

KINDS: dict[type[spaces.Space], SpaceKind] = {
    kind.space_class: kind
    for kind in (_Box(), _Discrete(), _MultiDiscrete(), _MultiBinary(), _Tuple(), _Dict())
}
"""Every kind of space rlenv supports, by gymnasium class."""

_BY_NAME = {kind.space_class.__name__: kind for kind in KINDS.values()}


def _kind(space: spaces.Space) -> SpaceKind | None:
    kind = KINDS.get(type(space))
    if kind is None:
        kind = next((k for cls, k in KINDS.items() if isinstance(space, cls)), None)
    return kind


def _supported(space: spaces.Space) -> SpaceKind:
    kind = _kind(space)
    if kind is None:
        raise TypeError(f"{type(space).__name__} spaces are not supported on the wire")
    return kind


def space_to_spec(space: spaces.Space) -> Spec:
    """Describe ``space`` as a plain map that msgpack can carry.

    Raises:
        TypeError: the space type cannot travel on the wire.
    """
    return _supported(space).to_spec(space)


def space_from_spec(spec: Spec) -> spaces.Space:
    """Rebuild the gymnasium space that :func:`space_to_spec` described.

    Raises:
        ValueError: the spec is not a valid description of a supported space.
    """
    name = spec.get("type") if isinstance(spec, Mapping) else None
    kind = _BY_NAME.get(name) if isinstance(name, str) else None
    if kind is None:
        raise ValueError(f"not a space spec: {spec!r:.200}")
    try:
        return kind.from_spec(spec)
    except (AttributeError, KeyError, TypeError, ValueError, AssertionError) as exc:
        # (gymnasium checks some arguments with assert)
        raise ValueError(f"invalid {name} space spec: {exc}") from exc


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
    kind = _kind(space)
    if kind is None:
        raise SpaceMismatch(f"{path}: {type(space).__name__} spaces are not supported")
    return kind.check(space, value, path)


def compile_check(space: spaces.Space, path: str = "action") -> Checker:
    """A checker prepared once for ``space``: the same verdicts and messages as :func:`check`.

    Its common case (a value in packed form, or an array of the space's exact dtype and shape,
    inside the bounds) costs a fraction of a microsecond; everything else goes to :func:`check`.
    Packed bytes of the wrong size are refused with a message saying what size was expected.
    """
    kind = _kind(space)
    if kind is None:
        return lambda value: check(space, value, path)
    return kind.checker(space, path)


def codec_for(space: spaces.Space) -> Codec:
    """The codec of ``space``'s packed form (see the module docstring).

    Raises:
        TypeError: the space type cannot travel on the wire.
    """
    return _supported(space).codec(space)


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


def __getattr__(name: str) -> Any:
    """The JSON form's old names here, for one release, with a warning (see space_json)."""
    return moved_name(__name__, name)
