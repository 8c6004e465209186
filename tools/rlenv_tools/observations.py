"""Comparing observations of any space, member by member: what the checks compare them with.

An observation of a ``Dict`` space is a map, of a ``Tuple`` space a tuple; their members may
be arrays, numbers, text or nested maps and tuples again. ``==`` on two such values raises
(numpy's "truth value of an array ... is ambiguous") or compares the wrong thing, so every
check of ``rlenv check`` and of the compliance suite compares them with
:func:`observation_difference`: maps by their keys then each member, tuples and lists member
by member, arrays by shape, dtype and bits (a NaN equals the same NaN; -0.0 differs from 0.0,
as in a bit-for-bit replay).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["observation_difference"]


def observation_difference(expected: Any, got: Any, where: str = "") -> str | None:
    """Where two observations first differ, in words; ``None`` if they are the same.

    Args:
        expected: one observation (of any space: maps and tuples are compared member by
            member).
        got: the other.
        where: the path of these values inside a larger observation (``"['Red'][0]"``),
            the start of the answer.

    Returns:
        ``None``, or the path of the first member that differs and how (``"['Blue']: [0.5
        0.1] != [0.5 0.2]"``).
    """
    here = where or "the observation"
    if isinstance(expected, dict) or isinstance(got, dict):
        if not (isinstance(expected, dict) and isinstance(got, dict)):
            return f"{here}: a {type(expected).__name__} against a {type(got).__name__}"
        if expected.keys() != got.keys():
            return f"{here}: keys {sorted(map(str, expected))} != {sorted(map(str, got))}"
        members = [(expected[key], got[key], f"{where}[{key!r}]") for key in expected]
    elif _is_sequence(expected) or _is_sequence(got):
        if not (_is_sequence(expected) and _is_sequence(got)) or len(expected) != len(got):
            return f"{here}: {_short(expected)} != {_short(got)}"
        members = [
            (one, other, f"{where}[{index}]")
            for index, (one, other) in enumerate(zip(expected, got, strict=True))
        ]
    else:
        one, other = np.asarray(expected), np.asarray(got)
        if one.shape != other.shape or one.dtype != other.dtype or not _same_values(one, other):
            return f"{here}: {_short(expected)} != {_short(got)}"
        return None
    for one, other, inside in members:
        difference = observation_difference(one, other, inside)
        if difference is not None:
            return difference
    return None


def _is_sequence(value: Any) -> bool:
    """A tuple or list that holds more than numbers (a ``Tuple`` observation, say)."""
    return isinstance(value, tuple | list) and not all(np.isscalar(item) for item in value)


def _same_values(one: np.ndarray, other: np.ndarray) -> bool:
    """Equal arrays of one shape and dtype: numbers bit for bit, other values by ``==``."""
    if one.dtype.kind in "biufcmM":
        return one.tobytes() == other.tobytes()
    return bool(np.array_equal(one, other))


def _short(value: Any) -> str:
    """``value`` for a message, at most 80 characters."""
    text = np.array2string(value, threshold=8) if isinstance(value, np.ndarray) else repr(value)
    return text if len(text) <= 80 else text[:77] + "..."
