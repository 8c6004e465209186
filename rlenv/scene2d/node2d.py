"""Node2D: a node with a position and a rotation in the plane, relative to the Node2D above it.

As in Godot, a Node2D's :attr:`~Node2D.position` and :attr:`~Node2D.rotation` are *local*: in
the frame of its nearest Node2D ancestor (or of the world when it has none), so moving a frame
moves what is built in it::

    table = Node2D("Table", position=(10.0, 0.0), rotation=math.pi / 2)
    leg = Marker2D("Leg", position=(1.0, 0.0))
    table.add_child(leg)
    leg.global_position                     # Vec2d(10.0, 1.0)
    table.to_local((10.0, 1.0))             # Vec2d(1.0, 0.0)

Physics bodies are Node2Ds too (:mod:`rlenv.scene2d.physics`): they enter their space at the
pose composed from their ancestors, and from then on the simulation moves them, their
``position`` reading back relative to the frame above. Setting the pose of a Node2D inside a
tree carries every body below it along (teleported, their velocities kept); between such moves
the simulation moves bodies on their own, and a Node2D below a body follows the body.

:meth:`Node2D.lattice` fills a regular pattern with copies of a node (Blueprints' ``lattice``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, ClassVar

from pymunk import Vec2d

from rlenv.node import Node, ProcessMode
from rlenv.scene2d.lattice import lattice

if TYPE_CHECKING:
    from rlenv.views import View

__all__ = ["Node2D", "Pose", "Vec", "frame_of"]

Vec = tuple[float, float] | Sequence[float]
Pose = tuple[float, float, float]
"""A placement in the plane: (x, y, angle in radians)."""


class Node2D(Node):
    """A node placed in the plane, relative to its nearest Node2D ancestor (Godot's Node2D).

    Args:
        name: the node name (defaults to the class name).
        position: position in the frame of the nearest Node2D ancestor.
        rotation: rotation in radians (counter-clockwise), relative to that frame.
        process_mode: when the node processes; see :class:`~rlenv.node.ProcessMode`.
    """

    exported: ClassVar[tuple[str, ...]] = ("position", "rotation")

    def __init__(
        self,
        name: str | None = None,
        *,
        position: Vec = (0.0, 0.0),
        rotation: float = 0.0,
        process_mode: ProcessMode = ProcessMode.INHERIT,
    ) -> None:
        super().__init__(name, process_mode=process_mode)
        self._position = _vector(position, "position")
        self._rotation = _angle(rotation, "rotation")

    # --- local pose ---------------------------------------------------------------------------

    @property
    def position(self) -> Vec2d:
        """The position in the frame of the nearest Node2D ancestor."""
        return self._position

    @position.setter
    def position(self, value: Vec) -> None:
        x, y = _vector(value, "position")
        self._move(x, y, self.rotation)

    @property
    def rotation(self) -> float:
        """The rotation in radians, relative to the frame of the nearest Node2D ancestor."""
        return self._rotation

    @rotation.setter
    def rotation(self, value: float) -> None:
        x, y = self.position
        self._move(x, y, _angle(value, "rotation"))

    # --- global pose --------------------------------------------------------------------------

    @property
    def global_position(self) -> Vec2d:
        """The position in the world."""
        x, y, _ = self._global_pose()
        return Vec2d(x, y)

    @global_position.setter
    def global_position(self, value: Vec) -> None:
        x, y = _vector(value, "global_position")
        self.position = self._to_parent_frame(x, y)

    @property
    def global_rotation(self) -> float:
        """The rotation in the world, in radians."""
        return self._global_pose()[2]

    @global_rotation.setter
    def global_rotation(self, value: float) -> None:
        frame = frame_of(self)
        parent_angle = frame._global_pose()[2] if frame is not None else 0.0
        self.rotation = _angle(value, "global_rotation") - parent_angle

    def to_global(self, point: Vec) -> Vec2d:
        """``point``, given in this node's frame, in the world's."""
        x, y = _vector(point, "point")
        return Vec2d(*apply(self._global_pose(), x, y))

    def to_local(self, point: Vec) -> Vec2d:
        """``point``, given in the world's frame, in this node's."""
        x, y = _vector(point, "point")
        return Vec2d(*unapply(self._global_pose(), x, y))

    # --- building -----------------------------------------------------------------------------

    def lattice(self, offsets: Any, counts: int | Sequence[int]) -> View:
        """Copies of this node along a regular pattern, beside it under the same parent.

        Blueprints' ``lattice``: ``domino.lattice((0.4, 0.0), 20)`` makes a row of 20 dominos,
        ``peg.lattice([(1.0, 0.0), (0.0, -1.0)], (4, 3))`` a 4 x 3 grid. The node at index
        ``(i, j, ...)`` is at ``position + i * offsets[0] + j * offsets[1] + ...``, with this
        node's rotation; every copy is a :meth:`~rlenv.node.Node.duplicate`, so a body copy
        gets its own pymunk body and shapes, and is built where it is placed
        (:meth:`~rlenv.scene2d.physics.PhysicsWorld.restart` puts it back there).

        Args:
            offsets: one vector ``(dx, dy)``, or one vector per dimension, in the parent's
                frame (the frame :attr:`position` is in).
            counts: how many nodes along each dimension: an int, or one per dimension.

        Returns:
            A View of all ``prod(counts)`` nodes, this one first, in lattice order (the last
            dimension varies fastest), which is also their order among their siblings.

        Raises:
            ValueError: offsets and counts do not match, a count is below 1, or the node has no
                parent to put the copies under.
        """
        return lattice(self, offsets, counts)

    # --- internals ----------------------------------------------------------------------------

    def _global_pose(self) -> Pose:
        """(x, y, angle) in the world."""
        x, y = self._position
        frame = frame_of(self)
        if frame is None:
            return (x, y, self._rotation)
        return compose(frame._global_pose(), x, y, self._rotation)

    def _store_pose(self, x: float, y: float, rotation: float) -> None:
        """Keep the local pose (bodies in a space place their pymunk body instead)."""
        self._position = Vec2d(x, y)
        self._rotation = rotation

    def _move(self, x: float, y: float, rotation: float) -> None:
        """Set the local pose; inside a tree, the bodies below follow (as Godot moves them)."""
        carried = self._bodies_below() if self._tree is not None else ()
        if not carried:
            self._store_pose(x, y, rotation)
            return
        before = self._global_pose()
        relative = [(body, relative_pose(before, body._global_pose())) for body in carried]
        self._store_pose(x, y, rotation)
        after = self._global_pose()
        for body, (rx, ry, angle) in relative:
            body._place(compose(after, rx, ry, angle))

    def _bodies_below(self) -> list[Any]:
        """The nodes below this one simulated in a space (they do not follow a frame alone)."""
        return [
            node
            for node in self.iter_subtree()
            if node is not self and getattr(node, "_in_space", False)
        ]

    def _to_parent_frame(self, x: float, y: float) -> tuple[float, float]:
        frame = frame_of(self)
        return (x, y) if frame is None else unapply(frame._global_pose(), x, y)


def frame_of(node: Node) -> Node2D | None:
    """The nearest Node2D ancestor of ``node``: the frame its pose is in (``None``: the world)."""
    ancestor = node.parent
    while ancestor is not None:
        if isinstance(ancestor, Node2D):
            return ancestor
        ancestor = ancestor.parent
    return None


def apply(pose: Pose, x: float, y: float) -> tuple[float, float]:
    """The point (x, y) of the frame ``pose``, in the frame ``pose`` is given in."""
    px, py, angle = pose
    if angle == 0.0:  # exact for frames that are not turned
        return (px + x, py + y)
    cos, sin = math.cos(angle), math.sin(angle)
    return (px + cos * x - sin * y, py + sin * x + cos * y)


def unapply(pose: Pose, x: float, y: float) -> tuple[float, float]:
    """The inverse of :func:`apply`: the point (x, y) in the frame ``pose``."""
    px, py, angle = pose
    dx, dy = x - px, y - py
    if angle == 0.0:
        return (dx, dy)
    cos, sin = math.cos(angle), math.sin(angle)
    return (cos * dx + sin * dy, -sin * dx + cos * dy)


def compose(pose: Pose, x: float, y: float, angle: float) -> Pose:
    """The pose (x, y, angle), given in the frame ``pose``, in the frame ``pose`` is given in."""
    gx, gy = apply(pose, x, y)
    return (gx, gy, pose[2] + angle)


def relative_pose(frame: Pose, pose: Pose) -> Pose:
    """``pose`` (in the world) in the frame ``frame`` (also in the world)."""
    x, y = unapply(frame, pose[0], pose[1])
    return (x, y, pose[2] - frame[2])


def _vector(value: Any, what: str) -> Vec2d:
    try:
        x, y = value
        return Vec2d(float(x), float(y))
    except (TypeError, ValueError):
        raise TypeError(f"{what} must be two numbers (x, y), got {value!r:.60}") from None


def _angle(value: Any, what: str) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{what} must be a number (radians), got {value!r:.60}") from None
