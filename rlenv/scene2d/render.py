"""Draw pymunk scenes: into RGB arrays, or as vector draw lists for viewers.

RGB arrays are drawn with numpy alone (no display, no drawing library); draw lists are the
shapes as data, for a viewer to draw at any size (the inspector's canvas).

Every shape is rasterised inside its own bounding box by a vectorised inside-test on the pixel
centres (circles by distance, segments as capsules, convex polygons by half-planes), so a frame
of a small scene costs well under a millisecond and the same state always gives the same bytes on
every machine. Colours come from each :class:`~rlenv.scene2d.physics.CollisionShape`'s ``color``, or
from its body's kind.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, cast

import numpy as np
import pymunk

from rlenv.node import Node
from rlenv.scene2d.physics import CollisionShape, PhysicsWorld

__all__ = ["BACKGROUND", "View", "draw", "draw_list", "fit_view"]

View = tuple[float, float, float, float]
"""A world rectangle: (x_min, y_min, x_max, y_max)."""

BACKGROUND = (255, 255, 255)
"""The default colour of empty space: white."""
_COLORS = {
    pymunk.Body.DYNAMIC: (66, 110, 180),
    pymunk.Body.KINEMATIC: (200, 140, 40),
    pymunk.Body.STATIC: (90, 90, 90),
}
_SENSOR = (120, 200, 120)
_MIN_HALF_WIDTH = 0.75  # pixels: thin segments stay visible


def draw(
    root: Node,
    width: int,
    height: int,
    view: View | None = None,
    background: tuple[int, int, int] = BACKGROUND,
) -> np.ndarray:
    """Draw every PhysicsWorld at or below ``root`` into a ``(height, width, 3)`` uint8 array.

    The world is drawn with y up (row 0 is the top of the view), each shape in its
    CollisionShape's ``color`` or its body's kind's (dynamic blue, kinematic orange, static
    grey, sensors green).

    Args:
        root: the node whose physics to draw (usually the environment).
        width: image width in pixels.
        height: image height in pixels.
        view: the world rectangle to show, fitted into the image keeping its aspect ratio and
            centred; by default the bounding box of every shape.
        background: the RGB colour of empty space.

    Returns:
        The RGB image.
    """
    shapes = list(_shapes(root))
    image = np.empty((height, width, 3), dtype=np.uint8)
    image[:] = background
    if view is None:
        view = fit_view([shape for shape, _ in shapes])
    x0, y0, scale = _transform(view, width, height)
    for shape, color in shapes:
        _draw_shape(image, shape, color, x0, y0, scale)
    return image


def draw_list(root: Node, view: View | None = None) -> dict[str, Any]:
    """Every shape of every PhysicsWorld at or below ``root``, as plain data to draw.

    ``{"view": [x_min, y_min, x_max, y_max], "shapes": [...]}`` (world coordinates, y up); each
    shape is a list, its kind first, then its colour as ``0xRRGGBB``:
    ``["circle", color, x, y, radius, angle]``, ``["segment", color, ax, ay, bx, by, radius]``
    or ``["polygon", color, radius, [x0, y0, x1, y1, ...]]``. A few bytes per shape: viewers
    draw it at any size (the same colours as :func:`draw`).

    Args:
        root: the node whose physics to describe (usually the environment).
        view: the world rectangle to show; by default the bounding box of every shape.

    Returns:
        The draw list, msgpack- and JSON-ready.
    """
    shapes = list(_shapes(root))
    if view is None:
        view = fit_view([shape for shape, _ in shapes])
    return {
        "view": list(view),
        "shapes": [
            item for shape, color in shapes if (item := _described(shape, color)) is not None
        ],
    }


def _described(shape: pymunk.Shape, color: tuple[int, int, int]) -> list[Any] | None:
    body = _body(shape)
    rgb = color[0] << 16 | color[1] << 8 | color[2]
    if isinstance(shape, pymunk.Circle):
        x, y = body.local_to_world(shape.offset)
        return ["circle", rgb, x, y, shape.radius, body.angle]
    if isinstance(shape, pymunk.Segment):
        (ax, ay), (bx, by) = body.local_to_world(shape.a), body.local_to_world(shape.b)
        return ["segment", rgb, ax, ay, bx, by, shape.radius]
    if isinstance(shape, pymunk.Poly):
        return [
            "polygon",
            rgb,
            shape.radius,
            [
                coordinate
                for vertex in shape.get_vertices()
                for coordinate in body.local_to_world(vertex)
            ],
        ]
    return None


def fit_view(shapes: Sequence[pymunk.Shape], margin: float = 0.1) -> View:
    """The bounding box of ``shapes``, grown by ``margin`` of its size on each side."""
    if not shapes:
        return (-1.0, -1.0, 1.0, 1.0)
    boxes = [shape.cache_bb() for shape in shapes]
    left = min(b.left for b in boxes)
    bottom = min(b.bottom for b in boxes)
    right = max(b.right for b in boxes)
    top = max(b.top for b in boxes)
    pad = margin * max(right - left, top - bottom, 1e-3)
    return (left - pad, bottom - pad, right + pad, top + pad)


def _body(shape: pymunk.Shape) -> pymunk.Body:
    # Only a space's shapes are drawn, and pymunk adds no shape to a space without its body.
    return cast(pymunk.Body, shape.body)


def _shapes(root: Node) -> Iterable[tuple[pymunk.Shape, tuple[int, int, int]]]:
    worlds = root.find_children("*", PhysicsWorld)
    if isinstance(root, PhysicsWorld):
        worlds.insert(0, root)
    for world in worlds:
        for shape in world.space.shapes:
            node = world._shape_nodes.get(shape)
            yield shape, _color(shape, node)


def _color(shape: pymunk.Shape, node: CollisionShape | None) -> tuple[int, int, int]:
    if node is not None and node.color is not None:
        return node.color
    if shape.sensor:
        return _SENSOR
    body = shape.body
    return _COLORS[body.body_type] if body is not None else _COLORS[pymunk.Body.STATIC]


def _transform(view: View, width: int, height: int) -> tuple[float, float, float]:
    """Pixel (i, j) centre = world (x0 + (j + 0.5) / scale, y0 - (i + 0.5) / scale)."""
    left, bottom, right, top = view
    scale = min(width / max(right - left, 1e-9), height / max(top - bottom, 1e-9))
    centre_x, centre_y = (left + right) / 2, (bottom + top) / 2
    return centre_x - width / (2 * scale), centre_y + height / (2 * scale), scale


def _draw_shape(
    image: np.ndarray,
    shape: pymunk.Shape,
    color: tuple[int, int, int],
    x0: float,
    y0: float,
    scale: float,
) -> None:
    box = shape.cache_bb()
    half_pixel = _MIN_HALF_WIDTH / scale
    cols = _pixel_range(
        box.left - half_pixel - x0, box.right + half_pixel - x0, scale, image.shape[1]
    )
    rows = _pixel_range(
        y0 - box.top - half_pixel, y0 - box.bottom + half_pixel, scale, image.shape[0]
    )
    if cols is None or rows is None:
        return
    x = (x0 + (np.arange(*cols) + 0.5) / scale)[np.newaxis, :]  # broadcast, never a grid
    y = (y0 - (np.arange(*rows) + 0.5) / scale)[:, np.newaxis]
    mask = np.broadcast_to(_inside(shape, x, y, half_pixel), (rows[1] - rows[0], cols[1] - cols[0]))
    image[rows[0] : rows[1], cols[0] : cols[1]][mask] = color


def _pixel_range(low: float, high: float, scale: float, size: int) -> tuple[int, int] | None:
    start = max(int(np.floor(low * scale)), 0)
    stop = min(int(np.ceil(high * scale)), size)
    return (start, stop) if start < stop else None


def _inside(shape: pymunk.Shape, x: np.ndarray, y: np.ndarray, half_pixel: float) -> np.ndarray:
    body = _body(shape)
    if isinstance(shape, pymunk.Circle):
        cx, cy = body.local_to_world(shape.offset)
        return (x - cx) ** 2 + (y - cy) ** 2 <= max(shape.radius, half_pixel) ** 2
    if isinstance(shape, pymunk.Segment):
        a = body.local_to_world(shape.a)
        b = body.local_to_world(shape.b)
        return _capsule(x, y, a, b, max(shape.radius, half_pixel))
    if isinstance(shape, pymunk.Poly):
        vertices = [body.local_to_world(v) for v in shape.get_vertices()]
        return _convex(x, y, vertices, shape.radius)
    return np.zeros((1, 1), dtype=bool)


def _capsule(
    x: np.ndarray, y: np.ndarray, a: Sequence[float], b: Sequence[float], radius: float
) -> np.ndarray:
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    length2 = dx * dx + dy * dy
    t = np.clip(((x - ax) * dx + (y - ay) * dy) / length2, 0.0, 1.0) if length2 else 0.0
    return (x - ax - t * dx) ** 2 + (y - ay - t * dy) ** 2 <= radius * radius


def _convex(
    x: np.ndarray, y: np.ndarray, vertices: Sequence[Sequence[float]], radius: float
) -> np.ndarray:
    mask: np.ndarray | bool = True
    count = len(vertices)
    for index in range(count):
        (ax, ay), (bx, by) = vertices[index], vertices[(index + 1) % count]
        edge_x, edge_y = bx - ax, by - ay
        length = (edge_x * edge_x + edge_y * edge_y) ** 0.5 or 1.0
        # pymunk keeps polygon vertices counter-clockwise: the inside is left of every edge
        mask = mask & ((edge_x * (y - ay) - edge_y * (x - ax)) / length >= -radius)
    return np.asarray(mask)
