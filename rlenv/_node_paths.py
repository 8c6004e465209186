"""Node names and the paths made of them (Godot's NodePath), for :class:`rlenv.node.Node`.

A path is names joined by ``/``: relative to a node (``World/Cart``, ``../Agent``, ``.``) or
absolute, from the tree's root (``/root/CartPole/World``). A name therefore may not contain the
characters that paths give a meaning to (``/ : @ % . "``, as in Godot), nor be ``.`` or ``..``;
among siblings it is made unique with a number (``Name``, ``Name2``, ``Name3`` ...).

These functions follow a node's structure (its name, parent, children and tree) and change
nothing: the node's methods (``get_node``, ``get_path_to``, ``add_child``, its name's setter)
call them.
"""

from __future__ import annotations

from collections.abc import Container
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # node.py imports this module
    from rlenv.node import Node

__all__ = ["ancestry", "check_name", "relative_path", "unique_name", "walk"]

_INVALID_NAME_CHARACTERS = frozenset('/:@%."')


def check_name(name: object) -> str:
    """``name``, if it may name a node.

    Raises:
        ValueError: ``name`` is not a non-empty string, is ``.`` or ``..``, or contains one of
            ``/ : @ % . "`` (the message names them).
    """
    if not isinstance(name, str) or not name or name in (".", ".."):
        raise ValueError(f"invalid node name {name!r}")
    bad = _INVALID_NAME_CHARACTERS.intersection(name)
    if bad:
        raise ValueError(f"node name {name!r} contains {''.join(sorted(bad))!r}")
    return name


def unique_name(name: str, taken: Container[str]) -> str:
    """``name``, or ``name`` numbered so that it is none of ``taken`` (``Name2``, ``Name3`` ...).

    A number that ends the name counts on: ``Leg2`` becomes ``Leg3``.
    """
    if name not in taken:
        return name
    stem = name.rstrip("0123456789") or name
    number = int(name[len(stem) :] or 1) + 1
    while f"{stem}{number}" in taken:
        number += 1
    return f"{stem}{number}"


def ancestry(node: Node) -> list[Node]:
    """The nodes from the top of ``node``'s structure (the root, in a tree) down to ``node``."""
    chain = []
    step: Node | None = node
    while step is not None:
        chain.append(step)
        step = step._parent
    return chain[::-1]


def relative_path(source: Node, target: Node) -> str:
    """The relative path from ``source`` to ``target`` (see :meth:`Node.get_path_to`).

    Raises:
        ValueError: the two nodes are not in the same structure.
    """
    mine = ancestry(source)
    theirs = ancestry(target)
    common = 0
    while common < min(len(mine), len(theirs)) and mine[common] is theirs[common]:
        common += 1
    if common == 0:
        raise ValueError(f"{source._name!r} and {target._name!r} are not in the same tree")
    ups = [".."] * (len(mine) - common)
    downs = [n._name for n in theirs[common:]]
    return "/".join(ups + downs) or "."


def walk(start: Node, path: str) -> tuple[Node | None, Node, str]:
    """Follow ``path`` from ``start`` (see :meth:`Node.get_node`).

    Returns:
        The node at ``path`` or None, the last node reached, and the step missing from there.
    """
    if not path:
        return None, start, ""
    node: Node = start
    names = path.split("/")
    if path.startswith("/"):
        if start._tree is None:
            return None, start, "/ (it is not inside a tree)"
        root = start._tree.root
        if names[1] != root._name:
            return None, root, names[1]
        node, names = root, names[2:]
    for part in names:
        if part in ("", "."):
            continue
        step = node._parent if part == ".." else node._children_by_name.get(part)
        if step is None:
            return None, node, part
        node = step
    return node, node, ""
