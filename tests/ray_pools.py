"""What the Ray tests share: the processes of a pool."""

from __future__ import annotations

import ray
from conftest import alive as alive  # the Ray tests import it from here

from rlenv_client.ray import RayServerPool


def server_pids(servers: RayServerPool) -> list[int]:
    """The process ids of a pool's servers now."""
    return ray.get([servers.actor(index).server_pid.remote() for index in range(servers.servers)])
