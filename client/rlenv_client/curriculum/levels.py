"""What a level is to a curriculum: plain data, checked, copied and made hashable.

A level is an int seed or a packed scene's data
(:meth:`rlenv.scene2d.packed_scene.PackedScene.to_data`): maps with str keys, lists, numbers,
strings, bytes, booleans and nil. A level is kept as a copy (tuples as lists, numpy scalars as
Python numbers), so that msgpack and json carry it as it is and the caller may reuse the object
it passed.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import Any

import numpy as np

__all__ = ["Level", "level_copy", "level_key"]

Level = Any
"""An int seed, or plain data (a packed scene's data)."""

_SCALARS: tuple[type, ...] = (type(None), bool, int, float, str, bytes)


def level_copy(level: Any) -> Level:
    """A checked copy of ``level``: plain types only, tuples as lists, numpy scalars unwrapped.

    Args:
        level: an int seed, or plain data nested in maps (str keys) and lists.

    Returns:
        A copy that shares no container with ``level``.

    Raises:
        ValueError: ``level`` holds something else (an object, a set, a map with a non-str key).
    """
    return _copy(level, "level")


def level_key(level: Level) -> Hashable:
    """A hashable form of a checked level: two levels have equal keys when their data are equal."""
    if isinstance(level, dict):
        return frozenset((key, level_key(value)) for key, value in level.items())
    if isinstance(level, list):
        return tuple(level_key(item) for item in level)
    return level


def _copy(value: Any, where: str) -> Any:
    if value.__class__ in _SCALARS:
        return value
    for scalar in _SCALARS[1:]:  # bool before int: bool is an int
        if isinstance(value, scalar):
            return scalar(value)
    if isinstance(value, np.generic) and not isinstance(value, np.object_ | np.void):
        return _copy(value.item(), where)
    if isinstance(value, list | tuple):
        return [_copy(item, f"{where}[{index}]") for index, item in enumerate(value)]
    if isinstance(value, dict):
        return {_key(key, where): _copy(item, f"{where}[{key!r}]") for key, item in value.items()}
    raise ValueError(
        f"{where} is a {type(value).__name__}: a level is an int seed or plain data "
        "(maps with str keys, lists, numbers, strings, bytes, booleans, None), as a "
        "packed scene's data"
    )


def _key(key: Any, where: str) -> str:
    if not isinstance(key, str):
        raise ValueError(
            f"{where} has a {type(key).__name__} key {key!r:.40}: a level's maps "
            "have str keys, as msgpack and json carry them"
        )
    return str(key)
