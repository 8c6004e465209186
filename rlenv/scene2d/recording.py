"""VideoRecorder: frames in, a video file out (through imageio and its ffmpeg plugin).

Used by :class:`~rlenv.scene2d.camera.Camera` and by environments recording themselves on a client's
request (``configure(record="episode.mp4")`` on a server started with ``--record-dir``).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["VideoRecorder"]

logger = logging.getLogger(__name__)


class VideoRecorder:
    """Writes RGB frames to ``path`` at ``fps`` frames per second.

    Raises:
        RuntimeError: imageio with ffmpeg is not installed.
    """

    def __init__(self, path: str | Path, fps: float) -> None:
        try:
            import imageio.v2 as imageio
        except ImportError:
            raise RuntimeError(
                "recording needs imageio and imageio-ffmpeg: pip install 'rlenv[video]'"
            ) from None
        self.path = Path(path)
        self._writer: Any = imageio.get_writer(str(path), fps=fps, macro_block_size=1)
        self.frames = 0
        logger.info("recording to %s at %.1f fps", path, fps)

    def add(self, frame: np.ndarray) -> None:
        """Append one ``(height, width, 3)`` uint8 frame."""
        self._writer.append_data(frame)
        self.frames += 1

    def close(self) -> int:
        """Finish the file; returns how many frames it holds."""
        self._writer.close()
        logger.info("recorded %d frames to %s", self.frames, self.path)
        return self.frames
