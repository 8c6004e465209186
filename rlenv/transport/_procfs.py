"""What one process reads of another in Linux's ``/proc``: whether it runs, its CPU, its memory.

The one reader of ``/proc`` for every layer (the tools' forked copies and benchmarks, the
compliance harness, the benchmarks' scripts, the tests). Each function reads one file when
called; none caches.
"""

from __future__ import annotations

import os

__all__ = ["alive", "cpu_seconds", "rollup_kib", "status_kib"]

_TICKS = os.sysconf("SC_CLK_TCK")


def _stat_fields(pid: int) -> list[bytes]:
    """The fields of ``/proc/PID/stat`` after the command's name (which may hold spaces)."""
    with open(f"/proc/{pid}/stat", "rb") as stat:
        return stat.read().rsplit(b")", 1)[1].split()


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, dead but not yet reaped, does not)."""
    try:
        return _stat_fields(pid)[0] != b"Z"
    except OSError:  # gone, before or while it was read (or no /proc)
        return False


def cpu_seconds(pid: int) -> float:
    """Seconds of CPU (user and system) process ``pid`` has used so far.

    Raises:
        OSError: no such process (or no ``/proc``).
    """
    fields = _stat_fields(pid)
    return (int(fields[11]) + int(fields[12])) / _TICKS


def rollup_kib(pid: int) -> dict[str, int]:
    """The memory figures of ``/proc/PID/smaps_rollup`` in KiB, by name (``Rss``, ``Pss``, ...).

    Raises:
        OSError: no such process (or no ``/proc``).
    """
    fields: dict[str, int] = {}
    with open(f"/proc/{pid}/smaps_rollup", "rb") as rollup:
        for line in rollup:
            name, _, rest = line.partition(b":")
            if rest.rstrip().endswith(b"kB"):
                fields[name.decode()] = int(rest.split()[0])
    return fields


def status_kib(pid: int, name: str) -> int | None:
    """The figure ``name`` of ``/proc/PID/status`` in KiB (``VmRSS``, ``VmHWM``, ...).

    ``None`` where the process is gone, there is no ``/proc`` or it has no such figure.
    """
    prefix = name.encode() + b":"
    try:
        with open(f"/proc/{pid}/status", "rb") as status:
            for line in status:
                if line.startswith(prefix):
                    return int(line.split()[1])
    except OSError:
        return None
    return None
