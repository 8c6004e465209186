"""RaycastSensor2D: rays cast from a point of the scene, the distances to what they hit.

Godot RL Agents' ``RaycastSensor2D`` and ML-Agents' ``RayPerceptionSensor2D``, on pymunk's
segment queries. The sensor is a :class:`~rlenv.scene2d.node2d.Node2D`: put it below the body
that carries it (it turns with it) and read :meth:`RaycastSensor2D.distances` in ``get_data``::

    body.add_child(RaycastSensor2D(n_rays=16, ray_length=6.0, name="Eyes"))
    ...
    def get_data(self, observation_request):
        return self.eyes.distances() / self.eyes.ray_length   # 1 where nothing is in reach

A query changes nothing in the space, so reading a sensor keeps episodes exact.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pymunk

from rlenv.node import Node
from rlenv.scene2d._pymunk_data import integer, number
from rlenv.scene2d.node2d import Node2D, Vec
from rlenv.scene2d.physics._space_owner import world_of
from rlenv.scene2d.physics.body import PhysicsBody
from rlenv.scene2d.physics.collision_shape import CollisionShape

__all__ = ["ALL_LAYERS", "MAX_RAYS", "RaycastSensor2D", "check_settings"]

ALL_LAYERS = pymunk.ShapeFilter.ALL_MASKS()
"""A collision mask that sees every shape (pymunk's ``ShapeFilter.ALL_MASKS()``)."""

MAX_RAYS = 1024
"""The most rays one sensor casts (level data may hold sensors: a bound on what it costs)."""


class RaycastSensor2D(Node2D):
    """``n_rays`` rays of ``ray_length`` metres, spread over ``cone_width`` radians.

    The rays start at the sensor's global position. Their directions are relative to its global
    rotation (0: along its +x): a cone narrower than a full turn spreads them evenly from
    ``-cone_width / 2`` to ``+cone_width / 2`` (one ray looks straight ahead); a full turn
    (``cone_width`` of ``2 * pi`` or more) puts them ``2 * pi / n_rays`` apart, the first
    straight ahead.

    Args:
        n_rays: how many rays, 1 to :data:`MAX_RAYS`.
        ray_length: how far each ray reaches, in metres (> 0).
        cone_width: the angle the rays span, in radians (Godot RL Agents takes degrees).
        collision_mask: the collision layers the rays see: a shape is seen when its
            ``filter.categories`` share a bit with this mask (Godot's ``collision_mask``).
        collide_with_sensors: whether sensor shapes stop a ray (Godot's
            ``collide_with_areas``: rlenv's areas are sensor shapes); by default they do not.
        exclude_parent: leave out the shapes of the body the sensor is mounted on (the nearest
            body above it), as Godot's ``RayCast2D.exclude_parent``.
        name: the node name.
        position: position in the frame of the nearest Node2D ancestor.
        rotation: rotation in radians, relative to that frame.

    Attributes:
        n_rays: how many rays.
        ray_length: their length, in metres.
        cone_width: the angle they span, in radians.
        collision_mask: the layers they see.
        collide_with_sensors: whether sensors stop them.
        exclude_parent: whether the body the sensor is mounted on is left out.
    """

    def __init__(
        self,
        name: str | None = None,
        *,
        n_rays: int = 16,
        ray_length: float = 5.0,
        cone_width: float = math.tau,
        collision_mask: int = ALL_LAYERS,
        collide_with_sensors: bool = False,
        exclude_parent: bool = True,
        position: Vec = (0.0, 0.0),
        rotation: float = 0.0,
    ) -> None:
        super().__init__(name, position=position, rotation=rotation)
        settings = check_settings(
            {
                "n_rays": n_rays,
                "ray_length": ray_length,
                "cone_width": cone_width,
                "collision_mask": collision_mask,
                "collide_with_sensors": collide_with_sensors,
                "exclude_parent": exclude_parent,
            },
            f"{self!r}: ",
        )
        self.n_rays: int = settings["n_rays"]
        self.ray_length: float = settings["ray_length"]
        self.cone_width: float = settings["cone_width"]
        self.collision_mask: int = settings["collision_mask"]
        self.collide_with_sensors: bool = settings["collide_with_sensors"]
        self.exclude_parent: bool = settings["exclude_parent"]
        self._hits: list[CollisionShape | None] = [None] * self.n_rays

    def angles(self) -> np.ndarray:
        """Each ray's direction in radians, relative to the sensor's rotation."""
        n, width = self.n_rays, self.cone_width
        if width >= math.tau:
            return np.arange(n) * (math.tau / n)
        if n == 1:
            return np.zeros(1)
        return np.linspace(-width / 2.0, width / 2.0, n)

    def distances(self) -> np.ndarray:
        """Cast the rays now: a float32 array of ``n_rays`` distances in metres.

        A ray stops at the first shape it sees (sensors only with
        :attr:`collide_with_sensors`); one that reaches nothing reads ``ray_length``. What each
        ray stopped at is then in :meth:`hits`.

        Raises:
            RuntimeError: the sensor is not below a PhysicsWorld.
        """
        length, sensors = self.ray_length, self.collide_with_sensors
        distances = np.full(self.n_rays, length, dtype=np.float32)
        hits: list[CollisionShape | None] = [None] * self.n_rays
        for index, crossed in enumerate(self._crossings()):
            stop = next(
                ((alpha, node) for alpha, shape, node in crossed if sensors or not shape.sensor),
                None,
            )
            if stop is not None:
                distances[index] = stop[0] * length
                hits[index] = stop[1]
        self._hits = hits
        return distances

    def hits(self) -> list[CollisionShape | None]:
        """What each ray stopped at in the last :meth:`distances`: its node, or ``None``."""
        return list(self._hits)

    def cast(self) -> list[list[tuple[float, CollisionShape]]]:
        """Everything each ray crosses, nearest first: ``(distance in metres, shape node)``.

        Sensors are included whatever :attr:`collide_with_sensors` says (nothing stops a ray
        here): a maze's agent can tell how far the nearest wall is along a ray, and whether it
        sees the goal before it.

        Raises:
            RuntimeError: the sensor is not below a PhysicsWorld.
        """
        length = self.ray_length
        return [
            [(alpha * length, node) for alpha, _, node in crossed] for crossed in self._crossings()
        ]

    def _crossings(self) -> list[list[tuple[float, pymunk.Shape, CollisionShape]]]:
        """Each ray's crossings, nearest first: (fraction of the ray, shape, its node)."""
        world = world_of(self)
        space, shape_nodes = world.space, world._shape_nodes
        origin = self.global_position
        origin_x, origin_y = origin
        rotation, length = self.global_rotation, self.ray_length
        excluded = self._excluded()
        query_filter = pymunk.ShapeFilter(mask=self.collision_mask)
        rays = []
        for angle in self.angles():
            direction = rotation + float(angle)
            end = (origin_x + math.cos(direction) * length, origin_y + math.sin(direction) * length)
            crossed = [
                (hit.alpha, hit.shape, shape_nodes[hit.shape])
                for hit in space.segment_query(origin, end, 0.0, query_filter)
                if hit.shape is not None and hit.shape not in excluded and hit.shape in shape_nodes
            ]
            crossed.sort(key=lambda crossing: crossing[0])
            rays.append(crossed)
        return rays

    def _excluded(self) -> frozenset[pymunk.Shape]:
        if not self.exclude_parent:
            return frozenset()
        body = _body_above(self)
        return frozenset() if body is None else frozenset(body.body.shapes)


def check_settings(settings: Mapping[str, Any], where: str = "") -> dict[str, Any]:
    """A sensor's settings (its constructor's keywords but the pose), checked.

    Raises:
        ValueError: a setting out of range or of the wrong type, named after ``where``.
    """
    checked = dict(settings)
    checked["n_rays"] = integer(settings["n_rays"], f"{where}n_rays", 1, MAX_RAYS)
    checked["ray_length"] = number(settings["ray_length"], f"{where}ray_length", low=0.0)
    if checked["ray_length"] == 0.0:
        raise ValueError(f"{where}ray_length must be more than 0")
    checked["cone_width"] = number(settings["cone_width"], f"{where}cone_width", low=0.0)
    checked["collision_mask"] = integer(
        settings["collision_mask"], f"{where}collision_mask", 0, ALL_LAYERS
    )
    for flag in ("collide_with_sensors", "exclude_parent"):
        if not isinstance(settings[flag], bool):
            raise ValueError(f"{where}{flag} must be true or false, got {settings[flag]!r:.40}")
    return checked


def _body_above(node: Node) -> Any:
    ancestor = node.parent
    while ancestor is not None:
        if isinstance(ancestor, PhysicsBody):
            return ancestor
        ancestor = ancestor.parent
    return None
