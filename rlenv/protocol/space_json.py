"""A space as JSON: its one JSON form, which the HTTP gateway serves and ONNX policies store.

:func:`space_to_json` describes a space in gymnasium's terms, from the wire spec of
:mod:`rlenv.protocol.spaces` (``{"type": "Box", "shape", "low", "high", "dtype"}``,
``Discrete``, ``MultiDiscrete``, ``MultiBinary``, ``Tuple``, ``Dict``): dtypes by name
(``"float32"``), a bound shared by every element as one number, and infinities as the strings
``"Infinity"`` and ``"-Infinity"`` (JSON has none). :func:`space_to_json_text` writes it as text;
:func:`space_from_json` reads it back, from the object or its text, and also reads the form that
rlenv 0.1's ONNX policies hold (every bound listed, dtypes as ``"<f4"``, infinities as
``"inf"``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv.protocol.spaces import space_from_spec, space_to_spec

__all__ = ["json_number", "space_from_json", "space_to_json", "space_to_json_text"]

_NON_FINITE = {math.inf: "Infinity", -math.inf: "-Infinity"}
_FROM_TEXT = {
    "Infinity": math.inf,
    "-Infinity": -math.inf,
    "NaN": math.nan,
    "inf": math.inf,
    "-inf": -math.inf,
    "nan": math.nan,
}  # (the older form's)


def json_number(value: Any) -> Any:
    """``value``, or the string JSON carries for it where it is not finite (``"Infinity"``)."""
    if isinstance(value, float) and not math.isfinite(value):
        return _NON_FINITE.get(value, "NaN")
    return value


def space_to_json(space: spaces.Space) -> dict[str, Any]:
    """``space`` in gymnasium's terms, as a JSON object (see the module docstring).

    Raises:
        TypeError: the space cannot travel (see :func:`rlenv.protocol.spaces.space_to_spec`).
    """
    return _spec_to_json(space_to_spec(space))


def space_to_json_text(space: spaces.Space) -> str:
    """:func:`space_to_json` as JSON text (what an ONNX policy's metadata holds).

    Raises:
        TypeError: the space cannot travel.
    """
    return json.dumps(space_to_json(space), allow_nan=False)


def _spec_to_json(spec: Mapping[str, Any]) -> dict[str, Any]:
    kind = spec["type"]
    if kind == "Box":
        low, high = np.asarray(spec["low"]), np.asarray(spec["high"])
        return {
            "type": kind,
            "shape": list(low.shape),
            "low": _bound(low),
            "high": _bound(high),
            "dtype": np.dtype(spec["dtype"]).name,
        }
    if kind == "Tuple":
        return {"type": kind, "spaces": [_spec_to_json(s) for s in spec["spaces"]]}
    if kind == "Dict":
        return {"type": kind, "spaces": {k: _spec_to_json(s) for k, s in spec["spaces"].items()}}
    described: dict[str, Any] = {"type": kind}
    for key, value in spec.items():
        if key == "dtype":
            described[key] = np.dtype(value).name
        elif key != "type":
            described[key] = value.tolist() if isinstance(value, np.ndarray) else value
    return described


def _bound(array: np.ndarray) -> Any:
    """One number when every element shares it, else a list in the array's shape."""
    flat = array.reshape(-1)
    if flat.size and (flat == flat[0]).all():
        return json_number(flat[0].item())
    return _numbers(array.tolist())


def _numbers(value: Any) -> Any:
    return [_numbers(item) for item in value] if isinstance(value, list) else json_number(value)


def space_from_json(described: Any) -> spaces.Space:
    """The gymnasium space :func:`space_to_json` described (the object, or its JSON text).

    Raises:
        ValueError: not JSON, or not a description of a supported space.
    """
    if isinstance(described, str | bytes):
        try:
            described = json.loads(described)
        except ValueError as error:
            raise ValueError(f"not a space in JSON: {error}") from None
    try:
        return space_from_spec(_json_to_spec(described))
    except (KeyError, TypeError, AttributeError) as error:
        raise ValueError(f"not a space: {error!r}") from None


def _json_to_spec(described: Any) -> dict[str, Any]:
    if not isinstance(described, Mapping):
        raise ValueError(f"a space is an object, got {described!r:.80}")
    kind = described.get("type")
    if kind == "Tuple":
        return {"type": kind, "spaces": [_json_to_spec(s) for s in described["spaces"]]}
    if kind == "Dict":
        return {
            "type": kind,
            "spaces": {k: _json_to_spec(s) for k, s in described["spaces"].items()},
        }
    spec: dict[str, Any] = {"type": kind}
    dtype = _dtype(described["dtype"]) if "dtype" in described else None
    if dtype is not None:
        spec["dtype"] = dtype.str
    if kind == "Box":
        bounds = {key: _array(described[key], dtype) for key in ("low", "high")}
        shape = (
            tuple(int(n) for n in described["shape"])
            if "shape" in described
            else bounds["low"].shape
        )  # the older form lists every bound
        for key, bound in bounds.items():
            spec[key] = np.broadcast_to(bound, shape).copy()
        return spec
    for key, value in described.items():
        if key not in ("type", "dtype"):
            spec[key] = (
                np.asarray(value, np.int64)
                if isinstance(value, list) and kind == "MultiDiscrete"
                else value
            )
    return spec


def _dtype(name: Any) -> np.dtype:
    dtype = np.dtype(str(name))
    if dtype.kind not in "biuf":
        raise ValueError(f"dtype {name!r:.40} is not numeric")
    return dtype


def _array(value: Any, dtype: np.dtype | None) -> np.ndarray:
    def number(item: Any) -> Any:
        if isinstance(item, list):
            return [number(i) for i in item]
        return _FROM_TEXT[item] if isinstance(item, str) else item

    return np.asarray(number(value), dtype)
