"""Reading a recording from a file: regular files only, within a size bound, its shape checked.

Every tool that opens a recording (``rlenv replay``, :meth:`Timeline.open
<rlenv_tools.timeline.Timeline.open>`, ``rlenv dataset create``, ``rlenv replay --inspect``)
reads it through :func:`read_recording`, from :meth:`EpisodeFile.load
<rlenv_client.replay.EpisodeFile.load>`:

- anything but a regular file (a FIFO, ``/dev/zero``, a socket, a folder) is refused at once,
  before a byte is read (the file is opened without blocking, then ``fstat`` says what it is);
- a file of more than :data:`MAX_RECORDING_BYTES` is refused from its size, before it is read
  (a sparse file costs nothing), and it is read as a stream that stops one byte past the bound
  (a file that grows while it is read);
- :func:`check_frames` refuses an action that asks for more than :data:`MAX_REPEAT_ACTION`
  ticks, which a re-simulation would otherwise run.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

from rlenv.protocol.codec import DEFAULT_MAX_FRAME_SIZE
from rlenv.protocol.messages import MAX_REPEAT_ACTION

__all__ = ["MAX_RECORDING_BYTES", "check_frames", "read_recording"]

MAX_RECORDING_BYTES = DEFAULT_MAX_FRAME_SIZE
"""The largest recording a tool reads (64 MiB, a frame's bound: a recording is one msgpack map,
and holds at most a frame's objects)."""


_KINDS = (
    (stat.S_ISDIR, "a folder"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a device"),
    (stat.S_ISBLK, "a device"),
    (stat.S_ISSOCK, "a socket"),
)


def read_recording(path: str | Path, limit: int = MAX_RECORDING_BYTES) -> bytes:
    """The bytes of the recording at ``path``, at most ``limit`` of them.

    Raises:
        ValueError: ``path`` is not a regular file, or holds more than ``limit`` bytes.
        OSError: the file cannot be opened (no such file, no permission).
    """
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0))
    try:
        mode = os.fstat(fd)
        if not stat.S_ISREG(mode.st_mode):
            kind = next((name for test, name in _KINDS if test(mode.st_mode)), "no regular file")
            raise ValueError(f"{path} is {kind}: a recording is a regular file")
        if mode.st_size > limit:
            raise ValueError(
                f"{path} holds {mode.st_size:,} bytes: a recording holds at most {limit:,}"
            )
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    finally:
        os.close(fd)
    if size > limit:
        raise ValueError(
            f"{path} grew past {limit:,} bytes while it was read: a recording "
            f"holds at most {limit:,}"
        )
    return b"".join(chunks)


def check_frames(events: list[Any], where: str) -> None:
    """Refuse an action event (``["action", action, frames]``) of more than the bound's ticks.

    Raises:
        ValueError: naming the event and the bound.
    """
    for index, event in enumerate(events):
        if event[0] == "action" and event[2] > MAX_REPEAT_ACTION:
            raise ValueError(
                f"{where}: events[{index}] asks for {event[2]:,} ticks; a recorded "
                f"action runs at most {MAX_REPEAT_ACTION:,}"
            )
