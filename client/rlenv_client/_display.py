"""A window that shows RGB frames, for ``render_mode="human"``: tkinter only, no extra package.

Frames are handed to Tk as binary PPM images, which Tk decodes natively.
"""

from __future__ import annotations

import os
import sys
from typing import Any

import numpy as np

__all__ = ["Display", "display_available"]


def display_available() -> bool:
    """Whether a window can be opened: a display server is set (always true off Linux/BSD)."""
    if sys.platform in ("win32", "darwin"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


class Display:
    """One window; :meth:`show` replaces its picture.

    Args:
        title: the window title.

    Raises:
        RuntimeError: no display, or Tk cannot open a window on it.
    """

    def __init__(self, title: str) -> None:
        if not display_available():
            raise RuntimeError("no display is available (DISPLAY is not set)")
        import tkinter

        try:
            self._root: Any = tkinter.Tk()
        except tkinter.TclError as error:
            raise RuntimeError(f"cannot open a window: {error}") from None
        self._root.title(title)
        self._label = tkinter.Label(self._root)
        self._label.pack()
        self._image: Any = None
        self._tkinter = tkinter

    def show(self, frame: np.ndarray) -> None:
        """Show an ``(height, width, 3)`` uint8 frame and let the window redraw."""
        height, width = frame.shape[:2]
        ppm = b"P6 %d %d 255\n" % (width, height) + np.ascontiguousarray(frame).tobytes()
        self._image = self._tkinter.PhotoImage(data=ppm, format="PPM")
        self._label.configure(image=self._image)
        self._root.update()

    def close(self) -> None:
        """Close the window."""
        self._root.destroy()
