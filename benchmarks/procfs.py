"""What the benchmarks read of a process in ``/proc``: the CPU time it has used.

The benchmarks run as scripts (``python benchmarks/NAME.py``), so they import this file as a
sibling; so does a process that another checkout's interpreter runs from one of them.
"""

from __future__ import annotations

import os

__all__ = ["cpu_seconds"]

_TICKS = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """Seconds of CPU (user and system) the process ``pid`` has used so far."""
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / _TICKS
