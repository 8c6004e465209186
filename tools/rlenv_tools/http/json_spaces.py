"""Spaces and values as JSON: gymnasium's terms, a JSON Schema beside each space.

- :func:`space_to_json` describes a space as gymnasium names it, and :func:`space_from_json`
  reads it back: the space's one JSON form, :mod:`rlenv.protocol.space_json`'s (ONNX policies
  store it too), re-exported here.
- :func:`json_schema` gives the JSON Schema (2020-12) of the space's values as they travel:
  arrays as (nested) JSON lists, Discrete as an integer, Tuple as a list, Dict as an object.
- **Images** travel as base64 PNG strings, never as nested lists: an image is a uint8 array of
  shape ``(height, width, channels)`` with 1, 3 or 4 channels, wherever it appears (an image
  observation space's schema says so; actions are always lists).
- :func:`value_encoder` prepares, once per space, what turns its values into JSON values
  (:func:`action_decoder` what turns JSON actions into what the environment checks fastest);
  :func:`to_json` converts anything else (``info``, snapshots): numpy arrays to lists, numpy
  scalars to numbers, bytes to base64, and non-finite floats (which JSON lacks) to the strings
  ``"NaN"``, ``"Infinity"`` and ``"-Infinity"``, as protobuf's JSON mapping does.
  :func:`dumps` never fails on such values.
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv.protocol.space_json import json_number, space_from_json, space_to_json
from rlenv_tools.http._png import encode_png

__all__ = [
    "action_decoder",
    "dumps",
    "is_image",
    "json_schema",
    "space_from_json",
    "space_to_json",
    "to_json",
    "value_encoder",
]

_PER_ELEMENT = 64
"""1-D arrays up to this size get per-element bounds in their schema; larger ones, and arrays
of more dimensions, the loosest bounds of their elements."""
_encode = json.JSONEncoder(separators=(",", ":"), allow_nan=False).encode


# --- JSON Schema ----------------------------------------------------------------------------


def is_image(space: spaces.Space) -> bool:
    """Whether ``space`` holds images: uint8 Box of shape (height, width, 1, 3 or 4)."""
    return isinstance(space, spaces.Box) and _image_shape(space.dtype, space.shape)


def _image_shape(dtype: np.dtype, shape: tuple[int, ...]) -> bool:
    return dtype == np.uint8 and len(shape) == 3 and shape[2] in (1, 3, 4) and 0 not in shape


def json_schema(space: spaces.Space, *, images: bool = True) -> dict[str, Any]:
    """The JSON Schema of ``space``'s values as they travel (see the module docstring).

    Args:
        space: the space.
        images: describe image spaces as base64 PNG strings (observations) rather than nested
            lists (actions).
    """
    if isinstance(space, spaces.Box):
        if images and is_image(space):
            height, width, channels = space.shape
            return {
                "type": "string",
                "contentEncoding": "base64",
                "contentMediaType": "image/png",
                "description": f"a {width}x{height} PNG image, {channels} channel(s)",
            }
        return _array_schema(space.low, space.high, space.dtype)
    if isinstance(space, spaces.Discrete):
        start = int(space.start)
        return {"type": "integer", "minimum": start, "maximum": start + int(space.n) - 1}
    if isinstance(space, spaces.MultiDiscrete):
        return _array_schema(space.start, space.start + space.nvec - 1, space.dtype)
    if isinstance(space, spaces.MultiBinary):
        return _array_schema(
            np.zeros(space.shape, np.int8), np.ones(space.shape, np.int8), np.dtype(np.int8)
        )
    if isinstance(space, spaces.Tuple):
        items = [json_schema(s, images=images) for s in space.spaces]
        return {
            "type": "array",
            "prefixItems": items,
            "items": False,
            "minItems": len(items),
            "maxItems": len(items),
        }
    if isinstance(space, spaces.Dict):
        return {
            "type": "object",
            "additionalProperties": False,
            "properties": {k: json_schema(s, images=images) for k, s in space.spaces.items()},
            "required": list(space.spaces),
        }
    return {"description": f"a value of {space}"}


def _array_schema(low: np.ndarray, high: np.ndarray, dtype: np.dtype) -> dict[str, Any]:
    shape = low.shape
    if (
        len(shape) == 1
        and 0 < shape[0] <= _PER_ELEMENT
        and not ((low == low.flat[0]).all() and (high == high.flat[0]).all())
    ):
        return {
            "type": "array",
            "prefixItems": [
                _element(lo, hi, dtype) for lo, hi in zip(low.tolist(), high.tolist(), strict=True)
            ],
            "items": False,
            "minItems": shape[0],
            "maxItems": shape[0],
        }
    schema = _element(
        low.min().item() if low.size else 0, high.max().item() if high.size else 0, dtype
    )
    for size in reversed(shape):
        schema = {"type": "array", "items": schema, "minItems": size, "maxItems": size}
    return schema


def _element(low: Any, high: Any, dtype: np.dtype) -> dict[str, Any]:
    if dtype.kind == "b":
        return {"type": "boolean"}
    schema: dict[str, Any] = {"type": "integer" if dtype.kind in "iu" else "number"}
    if math.isfinite(low):
        schema["minimum"] = low
    if math.isfinite(high):
        schema["maximum"] = high
    return schema


# --- values ---------------------------------------------------------------------------------


def value_encoder(space: spaces.Space, *, images: bool = True) -> Callable[[Any], Any]:
    """A function from values of ``space`` (as clients return them) to JSON values.

    Prepared once per space: arrays become (nested) lists, images base64 PNG strings (with
    ``images``), Discrete values integers, Tuples lists and Dicts objects.
    """
    if isinstance(space, spaces.Box | spaces.MultiDiscrete | spaces.MultiBinary):
        if images and is_image(space):
            return _png_text
        return _array_to_list
    if isinstance(space, spaces.Discrete):
        return int
    if isinstance(space, spaces.Tuple):
        items = [value_encoder(s, images=images) for s in space.spaces]
        return lambda value: [encode(v) for encode, v in zip(items, value, strict=True)]
    if isinstance(space, spaces.Dict):
        fields = {k: value_encoder(s, images=images) for k, s in space.spaces.items()}
        return lambda value: {k: encode(value[k]) for k, encode in fields.items()}
    return to_json


def action_decoder(space: spaces.Space) -> Callable[[Any], Any]:
    """A function from JSON actions to what the environment checks fastest, prepared once.

    A JSON list of numbers for a float Box becomes an array of the space's dtype and shape
    (what the protocol's compiled check takes at once), as the environment's own careful check
    would convert it; anything else (another shape, booleans, text, numbers too large for the
    dtype, integer spaces, whose casts could wrap) is passed as it is, for the environment to
    refuse with its precise message. Dict and Tuple actions are decoded item by item.
    """
    if isinstance(space, spaces.Box) and space.dtype.kind == "f":
        return _float_array_decoder(space.dtype, space.shape)
    if isinstance(space, spaces.Dict):
        fields = {k: action_decoder(s) for k, s in space.spaces.items()}

        def decode_dict(value: Any) -> Any:
            if value.__class__ is not dict:
                return value
            return {k: fields[k](v) if k in fields else v for k, v in value.items()}

        return decode_dict
    if isinstance(space, spaces.Tuple):
        items = [action_decoder(s) for s in space.spaces]

        def decode_tuple(value: Any) -> Any:
            if value.__class__ is not list or len(value) != len(items):
                return value
            return [decode(v) for decode, v in zip(items, value, strict=True)]

        return decode_tuple
    return _unchanged


def _float_array_decoder(dtype: np.dtype, shape: tuple[int, ...]) -> Callable[[Any], Any]:
    limit = float(np.finfo(dtype).max)
    flat = len(shape) == 1

    def number(item: Any) -> bool:  # finite in dtype (JSON has no NaN; "1e999" parses as inf)
        return (item.__class__ is float or item.__class__ is int) and -limit <= item <= limit

    def decode(value: Any) -> Any:
        if value.__class__ is not list:
            return value
        if flat:
            if len(value) == shape[0] and all(number(item) for item in value):
                return np.array(value, dtype)
            return value
        try:
            array = np.asarray(value)
        except ValueError:  # ragged
            return value
        if (
            array.dtype.kind not in "iuf"
            or array.shape != shape
            or not (np.abs(array) <= limit).all()
        ):
            return value
        return array.astype(dtype)

    return decode


def _unchanged(value: Any) -> Any:
    return value


def _array_to_list(value: Any) -> Any:
    return value.tolist() if isinstance(value, np.ndarray) else to_json(value)


def _png_text(image: np.ndarray) -> str:
    return base64.b64encode(encode_png(image, level=1)).decode("ascii")


def to_json(value: Any) -> Any:
    """``value`` as plain JSON values (see the module docstring); never raises."""
    kind = type(value)
    if kind is str or kind is int or kind is bool or value is None:
        return value
    if kind is float:
        return value if math.isfinite(value) else json_number(value)
    if isinstance(value, np.ndarray):
        if _image_shape(value.dtype, value.shape):
            return _png_text(value)
        if value.dtype.kind == "c":
            return to_json(np.stack((value.real, value.imag), axis=-1))
        return to_json(value.tolist()) if value.dtype.kind == "f" else value.tolist()
    if isinstance(value, np.generic):
        return to_json(value.item())
    if isinstance(value, Mapping):
        return {str(k): to_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_json(v) for v in value]
    if isinstance(value, bytes | bytearray | memoryview):
        return base64.b64encode(value).decode("ascii")
    if isinstance(value, int | float):  # subclasses: bool-like, numpy's float64
        return to_json(float(value) if isinstance(value, float) else int(value))
    if isinstance(value, complex):
        return [to_json(value.real), to_json(value.imag)]
    return str(value)


def dumps(value: Any) -> bytes:
    """``value`` as compact JSON bytes; values JSON lacks are converted by :func:`to_json`."""
    try:
        return _encode(value).encode()
    except (TypeError, ValueError):
        return _encode(to_json(value)).encode()
