"""The array kinds of space: Box, MultiDiscrete and MultiBinary, their checks and their codec.

Their values travel as raw bytes in the space's dtype, C order (see :mod:`rlenv.protocol.spaces`,
whose :data:`~rlenv.protocol.spaces.KINDS` holds the three records). A check converts what came
off the wire, or refuses it with a message naming the offending element and the rule it broke.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv.protocol._space_kind import Checker, Codec, SpaceKind, SpaceMismatch, Spec

__all__ = ["BoxKind", "MultiBinaryKind", "MultiDiscreteKind", "non_finite_at"]

_SMALL = 32
"""Arrays up to this many elements are checked element by element in Python (cheaper than
numpy's reductions at this size); larger ones with numpy."""


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


class BoxKind(_ArrayKind):
    """Box spaces: arrays of any numeric dtype, within bounds per element."""

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


class MultiDiscreteKind(_ArrayKind):
    """MultiDiscrete spaces: arrays of integers, each in its own range."""

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


class MultiBinaryKind(_ArrayKind):
    """MultiBinary spaces: arrays of zeros and ones."""

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
                finite = non_finite_at(array) is None
            if not finite:
                where = non_finite_at(array)
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


_WIDE = {"f": np.float64, "c": np.complex128}


def non_finite_at(array: np.ndarray, path: str = "") -> str | None:
    """Where ``array`` holds NaN or infinity: ``path`` and the first such element's index.

    Returns:
        ``path`` followed by the index, e.g. ``"[2]"``, or ``None`` if every element is finite.
    """
    kind = array.dtype.kind
    if kind not in "fc":
        return None
    # One reduction on the happy path for narrow floats: their sum in double precision
    # cannot overflow, so it is finite exactly when every element is.
    narrow = array.dtype.itemsize <= (8 if kind == "c" else 4)
    if not (narrow and cmath.isfinite(array.sum(dtype=_WIDE[kind]))):
        finite = np.isfinite(array)
        if not finite.all():
            return path + (_first(~finite) or "")
    return None
