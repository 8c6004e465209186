"""What the benchmarks read of a process in ``/proc``: the CPU time it has used, its memory.

The benchmarks run as scripts (``python benchmarks/NAME.py``), so they import this file as a
sibling; it reads through :mod:`rlenv.transport._procfs`, the one reader of ``/proc``.
"""

from __future__ import annotations

from rlenv.transport._procfs import cpu_seconds, rollup_kib

__all__ = ["cpu_seconds", "memory_kib"]


def memory_kib(pid: int) -> tuple[int, int]:
    """RSS and USS (private pages) of process ``pid``, in KiB."""
    fields = rollup_kib(pid)
    return fields["Rss"], fields["Private_Clean"] + fields["Private_Dirty"]
