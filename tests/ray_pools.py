"""What the Ray tests share: polling with a deadline, and the processes of a pool."""

from __future__ import annotations

import time
from collections.abc import Callable

import ray

from rlenv_client.ray import RayServerPool


def wait_until(condition: Callable[[], bool], message: str, seconds: float = 30.0) -> None:
    """Poll ``condition`` until it holds (no fixed sleep)."""
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, message
        time.sleep(0.05)


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, dead but not yet reaped by its parent, does not)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rpartition(")")[2].split()[0] != "Z"
    except FileNotFoundError:
        return False


def server_pids(servers: RayServerPool) -> list[int]:
    """The process ids of a pool's servers now."""
    return ray.get([servers.actor(index).server_pid.remote()
                    for index in range(servers.servers)])
