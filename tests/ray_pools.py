"""What the Ray tests share: the processes of a pool."""

from __future__ import annotations

import ray

from rlenv_client.ray import RayServerPool


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
