"""Rows of batched values: one sub-environment's share of gymnasium's ``batch_space`` layout.

A batch of a Box, Discrete, MultiDiscrete or MultiBinary space (every space the protocol
carries, see :mod:`rlenv.protocol.spaces`) is one array whose first axis runs over
sub-environments; a batch of a Dict or Tuple space is a map or tuple of such batches. These
helpers cut and fill such batches without going through one value per sub-environment.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, SupportsIndex

import numpy as np
from gymnasium import spaces

__all__ = ["check_shape", "empty_like", "repeat_rows", "row", "rows", "set_row", "set_rows"]

_ARRAYS = (spaces.Box, spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)


def check_shape(batched: spaces.Space, batch: Any, name: str) -> None:
    """Check that ``batch`` has the layout and array shapes of the batched space ``batched``.

    Only the structure and shapes: dtypes and bounds are the servers' to check.

    Raises:
        ValueError: naming ``name`` (and where in it), its shape and the expected one.
    """
    if isinstance(batched, _ARRAYS):  # first: Dict and Tuple are ABCs, slower to test for
        _check_array(batched, batch, name)
    elif isinstance(batched, spaces.Dict):
        if not isinstance(batch, Mapping) or set(batch) != set(batched.spaces):
            raise ValueError(f"{name} must be a map with the keys {sorted(batched.spaces)}")
        for key, space in batched.spaces.items():
            check_shape(space, batch[key], f"{name}[{key!r}]")
    elif isinstance(batched, spaces.Tuple):
        if not isinstance(batch, tuple | list) or len(batch) != len(batched.spaces):
            raise ValueError(f"{name} must be a tuple of {len(batched.spaces)} batches")
        for index, space in enumerate(batched.spaces):
            check_shape(space, batch[index], f"{name}[{index}]")
    else:
        _check_array(batched, batch, name)


def _check_array(batched: spaces.Space, batch: Any, name: str) -> None:
    try:
        shape = np.shape(batch)
    except ValueError:  # ragged nested lists
        raise ValueError(f"{name} is not an array of shape {batched.shape}") from None
    if shape != batched.shape:
        raise ValueError(f"{name} has shape {shape}, expected {batched.shape}")


def rows(batch: Any, start: int, stop: int) -> Any:
    """Sub-environments ``start`` to ``stop`` (excluded) of ``batch`` (views where possible)."""
    return _read(batch, lambda array: np.asarray(array)[start:stop])


def empty_like(batch: Any) -> Any:
    """A new batch of the same layout, shapes and dtypes as ``batch``, its values unset."""
    return _read(batch, np.empty_like)


def row(batch: Any, index: SupportsIndex) -> Any:
    """Sub-environment ``index`` of ``batch``, copied (later writes to the batch leave it be)."""
    return _read(batch, lambda array: np.array(array[index]))


def set_rows(out: Any, start: int, part: Any) -> None:
    """Write the batch ``part`` into ``out`` from sub-environment ``start`` on."""
    _write(out, part, lambda piece: slice(start, start + len(piece)))


def set_row(out: Any, index: SupportsIndex, value: Any) -> None:
    """Write one sub-environment's ``value`` into row ``index`` of ``out``."""
    _write(out, value, lambda piece: index)


def repeat_rows(value: Any, k: int) -> Any:
    """A batched value (or a map of them) with each row repeated ``k`` times."""
    if isinstance(value, dict):
        return {key: repeat_rows(item, k) for key, item in value.items()}
    return np.repeat(value, k, axis=0) if k > 1 else value


def _read(batch: Any, take: Callable[[Any], Any]) -> Any:
    """``take`` applied to every array of ``batch``, keeping its maps and tuples."""
    if isinstance(batch, dict):
        return {key: _read(value, take) for key, value in batch.items()}
    if isinstance(batch, tuple):
        return tuple(_read(value, take) for value in batch)
    return take(batch)


def _write(out: Any, value: Any, where: Callable[[Any], Any]) -> None:
    """Write every array of ``value`` into the matching array of ``out`` at ``where(piece)``."""
    if isinstance(out, dict):
        for key, column in out.items():
            _write(column, value[key], where)
    elif isinstance(out, tuple):
        for column, piece in zip(out, value, strict=True):
            _write(column, piece, where)
    else:
        out[where(value)] = value
