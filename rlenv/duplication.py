"""Duplicating a subtree (:meth:`rlenv.node.Node.duplicate`): Godot's rules over Python's copy.

A duplicate is built in four passes over the subtree, in tree order:

1. an empty instance of each node's class, entered in the deep-copy ``memo`` under the
   original's ``id``, so that any reference to a node of the subtree, wherever it sits (an
   attribute, a list, a bound method), becomes a reference to its copy;
2. each node's ``_duplicate_resources(memo)``: copies of what the copy module must not copy
   (pymunk bodies, shapes and spaces), entered in the memo the same way;
3. each node's attributes, copied deeply through that memo, except those of its class's
   ``_TREE_STATE`` (its place in a tree), which start afresh: no parent for the copied root,
   children mapped to their copies, not in a tree, not ready;
4. signal connections, remapped by the same rule, then each copy's ``_duplicated(original)``.

Nodes outside the subtree are never copied: :meth:`Node.__deepcopy__` returns them as they are
while a duplicate is under way.
"""

from __future__ import annotations

import copy
import types
from collections.abc import Mapping
from enum import Enum
from typing import TYPE_CHECKING, Any, TypeVar, cast

from rlenv.signals import BoundSignal

if TYPE_CHECKING:  # node.py imports this module: it knows nodes by their methods only
    from rlenv.node import Node

__all__ = ["copied_node", "duplicate_subtree"]

N = TypeVar("N", bound="Node")

_DUPLICATING = object()
"""In a memo, it marks the deep copy as a duplicate of a subtree."""
_ATOMIC = frozenset({int, float, bool, str, bytes, complex, type(None)})


def duplicate_subtree(root: N, outside_a_tree: Mapping[str, Any]) -> N:
    """A copy of ``root`` and its subtree, outside any tree (see :meth:`Node.duplicate`).

    Args:
        root: the subtree's root.
        outside_a_tree: the tree state of a node that never entered a tree, by attribute.

    Raises:
        ValueError: ``root`` was freed.
    """
    if root._freed:
        raise ValueError(f"cannot duplicate {root._name!r}: it was freed")
    originals = list(root.iter_subtree())
    memo: dict[int, Any] = {id(_DUPLICATING): _DUPLICATING}
    copies = [object.__new__(type(node)) for node in originals]
    for node, blank in zip(originals, copies, strict=True):
        memo[id(node)] = blank
    for node in originals:
        node._duplicate_resources(memo)
    for node, blank in zip(originals, copies, strict=True):
        _copy_state(node, blank, memo, outside_a_tree)
    copies[0]._parent = None
    for node, blank in zip(originals, copies, strict=True):
        if node._signals:
            blank._signals = {
                name: _copied_signal(bound, blank, memo) for name, bound in node._signals.items()
            }
    for node, blank in zip(originals, copies, strict=True):
        blank._duplicated(node)
    return cast(N, copies[0])  # a blank of type(root)


def copied_node(node: Node, memo: dict[int, Any]) -> Node:
    """What ``copy.deepcopy`` makes of ``node``: itself inside a duplicate, else its duplicate.

    Inside a duplicate, a node that reaches this is outside the duplicated subtree (the
    subtree's nodes are in the memo already), so it is kept, not copied.
    """
    if id(_DUPLICATING) in memo:
        return node
    return node.duplicate()


def _copy_state(
    node: Node, blank: Node, memo: dict[int, Any], outside_a_tree: Mapping[str, Any]
) -> None:
    kind = type(node)
    skipped = _SKIPPED.get(kind)
    if skipped is None:
        skipped = _SKIPPED[kind] = kind._TREE_STATE | {"_groups"}
    state = blank.__dict__
    mapped = memo.get
    for key, value in node.__dict__.items():
        if key in skipped:
            continue
        if value.__class__ in _ATOMIC:
            state[key] = value
            continue
        found = mapped(id(value))  # a node or a resource of the subtree: its copy
        if found is not None:
            state[key] = found
        else:
            state[key] = value if _immutable(value) else copy.deepcopy(value, memo)
    state["_groups"] = set(node._groups)
    state["_parent"] = mapped(id(node._parent))
    state["_children"] = [memo[id(child)] for child in node._children]
    state["_children_by_name"] = {
        name: memo[id(child)] for name, child in node._children_by_name.items()
    }
    state["_signals"] = {}
    state.update(outside_a_tree)


_SKIPPED: dict[type, frozenset[str]] = {}
"""Per class: the attributes a copy does not take from its original."""


def _immutable(value: Any) -> bool:
    """Whether ``value`` can be shared by the copy as it is (and copying it would cost)."""
    if isinstance(value, Enum):
        return True
    return isinstance(value, tuple) and all(item.__class__ in _ATOMIC for item in value)


def _copied_signal(bound: BoundSignal, owner: Node, memo: dict[int, Any]) -> BoundSignal:
    signal = BoundSignal(owner, bound.name)
    signal._connections = tuple(
        (_remapped(callback, memo), one_shot) for callback, one_shot in bound._connections
    )
    signal._one_shots = bound._one_shots
    return signal


def _remapped(callback: Any, memo: dict[int, Any]) -> Any:
    """A method of an object that was copied, bound to the copy; anything else as it is."""
    if isinstance(callback, types.MethodType):
        target = memo.get(id(callback.__self__))
        if target is not None and target is not callback.__self__:
            return types.MethodType(callback.__func__, target)
    return callback
