"""end_process, the one way every layer ends a child process, against real subprocesses."""

from __future__ import annotations

import signal
import subprocess
import sys

from conftest import alive, wait_until

from rlenv_client.launcher import end_process

_READY = "import sys; print('ready', flush=True); "


def _child(code: str, **options: object) -> subprocess.Popen[str]:
    process = subprocess.Popen(
        [sys.executable, "-c", _READY + code],
        stdout=subprocess.PIPE,
        stdin=subprocess.PIPE,
        text=True,
        **options,
    )  # type: ignore[call-overload]
    assert process.stdout is not None and process.stdout.readline() == "ready\n"
    return process


def test_sigterm_ends_a_process_that_obeys_it() -> None:
    process = _child("sys.stdin.read()")
    assert end_process(process, 30.0) == -signal.SIGTERM
    assert not alive(process.pid)


def test_one_that_ignores_sigterm_is_killed_at_the_deadline() -> None:
    process = _child(
        "import signal; signal.signal(signal.SIGTERM, signal.SIG_IGN); "
        "print('ignoring', flush=True); sys.stdin.read()"
    )
    assert process.stdout is not None and process.stdout.readline() == "ignoring\n"
    assert end_process(process, 0.2) == -signal.SIGKILL
    assert not alive(process.pid)


def test_without_a_first_signal_it_waits_for_the_process_to_end_by_itself() -> None:
    process = _child("sys.stdin.read(); sys.exit(3)")
    assert process.stdin is not None
    process.stdin.close()  # its input closed: it ends by itself
    assert end_process(process, 30.0, first=None) == 3
    assert end_process(process) == 3  # ended already: only reaped, nothing signalled


def test_a_group_ends_with_its_leader() -> None:
    leader = _child(
        "import subprocess; child = subprocess.Popen([sys.executable, '-c', "
        "'import time; time.sleep(600)']); print(child.pid, flush=True); "
        "sys.stdin.read()",
        start_new_session=True,
    )
    assert leader.stdout is not None
    grandchild = int(leader.stdout.readline())
    assert alive(grandchild)
    assert end_process(leader, 30.0, group=True) == -signal.SIGTERM
    wait_until(lambda: not alive(grandchild), "the group's other process outlived its leader")
