"""What bodies, shapes and joints know of the world whose space they join: a node owning one.

:class:`~rlenv.scene2d.physics.world.PhysicsWorld` is the one rlenv has; the nodes that join a
space find the nearest owner above them (:func:`world_of`) and know it through this base alone,
so that the world may know them without a circle of imports.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pymunk

from rlenv.node import Node

if TYPE_CHECKING:
    from rlenv.scene2d.physics.collision_shape import CollisionShape

__all__ = ["SpaceOwner", "Vec", "world_of"]

Vec = tuple[float, float]
"""A point or vector: any pair of numbers."""


class SpaceOwner(Node):
    """A node that owns a ``pymunk.Space`` for the physics nodes below it.

    Attributes:
        space: the space.
    """

    space: pymunk.Space
    _shape_nodes: dict[pymunk.Shape, CollisionShape]  # each shape in the space, by its node


def world_of(node: Node) -> SpaceOwner:
    """The nearest space owner above ``node``.

    Raises:
        RuntimeError: there is none.
    """
    ancestor = node.parent
    while ancestor is not None:
        if isinstance(ancestor, SpaceOwner):
            return ancestor
        ancestor = ancestor.parent
    raise RuntimeError(f"{node!r} must be placed below a PhysicsWorld")
