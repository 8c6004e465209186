"""Remote introspection (Godot's remote inspector): the node tree, properties, statistics.

A request's ``inspect`` part asks for one of::

    {"tree": {}}                          every node: path, type, exported values, read-only ones
    {"node": {"path": ...}}               one node, as in the tree
    {"get": {"path": "/root/CartPole/World/...", "property": "angle"}}
    {"set": {"path": ..., "property": ..., "value": ...}}      for this episode
    {"configure": {"agent": {...}, ...}}  as a ``config`` part: kept across episodes
    {"stats": {"since": n}}               episodes finished (numbered n and later), totals

None of them takes control: an observer (a person's inspector) may change the environment while
its controller trains, between two of the controller's requests (at a tick boundary); every
change is logged for snapshots like the controller's own. Paths are absolute or relative to the
environment. Which properties a node exports and what value may replace one is
:mod:`rlenv.serving._properties`' business: nothing else, and never code, is accepted.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

from rlenv.demonstration_keys import keys_of
from rlenv.environment import RLEnvironment
from rlenv.node import Node
from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.serving._properties import conform, exported_of, exported_values, to_wire

__all__ = [
    "check_inspect",
    "get_property",
    "node_at",
    "node_entry",
    "node_of",
    "set_property",
    "tree",
]

_PATH = frozenset({"path"})
_ARGUMENTS: dict[str, tuple[frozenset[str], frozenset[str]]] = {  # required, optional
    "tree": (frozenset(), frozenset()),
    "node": (_PATH, frozenset()),
    "get": (frozenset({"path", "property"}), frozenset()),
    "set": (frozenset({"path", "property", "value"}), frozenset()),
    "configure": (frozenset(), frozenset({"environment", "agent", "world"})),
    "stats": (frozenset(), frozenset({"since"})),
}
_USAGE = (
    "inspect must be one of {'tree': {}}, {'node': {path}}, {'get': {path, property}}, "
    "{'set': {path, property, value}}, {'configure': <config>} or {'stats': {since}}"
)


def check_inspect(spec: Any) -> tuple[str, Mapping[str, Any]]:
    """Check an ``inspect`` part's shape; returns (operation, its arguments).

    Raises:
        RequestError: ``bad_request``.
    """
    if not isinstance(spec, Mapping) or len(spec) != 1 or next(iter(spec)) not in _ARGUMENTS:
        raise RequestError(ErrorCode.BAD_REQUEST, _USAGE)
    operation, arguments = next(iter(spec.items()))
    required, optional = _ARGUMENTS[operation]
    if (
        not isinstance(arguments, Mapping)
        or not required <= arguments.keys() <= required | optional
    ):
        expected = sorted(required) + [f"{name} (optional)" for name in sorted(optional)]
        raise RequestError(
            ErrorCode.BAD_REQUEST, f"inspect.{operation} takes exactly {expected or 'an empty map'}"
        )
    since = arguments.get("since", 0)
    if type(since) is not int or since < 0:
        raise RequestError(
            ErrorCode.BAD_REQUEST, f"inspect.stats.since must be an integer >= 0, got {since!r:.40}"
        )
    return operation, arguments


def tree(environment: RLEnvironment) -> list[dict[str, Any]]:
    """Every node at or below ``environment``, in tree order (see :func:`node_entry`)."""
    sections = _config_sections(environment)
    return [node_entry(node, sections.get(id(node))) for node in environment.iter_subtree()]


def node_entry(node: Node, section: str | None = None) -> dict[str, Any]:
    """A node as data: path, type, exported values, the read-only ones among them.

    The nodes a ``config`` reaches (the environment, its agents, its world) also say which
    ``section`` of a config reaches them (``config``) and what it may change
    (``configurable``): a change there lasts across episodes, a ``set`` for one. Agents also
    say which keys a person acts with (``demonstration_keys``, see
    :mod:`rlenv.demonstration_keys`) and whether their class has a ``heuristic`` (2.6).
    """
    exported = exported_values(node)
    entry = {
        "path": node.get_path(),
        "type": type(node).__name__,
        "exported": exported,
        "read_only": [name for name in exported if _read_only(node, name)],
    }
    if section is not None:
        entry["config"] = section
        entry["configurable"] = list(getattr(node, "configurable", ()))
    if section == "agent":
        entry["demonstration_keys"] = keys_of(node)
        entry["heuristic"] = node.has_heuristic()  # type: ignore[attr-defined]  # an RLAgent
    return entry


def node_of(environment: RLEnvironment, path: Any) -> dict[str, Any]:
    """The entry (:func:`node_entry`) of the node at ``path``."""
    node = node_at(environment, path)
    return node_entry(node, _config_sections(environment).get(id(node)))


def _config_sections(environment: RLEnvironment) -> dict[int, str]:
    sections = {id(environment): "environment"}
    sections.update((id(agent), "agent") for agent in environment.agents)
    if environment.world is not None:
        sections[id(environment.world)] = "world"
    return sections


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


def set_property(
    root: Node, path: Any, name: Any, value: Any, *, dry_run: bool = False
) -> tuple[Node, str, Any]:
    """Set the exported property ``name`` of the node at ``path`` to ``value`` (type-checked).

    With ``dry_run`` everything is checked and nothing is set. Returns the node, the property's
    name and the value it had before (a deep copy: a setter may change it in place).

    Raises:
        RequestError: ``bad_request`` naming the node, the property and the expected type, or
            what its setter refused: a setter that raises ``ValueError`` refuses the value
            and changes nothing (rlenv's own do: a negative friction, a damping below 0).
    """
    node = node_at(root, path)
    prop = _exported(node, name)
    if _read_only(node, prop):
        raise RequestError(
            ErrorCode.BAD_REQUEST, f"inspect: {type(node).__name__}.{prop} is read-only"
        )
    try:
        conformed = conform(getattr(node, prop), value)
    except TypeError as error:
        raise RequestError(
            ErrorCode.BAD_REQUEST, f"inspect: {type(node).__name__}.{prop} {error}"
        ) from None
    previous = getattr(node, prop)
    if not dry_run:
        previous = copy.deepcopy(previous)
        try:
            setattr(node, prop, conformed)
        except ValueError as error:
            raise RequestError(
                ErrorCode.BAD_REQUEST, f"inspect: {type(node).__name__}.{prop}: {error}"
            ) from None
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
