"""Marker2D: a mounting point in the plane (Godot's Marker2D, Blueprints' Placeholder).

Markers are how a reusable piece says where things go on it; :meth:`Marker2D.attach` puts a
copy of a node there, and :attr:`rlenv.node.Node.placeholders` finds the markers below any
node::

    table = StaticBody(name="Table")
    for x in (-0.9, 0.9):
        table.add_child(Marker2D("leg", position=(x, -0.4), rotation=math.pi))
    table.add_child(Marker2D("plate", position=(0.7, 0.0)))
    legs = table.placeholders.named("leg*").attach(leg)     # a View of the two new legs
    table.placeholders["plate*"].attach(bowl)
"""

from __future__ import annotations

from typing import TypeVar

from rlenv.node import Node
from rlenv.scene2d.node2d import Node2D, Vec

__all__ = ["Marker2D"]

N = TypeVar("N", bound=Node)


class Marker2D(Node2D):
    """A named point with a rotation where copies of nodes are mounted.

    Args:
        name: the node name (siblings of the same name become ``leg``, ``leg2``, ...).
        position: position in the frame of the nearest Node2D ancestor.
        rotation: rotation in radians, relative to that frame; what is attached turns with it.
    """

    def __init__(
        self, name: str | None = None, *, position: Vec = (0.0, 0.0), rotation: float = 0.0
    ) -> None:
        super().__init__(name, position=position, rotation=rotation)

    def attach(self, node: N) -> N:
        """Add a :meth:`~rlenv.node.Node.duplicate` of ``node`` under this marker; return it.

        The copy keeps its own position and rotation, now relative to the marker: a node at
        the origin sits on the marker. ``node`` itself is left as it is (a template).
        """
        copy = node.duplicate()
        self.add_child(copy)
        return copy
