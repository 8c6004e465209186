"""PNG images from numpy arrays, with the standard library only (zlib).

Frames (:meth:`~rlenv_client.base.BaseClient.render`) and image observations travel over HTTP
as PNG: a fraction of the raw bytes for drawn scenes, and never nested JSON lists of pixels.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

__all__ = ["encode_png"]

_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_COLOR_TYPES = {1: 0, 2: 4, 3: 2, 4: 6}  # channels -> gray, gray+alpha, RGB, RGBA


def encode_png(image: np.ndarray, level: int = 6) -> bytes:
    """Encode an ``(height, width)`` or ``(height, width, channels)`` uint8 array as PNG.

    Args:
        image: 1 (gray), 2 (gray and alpha), 3 (RGB) or 4 (RGBA) channels, channels last.
        level: zlib's compression level (1: fastest; 6: its default).

    Raises:
        ValueError: the array is not uint8 or not of such a shape.
    """
    array = np.asarray(image)
    if array.ndim == 2:
        array = array[:, :, None]
    if (
        array.dtype != np.uint8
        or array.ndim != 3
        or array.shape[2] not in _COLOR_TYPES
        or 0 in array.shape
    ):
        raise ValueError(
            f"a PNG image is a non-empty (height, width[, 1-4 channels]) uint8 "
            f"array, got {array.dtype} of shape {np.shape(image)}"
        )
    height, width, channels = array.shape
    rows = np.empty((height, 1 + width * channels), np.uint8)
    rows[:, 0] = 0  # filter type None on every row
    rows[:, 1:] = array.reshape(height, width * channels)
    header = struct.pack(">IIBBBBB", width, height, 8, _COLOR_TYPES[channels], 0, 0, 0)
    return b"".join(
        (
            _SIGNATURE,
            _chunk(b"IHDR", header),
            _chunk(b"IDAT", zlib.compress(rows.tobytes(), level)),
            _chunk(b"IEND", b""),
        )
    )


def _chunk(kind: bytes, data: bytes) -> bytes:
    return b"".join(
        (struct.pack(">I", len(data)), kind, data, struct.pack(">I", zlib.crc32(kind + data)))
    )
