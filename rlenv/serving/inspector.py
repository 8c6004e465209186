"""Remote introspection: the node tree and exported properties, as data (Godot's remote inspector).

A request's ``inspect`` part asks for one of::

    {"tree": {}}                          every node: path, type, exported values, read-only ones
    {"get": {"path": "/root/CartPole/World/...", "property": "angle"}}
    {"set": {"path": ..., "property": ..., "value": ...}}

Paths are absolute or relative to the environment. Which properties a node exports and what
value may replace one is :mod:`rlenv.properties`' business: nothing else, and never code, is
accepted.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

from rlenv.errors import ErrorCode, RequestError
from rlenv.node import Node
from rlenv.properties import conform, exported_of, to_wire

__all__ = ["check_inspect", "get_property", "node_at", "set_property", "tree"]

_ARGUMENTS = {"tree": frozenset(), "get": frozenset({"path", "property"}),
              "set": frozenset({"path", "property", "value"})}


def check_inspect(spec: Any) -> tuple[str, Mapping[str, Any]]:
    """Check an ``inspect`` part's shape; returns (operation, its arguments).

    Raises:
        RequestError: ``bad_request``.
    """
    if not isinstance(spec, Mapping) or len(spec) != 1 or next(iter(spec)) not in _ARGUMENTS:
        raise RequestError(ErrorCode.BAD_REQUEST, "inspect must be one of {'tree': {}}, "
                           "{'get': {path, property}} or {'set': {path, property, value}}")
    operation, arguments = next(iter(spec.items()))
    expected = _ARGUMENTS[operation]
    if not isinstance(arguments, Mapping) or set(arguments) != expected:
        raise RequestError(ErrorCode.BAD_REQUEST, f"inspect.{operation} takes exactly "
                           f"{sorted(expected) or 'an empty map'}")
    return operation, arguments


def tree(root: Node) -> list[dict[str, Any]]:
    """Every node at or below ``root``, in tree order, with its exported values.

    ``read_only`` names the exported properties that ``set`` may not change.
    """
    return [{"path": node.get_path(), "type": type(node).__name__,
             "exported": {name: to_wire(getattr(node, name)) for name in exported_of(node)},
             "read_only": [name for name in exported_of(node) if _read_only(node, name)]}
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


def get_property(root: Node, path: Any, name: Any) -> Any:
    """The exported property ``name`` of the node at ``path``, as wire data."""
    node = node_at(root, path)
    return to_wire(getattr(node, _exported(node, name)))


def set_property(root: Node, path: Any, name: Any, value: Any, *,
                 dry_run: bool = False) -> tuple[Node, str, Any]:
    """Set the exported property ``name`` of the node at ``path`` to ``value`` (type-checked).

    With ``dry_run`` everything is checked and nothing is set. Returns the node, the property's
    name and the value it had before (a deep copy: a setter may change it in place).

    Raises:
        RequestError: ``bad_request`` naming the node, the property and the expected type.
    """
    node = node_at(root, path)
    prop = _exported(node, name)
    if _read_only(node, prop):
        raise RequestError(ErrorCode.BAD_REQUEST,
                           f"inspect: {type(node).__name__}.{prop} is read-only")
    try:
        conformed = conform(getattr(node, prop), value)
    except TypeError as error:
        raise RequestError(ErrorCode.BAD_REQUEST,
                           f"inspect: {type(node).__name__}.{prop} {error}") from None
    previous = getattr(node, prop)
    if not dry_run:
        previous = copy.deepcopy(previous)
        setattr(node, prop, conformed)
    return node, prop, previous


def _read_only(node: Node, name: str) -> bool:
    attribute = getattr(type(node), name, None)
    return isinstance(attribute, property) and attribute.fset is None


def _exported(node: Node, name: Any) -> str:
    names = exported_of(node)
    if name not in names:
        raise RequestError(
            ErrorCode.BAD_REQUEST,
            f"inspect: {type(node).__name__} at {node.get_path()} exports no {name!r}; it "
            f"exports {', '.join(names) or 'nothing'}",
        )
    return str(name)
