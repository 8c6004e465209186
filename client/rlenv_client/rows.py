"""Rows of batched values: one sub-environment's share of gymnasium's ``batch_space`` layout.

A batch of a Box, Discrete, MultiDiscrete or MultiBinary space (every space the protocol
carries, see :mod:`rlenv.protocol.spaces`) is one array whose first axis runs over
sub-environments; a batch of a Dict or Tuple space is a map or tuple of such batches. These
helpers cut and fill such batches without going through one value per sub-environment.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["row", "rows", "set_row", "set_rows"]


def rows(batch: Any, start: int, stop: int) -> Any:
    """Sub-environments ``start`` to ``stop`` (excluded) of ``batch`` (views where possible)."""
    return _read(batch, lambda array: np.asarray(array)[start:stop])


def row(batch: Any, index: int) -> Any:
    """Sub-environment ``index`` of ``batch``, copied (later writes to the batch leave it be)."""
    return _read(batch, lambda array: np.array(array[index]))


def set_rows(out: Any, start: int, part: Any) -> None:
    """Write the batch ``part`` into ``out`` from sub-environment ``start`` on."""
    _write(out, part, lambda piece: slice(start, start + len(piece)))


def set_row(out: Any, index: int, value: Any) -> None:
    """Write one sub-environment's ``value`` into row ``index`` of ``out``."""
    _write(out, value, lambda piece: index)


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
