"""Properties that clients may read and set: which a node has, and what value may replace one.

A node class lists what a client may read and set in ``exported`` (as Godot's ``@export``) and
what a client may configure in ``configurable`` (RL nodes). A value sent by a client replaces the
current one only if it is of the same sort (:func:`conform`): nothing else, and never code, is
accepted. Configuration (:class:`~rlenv.rl_node.RLNode`) and the remote inspector
(:mod:`rlenv.serving._inspector`) share these rules.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from rlenv.node import Node
from rlenv.protocol.spaces import find_non_finite

__all__ = ["conform", "declared_of", "exported_of", "exported_values", "to_wire"]


def exported_of(node: Node) -> tuple[str, ...]:
    """The properties ``node`` exports: its class's ``exported`` and ``configurable``."""
    node_class: type = type(node)  # as a plain type: mypy finds type[Node] unhashable
    return tuple(name for name in declared_of(node_class) if hasattr(node, name))


def exported_values(node: Node) -> dict[str, Any]:
    """What ``node`` exports, each value as plain data (:func:`to_wire`), in one read each."""
    values = {}
    node_class: type = type(node)  # as a plain type: mypy finds type[Node] unhashable
    for name in declared_of(node_class):
        try:
            values[name] = to_wire(getattr(node, name))
        except AttributeError:  # not there (as exported_of leaves it out)
            continue
    return values


@functools.cache
def declared_of(node_class: type) -> tuple[str, ...]:
    """The names a node class lists in ``exported`` and ``configurable``, each once."""
    names = (*getattr(node_class, "exported", ()), *getattr(node_class, "configurable", ()))
    return tuple(dict.fromkeys(names))


def conform(current: Any, value: Any) -> Any:
    """``value``, made like ``current``, to replace it.

    A bool takes a bool; an int an int; a float any number (as a float); a vector (a tuple,
    such as pymunk's ``Vec2d``) a list or tuple of as many numbers (as floats); ``None`` takes
    anything; anything else a value of its own type. Nothing that holds NaN or infinity is
    taken: a setting outlives the episode, and every later one would fail.

    Raises:
        TypeError: ``value`` is not like ``current``, or is not finite.
    """
    where = find_non_finite(value)
    if where is not None:
        raise TypeError(
            f"must be finite, got {value!r:.60}" + (f" (not finite at {where})" if where else "")
        )
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if isinstance(current, bool | np.bool_):
        if isinstance(value, bool):
            return value
    elif isinstance(current, float | np.floating):
        if number:
            return float(value)
    elif isinstance(current, int | np.integer):
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif isinstance(current, tuple):
        if (
            isinstance(value, list | tuple)
            and len(value) == len(current)
            and all(isinstance(item, int | float) and not isinstance(item, bool) for item in value)
        ):
            return tuple(float(item) for item in value)
    elif current is None or isinstance(value, type(current)):
        return value
    raise TypeError(f"must be {_sort_of(current)} like {to_wire(current)!r:.40}, got {value!r:.60}")


def _sort_of(value: Any) -> str:
    if isinstance(value, bool | np.bool_):
        return "a bool"
    if isinstance(value, float | np.floating):
        return "a float"
    if isinstance(value, int | np.integer):
        return "an int"
    if isinstance(value, tuple):
        return f"a list of {len(value)} numbers"
    return f"a {type(value).__name__}"


def to_wire(value: Any) -> Any:
    """A property's value as plain data (vectors as lists, numpy scalars as numbers)."""
    if isinstance(value, tuple):  # pymunk Vec2d is a tuple
        return [to_wire(item) for item in value]
    if isinstance(value, np.generic):
        return value.item()
    return value
