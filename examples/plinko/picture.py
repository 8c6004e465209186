"""Draw two Plinko levels side by side into a PNG: ``python -m examples.plinko.picture PATH``.

The picture in docs/procedural.md (``make plinko-picture``): the levels of seed 5 at
difficulty 0.2 and of seed 6 at difficulty 0.9, each drawn by rlenv's own renderer (the frames
``render()`` returns), written as a PNG with the standard library (zlib) alone.
"""

from __future__ import annotations

import struct
import sys
import zlib
from pathlib import Path

import numpy as np

from rlenv_client import LocalClient

from . import PlinkoEnvironment

__all__ = ["levels_picture", "main", "write_png"]

LEVELS = ((5, 0.2), (6, 0.9))
"""(seed, difficulty) of each level drawn."""
GAP = 12  # pixels of white between the levels


def levels_picture(levels: tuple[tuple[int, float], ...] = LEVELS) -> np.ndarray:
    """The frames of the levels (after a reset each), side by side: (H, W, 3) uint8."""
    frames = []
    with LocalClient(PlinkoEnvironment) as client:
        for seed, difficulty in levels:
            client.configure(world={"difficulty": difficulty})
            client.reset(seed=seed)
            frames.append(client.render())
    height = frames[0].shape[0]
    gap = np.full((height, GAP, 3), 255, dtype=np.uint8)
    parts = [frames[0]]
    for frame in frames[1:]:
        parts += [gap, frame]
    return np.concatenate(parts, axis=1)


def write_png(path: Path, image: np.ndarray) -> None:
    """Write an (H, W, 3) uint8 RGB array as a PNG file."""
    height, width, _ = image.shape
    rows = b"".join(b"\x00" + image[row].tobytes() for row in range(height))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data))
            + kind
            + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
        )

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(rows, 9))
        + chunk(b"IEND", b"")
    )


def main() -> None:
    """Write the picture to the path given (docs/images/plinko-levels.png by default)."""
    path = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/images/plinko-levels.png")
    write_png(path, levels_picture())
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
