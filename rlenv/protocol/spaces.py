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

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv.protocol._array_spaces import (
    BoxKind,
    MultiBinaryKind,
    MultiDiscreteKind,
    non_finite_at,
)
from rlenv.protocol._moved_names import moved_name
from rlenv.protocol._space_kind import Checker, Codec, SpaceKind, SpaceMismatch, Spec

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
    for kind in (
        BoxKind(),
        _Discrete(),
        MultiDiscreteKind(),
        MultiBinaryKind(),
        _Tuple(),
        _Dict(),
    )
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


def find_non_finite(value: Any, path: str = "") -> str | None:
    """Where ``value`` (arrays, numbers, nested lists, tuples and maps) holds NaN or infinity.

    Returns:
        The path of the first such element, e.g. ``"[2]"`` or ``"['pos'][0]"``, or ``None``.
    """
    if type(value) is np.ndarray:
        return non_finite_at(value, path)
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
