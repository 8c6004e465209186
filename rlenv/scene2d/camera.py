"""Camera: a node that sees the pymunk scene around it as RGB arrays, and can film it.

A camera draws every pymunk space in the subtree of its parent (place it next to what it should
see), headless, with :func:`rlenv.scene2d.render.draw`. Use :meth:`Camera.capture` as (part of) an
agent's observation, and :meth:`Camera.start_recording` / :meth:`Camera.stop_recording` to film
the physics frame by frame, as Blueprints' cameras do::

    camera = Camera(view=(-5, -5, 5, 5), size=(64, 64), name="Eye")
    world.add_child(camera)
    frame = camera.capture()                      # (64, 64, 3) uint8
    camera.start_recording("episode.mp4")         # one video frame per physics tick
    ...
    camera.stop_recording()

Recording needs ``imageio`` with its ffmpeg plugin (``pip install 'rlenv[video]'``).
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import numpy as np

from rlenv.node import Node
from rlenv.scene2d.node2d import Node2D
from rlenv.scene2d.recording import VideoRecorder
from rlenv.scene2d.render import BACKGROUND, View, draw

__all__ = ["Camera"]


class Camera(Node):
    """Sees the scene below its parent.

    Frames show the world with y up: row 0 of the array is the top (``y_max``) of the view. The
    view is fitted into the frame keeping its aspect ratio, centred.

    Args:
        view: the world rectangle (x_min, y_min, x_max, y_max) it sees, in world coordinates;
            the bounding box of every shape, frame by frame, when ``None``. When following,
            only its width and height matter.
        size: (width, height) of its frames, in pixels.
        follow: path (relative to the camera, e.g. ``../Ball``) of a node with a ``position``
            (a body) to keep centred.
        background: RGB colour (0-255 each) of empty space.
        name: the node name.

    Attributes:
        view: the world rectangle it sees (see above); may be changed at any time.
        size: (width, height) of its frames, in pixels.
        follow: the path of the node it keeps centred, or ``None``.
        background: RGB colour of empty space.
    """

    _TREE_STATE: ClassVar[frozenset[str]] = Node._TREE_STATE | {"_recorder"}

    def __init__(
        self,
        view: View | None = None,
        size: tuple[int, int] = (84, 84),
        *,
        follow: str | None = None,
        background: tuple[int, int, int] = BACKGROUND,
        name: str | None = None,
    ) -> None:
        super().__init__(name)
        self.view = view
        self.size = size
        self.follow = follow
        self.background = background
        self._recorder: VideoRecorder | None = None
        self._every = 1
        self._ticks = 0
        self.set_physics_process(False)  # ticks matter only while recording

    def capture(self) -> np.ndarray:
        """What the camera sees now: an ``(height, width, 3)`` uint8 RGB array (row 0 at the top).

        Raises:
            RuntimeError: the camera has no parent to look at.
        """
        scene = self.parent
        if scene is None:
            raise RuntimeError(f"{self!r} has no parent to look at")
        width, height = self.size
        return draw(scene, width, height, self._current_view(), self.background)

    def start_recording(self, path: str | Path, fps: float | None = None, every: int = 1) -> None:
        """Film from now on: one video frame every ``every`` physics ticks, into ``path``.

        Args:
            path: the video file to write (its extension picks the format, e.g. ``.mp4``).
            fps: frames per second of the video; by default real time.
            every: physics ticks between frames.

        Raises:
            RuntimeError: already recording, or imageio with ffmpeg is not installed.
        """
        if self._recorder is not None:
            raise RuntimeError(f"{self!r} is already recording")
        if fps is None:
            fps = self.get_tree().physics_ticks_per_second / every
        self._recorder = VideoRecorder(path, fps)
        self._every = every
        self._ticks = 0
        self.set_physics_process(True)

    def stop_recording(self) -> int:
        """Stop filming and close the video; returns how many frames it holds."""
        recorder, self._recorder = self._recorder, None
        self.set_physics_process(False)
        return recorder.close() if recorder is not None else 0

    @property
    def recording(self) -> bool:
        """Whether the camera is filming."""
        return self._recorder is not None

    def _duplicated(self, original: Node) -> None:
        self._recorder = None  # a copy does not film (nor write into the original's file)
        self.set_physics_process(False)

    def _physics_process(self, delta: float) -> None:
        self.call_deferred(self._record)  # at the end of the tick, after the physics stepped

    def _exit_tree(self) -> None:
        self.stop_recording()

    def _record(self) -> None:
        if self._recorder is None:
            return
        self._ticks += 1
        if self._ticks % self._every == 0:
            self._recorder.add(self.capture())

    def _current_view(self) -> View | None:
        if self.follow is None:
            return self.view
        target = self.get_node(self.follow)
        if isinstance(target, Node2D):  # where it is in the world, whatever frame it is in
            x, y = target.global_position
        else:
            x, y = target.position  # type: ignore[attr-defined]
        left, bottom, right, top = self.view or (-1.0, -1.0, 1.0, 1.0)
        half_width, half_height = (right - left) / 2, (top - bottom) / 2
        return (x - half_width, y - half_height, x + half_width, y + half_height)
