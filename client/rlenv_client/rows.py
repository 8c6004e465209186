"""Rows of batched values: one sub-environment's share of gymnasium's ``batch_space`` layout.

A batch of a Box, Discrete, MultiDiscrete or MultiBinary space (every space the protocol
carries, see :mod:`rlenv.spaces`) is one array whose first axis runs over sub-environments; a
batch of a Dict or Tuple space is a map or tuple of such batches.
These helpers cut and fill such batches without going through one value per sub-environment.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["row", "rows", "set_row", "set_rows"]


def rows(batch: Any, start: int, stop: int) -> Any:
    """Sub-environments ``start`` to ``stop`` (excluded) of ``batch`` (views where possible)."""
    if isinstance(batch, dict):
        return {key: rows(value, start, stop) for key, value in batch.items()}
    if isinstance(batch, tuple):
        return tuple(rows(value, start, stop) for value in batch)
    return np.asarray(batch)[start:stop]


def row(batch: Any, index: int) -> Any:
    """Sub-environment ``index`` of ``batch``, copied (later writes to the batch leave it be)."""
    if isinstance(batch, dict):
        return {key: row(value, index) for key, value in batch.items()}
    if isinstance(batch, tuple):
        return tuple(row(value, index) for value in batch)
    return np.array(batch[index])


def set_rows(out: Any, start: int, part: Any) -> None:
    """Write the batch ``part`` into ``out`` from sub-environment ``start`` on."""
    if isinstance(out, dict):
        for key, value in out.items():
            set_rows(value, start, part[key])
    elif isinstance(out, tuple):
        for value, piece in zip(out, part, strict=True):
            set_rows(value, start, piece)
    else:
        out[start:start + len(part)] = part


def set_row(out: Any, index: int, value: Any) -> None:
    """Write one sub-environment's ``value`` into row ``index`` of ``out``."""
    if isinstance(out, dict):
        for key, column in out.items():
            set_row(column, index, value[key])
    elif isinstance(out, tuple):
        for column, piece in zip(out, value, strict=True):
            set_row(column, index, piece)
    else:
        out[index] = value
