"""A forked environment's process: its errors carry their traceback; a fork leaves the original's
collector as it was (``rlenv_tools.forking``)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from rlenv.protocol.errors import RemoteError
from rlenv_tools.forking import ForkedEnvironment


def test_an_error_in_the_environment_process_comes_with_its_traceback() -> None:
    environment = ForkedEnvironment.start("examples.faulty:FaultyEnvironment", timeout=120.0)
    try:
        with pytest.raises(RemoteError) as raised:
            environment.run([[1]])  # not a step: the process's own loop raises on it
        assert raised.value.code == "environment_error"
        message = raised.value.message
        assert message.startswith("TypeError: 'int' object is not subscriptable\n")
        assert "Traceback (most recent call last):" in message
        assert "forking.py" in message and ", in run\n" in message  # where it was raised
        copy = environment.fork()  # the process went on serving
        copy.close()
    finally:
        environment.close()


_FORK_AND_COUNT = """
import gc, os, socket, sys
from rlenv_tools import forking

ours, theirs = socket.socketpair()
gc.collect()
if forking._fork(ours) is not None:  # the copy
    os._exit(0 if gc.get_freeze_count() > 0 else 3)  # keeps what it inherited frozen
message, fds, _, _ = socket.recv_fds(theirs, 16, 1)
os.close(fds[0])
pid = forking._FORKED.unpack(message)[0]
_, status = os.waitpid(pid, 0)
print(gc.get_freeze_count(), os.waitstatus_to_exitcode(status))
"""


def test_a_fork_leaves_nothing_frozen_in_the_original() -> None:
    # gc.freeze() before the fork keeps the copy's collector off the shared pages; left in
    # place, the original (a timeline forks it again and again) would never collect again
    # whatever it held at the fork.
    result = subprocess.run(
        [sys.executable, "-c", _FORK_AND_COUNT],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    assert result.stdout.split() == ["0", "0"]
