"""Remote introspection: the node tree and exported properties, as data (Godot's remote inspector).

Every node class lists the properties a client may read and set in ``exported`` (as Godot's
``@export``): physics bodies their position and velocities, shapes their friction, RL nodes what
they let clients configure. A request's ``inspect`` part asks for one of::

    {"tree": {}}                                       every node: path, type, exported values
    {"get": {"path": "/root/CartPole/World/...", "property": "angle"}}
    {"set": {"path": ..., "property": ..., "value": ...}}

Paths are absolute or relative to the environment. A value is set only if it has the type of the
current one (an int may set a float; a vector takes a list of two numbers); nothing else, and
never code, is accepted.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from rlenv.errors import ErrorCode, RequestError
from rlenv.node import Node

__all__ = ["check_inspect", "exported_of", "get_property", "node_at", "set_property", "tree"]

_OPERATIONS = frozenset({"tree", "get", "set"})


def exported_of(node: Node) -> tuple[str, ...]:
    """The properties ``node`` exports.

    They are its class's ``exported``, and what it lets clients configure (``configurable``).
    """
    names = (*getattr(type(node), "exported", ()), *getattr(type(node), "configurable", ()))
    return tuple(name for name in dict.fromkeys(names) if hasattr(node, name))


def tree(root: Node) -> list[dict[str, Any]]:
    """Every node at or below ``root``, in tree order, with its exported values."""
    return [{"path": node.get_path(), "type": type(node).__name__,
             "exported": {name: _to_wire(getattr(node, name)) for name in exported_of(node)}}
            for node in root.iter_subtree()]


def node_at(root: Node, path: Any) -> Node:
    """The node at ``path`` (absolute, or relative to ``root``).

    Raises:
        RequestError: ``bad_request`` when there is no such node.
    """
    if not isinstance(path, str) or not path:
        raise RequestError(ErrorCode.BAD_REQUEST, "inspect: 'path' must be a node path")
    node = root.get_node_or_null(path)
    if node is None:
        raise RequestError(ErrorCode.BAD_REQUEST, f"inspect: no node at path {path!r}")
    return node


def _exported(node: Node, name: Any) -> str:
    names = exported_of(node)
    if name not in names:
        raise RequestError(
            ErrorCode.BAD_REQUEST,
            f"inspect: {type(node).__name__} at {node.get_path()} exports no {name!r}; it "
            f"exports {', '.join(names) or 'nothing'}",
        )
    return str(name)


def get_property(root: Node, path: Any, name: Any) -> Any:
    """The exported property ``name`` of the node at ``path``, as wire data."""
    node = node_at(root, path)
    return _to_wire(getattr(node, _exported(node, name)))


def set_property(root: Node, path: Any, name: Any, value: Any, *, dry_run: bool = False) -> None:
    """Set the exported property ``name`` of the node at ``path`` to ``value`` (type-checked).

    With ``dry_run`` everything is checked and nothing is set.

    Raises:
        RequestError: ``bad_request`` naming the node, the property and the expected type.
    """
    node = node_at(root, path)
    prop = _exported(node, name)
    conformed = _conform(node, prop, getattr(node, prop), value)
    if not dry_run:
        setattr(node, prop, conformed)


def check_inspect(spec: Any) -> tuple[str, Mapping[str, Any]]:
    """Check an ``inspect`` part's shape; returns (operation, its arguments).

    Raises:
        RequestError: ``bad_request``.
    """
    if not isinstance(spec, Mapping) or len(spec) != 1 or next(iter(spec)) not in _OPERATIONS:
        raise RequestError(ErrorCode.BAD_REQUEST, "inspect must be one of {'tree': {}}, "
                           "{'get': {path, property}} or {'set': {path, property, value}}")
    operation, arguments = next(iter(spec.items()))
    keys = {"tree": set(), "get": {"path", "property"}, "set": {"path", "property", "value"}}
    if not isinstance(arguments, Mapping) or set(arguments) != keys[operation]:
        raise RequestError(ErrorCode.BAD_REQUEST, f"inspect.{operation} takes exactly "
                           f"{sorted(keys[operation]) or 'an empty map'}")
    return operation, arguments


def _to_wire(value: Any) -> Any:
    if isinstance(value, tuple):  # pymunk Vec2d is a tuple
        return [_to_wire(item) for item in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _conform(node: Node, name: str, current: Any, value: Any) -> Any:
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if isinstance(current, bool):
        if isinstance(value, bool):
            return value
    elif isinstance(current, float | np.floating):
        if number:
            return float(value)
    elif isinstance(current, int | np.integer):
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif isinstance(current, tuple):
        if isinstance(value, list | tuple) and len(value) == len(current) and all(
            isinstance(item, int | float) and not isinstance(item, bool) for item in value
        ):
            return tuple(float(item) for item in value)
    elif current is None or isinstance(value, type(current)):
        return value
    raise RequestError(ErrorCode.BAD_REQUEST, f"inspect: {type(node).__name__}.{name} must be "
                       f"like {_to_wire(current)!r:.40}, got {value!r:.40}")
