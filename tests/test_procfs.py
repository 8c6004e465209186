"""rlenv.transport._procfs, the one reader of /proc, against real processes."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from rlenv.transport import _procfs as procfs


def test_a_running_process_is_alive_and_its_figures_are_read() -> None:
    child = subprocess.Popen(
        [sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE
    )
    try:
        assert procfs.alive(child.pid)
        assert procfs.cpu_seconds(child.pid) >= 0.0
        rollup = procfs.rollup_kib(child.pid)
        assert rollup["Rss"] > 0 and rollup["Pss"] > 0 and "Private_Dirty" in rollup
        rss = procfs.status_kib(child.pid, "VmRSS")
        assert rss is not None and procfs.status_kib(child.pid, "VmHWM") >= rss  # type: ignore[operator]
        assert procfs.status_kib(child.pid, "NoSuchFigure") is None
    finally:
        child.communicate(b"")
    assert not procfs.alive(child.pid)  # reaped: gone
    assert procfs.status_kib(child.pid, "VmRSS") is None


def test_a_zombie_is_not_alive_and_own_cpu_time_grows() -> None:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    deadline = time.monotonic() + 60
    while procfs.alive(child.pid):  # exits; unreaped it stays a zombie
        assert time.monotonic() < deadline, "the child did not exit"
        time.sleep(0.01)
    assert os.path.exists(f"/proc/{child.pid}")  # still there, as a zombie
    child.wait()
    before = procfs.cpu_seconds(os.getpid())
    end = time.process_time() + 0.05
    while time.process_time() < end:
        pass
    assert procfs.cpu_seconds(os.getpid()) > before
