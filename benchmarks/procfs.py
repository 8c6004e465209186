"""What the benchmarks read of a process in ``/proc``: the CPU time it has used, its memory.

The benchmarks run as scripts (``python benchmarks/NAME.py``), so they import this file as a
sibling; so does a process that another checkout's interpreter runs from one of them.
"""

from __future__ import annotations

import os

__all__ = ["cpu_seconds", "memory_kib"]

_TICKS = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """Seconds of CPU (user and system) the process ``pid`` has used so far."""
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / _TICKS


def memory_kib(pid: int) -> tuple[int, int]:
    """RSS and USS (private pages) of process ``pid``, in KiB."""
    fields: dict[str, int] = {}
    with open(f"/proc/{pid}/smaps_rollup") as rollup:
        for line in rollup:
            name, _, rest = line.partition(":")
            if rest.strip().endswith("kB"):
                fields[name] = int(rest.split()[0])
    return fields["Rss"], fields["Private_Clean"] + fields["Private_Dirty"]
