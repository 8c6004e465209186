"""Lattices: copies of a node along a regular pattern (:meth:`Node2D.lattice`, Blueprints')."""

from __future__ import annotations

import itertools
import math
import operator
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from rlenv.views import View

if TYPE_CHECKING:  # node2d.py imports this module
    from rlenv.node import Node
    from rlenv.scene2d.node2d import Node2D

__all__ = ["lattice"]

MAX_NODES = 1_000_000


def lattice(node: Node2D, offsets: Any, counts: int | Sequence[int]) -> View:
    """Copies of ``node`` beside it; see :meth:`Node2D.lattice`.

    Raises:
        ValueError: offsets and counts do not match, a count is below 1, or ``node`` has no
            parent.
    """
    parent = node.parent
    if parent is None:
        raise ValueError(
            f"{node.name!r} has no parent: a lattice puts its copies beside it, "
            "under the same parent; add it to one first"
        )
    vectors = _vectors(offsets)
    sizes = _sizes(counts, len(vectors))
    total = math.prod(sizes)
    if total > MAX_NODES:
        raise ValueError(f"a lattice of {total:,} nodes is more than {MAX_NODES:,}")
    x0, y0 = node.position
    index = node.get_index()
    last = parent._children[-1] is node  # then appending keeps the lattice order
    names = _free_names(node.name, parent, total - 1)
    nodes: list[Node] = [node]
    cells = itertools.product(*(range(size) for size in sizes))
    next(cells)  # (0, 0, ...): the node itself
    for number, cell in enumerate(cells, start=1):
        copy = node.duplicate()
        copy.position = (
            x0 + sum(i * dx for i, (dx, _) in zip(cell, vectors, strict=True)),
            y0 + sum(i * dy for i, (_, dy) in zip(cell, vectors, strict=True)),
        )
        copy._name = names[number - 1]
        parent.add_child(copy)
        if not last:
            parent.move_child(copy, index + number)  # so that tree order is lattice order
        nodes.append(copy)
    return View(nodes, f"{node.name}.lattice")


def _vectors(offsets: Any) -> list[tuple[float, float]]:
    try:
        array = np.asarray(offsets, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(
            f"offsets must be a vector (dx, dy) or one vector per dimension, got {offsets!r:.60}"
        ) from None
    if array.shape == (2,):
        array = array[np.newaxis]
    if array.ndim != 2 or array.shape[1] != 2 or array.shape[0] == 0:
        raise ValueError(
            f"offsets must be a vector (dx, dy) or one vector per dimension, got "
            f"an array of shape {array.shape}"
        )
    if not np.isfinite(array).all():
        raise ValueError("offsets must be finite")
    return [(float(dx), float(dy)) for dx, dy in array]


def _sizes(counts: int | Sequence[int], dimensions: int) -> tuple[int, ...]:
    try:
        sizes = (
            (operator.index(counts),)
            if not isinstance(counts, Sequence)
            else tuple(operator.index(count) for count in counts)
        )
    except TypeError:
        raise ValueError(
            f"counts must be an int or one int per dimension, got {counts!r:.60}"
        ) from None
    if len(sizes) != dimensions:
        raise ValueError(
            f"{len(sizes)} counts for {dimensions} offset vectors: give one count per vector"
        )
    if min(sizes) < 1:
        raise ValueError(f"every count must be at least 1, got {sizes}")
    return sizes


def _free_names(name: str, parent: Node, count: int) -> list[str]:
    """``count`` names ``Stem2``, ``Stem3``... not taken under ``parent`` (in one pass)."""
    stem = name.rstrip("0123456789") or name
    number = int(name[len(stem) :] or 1)
    taken = parent._children_by_name
    names: list[str] = []
    while len(names) < count:
        number += 1
        candidate = f"{stem}{number}"
        if candidate not in taken:
            names.append(candidate)
    return names
