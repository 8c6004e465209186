"""Servers shared by the environments of one process: what ``gymnasium.make`` gives.

Trainers make their environments one by one and step them one after the other (SB3's
``make_vec_env``, gymnasium's ``SyncVectorEnv``, CleanRL). A server per environment would make
every step wake another sleeping process, and their waiting processes would take the trainer's
cores. So the environments of one process that serve the same ``MODULE:CLASS`` with the same
server arguments share one server, started with ``--per-client``: each environment still has
a connection and an environment of its own (its own tree, seed, configuration and errors), and
only the process is shared. The server stops when the last of them closes.

A shared server that dies is replaced once, for all its environments: each of them finds it
lost, ends its episode as truncated (``info["server_restarted"]``) and connects to the
replacement, within its own ``max_restarts``. A process made by ``fork`` shares nothing with
its parent: it starts servers of its own.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from dataclasses import dataclass

from rlenv_client.launcher import ServerProcess

__all__ = ["MAX_CLIENTS", "SharedServers", "shared_servers"]

MAX_CLIENTS = 256
"""Environments one shared server hosts at most; more start another server."""


@dataclass
class _Shared:
    server: ServerProcess
    users: int = 0


class SharedServers:
    """The shared servers of this process, by what they serve (thread-safe).

    Args:
        startup_timeout: seconds a new server may take to listen.
    """

    def __init__(self, startup_timeout: float = 60.0) -> None:
        self.startup_timeout = startup_timeout
        self._forget()

    def lease(self, target: str, server_args: Sequence[str] = ()) -> ServerProcess:
        """A running server of ``target`` with a place for one more environment.

        Call :meth:`release` with it when that environment closes. A server that must start
        starts outside the lock: other threads lease, release and look meanwhile, and those
        that want the same server wait for it (then start one themselves if it did not start).

        Raises:
            ServerStartError: a new server was needed and could not start.
        """
        key = (target, tuple(server_args))
        while True:
            with self._lock:
                place = next(
                    (
                        entry
                        for entry in self._servers.get(key, ())
                        if entry.users < MAX_CLIENTS and entry.server.is_alive()
                    ),
                    None,
                )
                if place is not None:
                    place.users += 1
                    return place.server
                starting = self._starting.get(key)
                if starting is None:  # this thread starts it
                    starting = self._starting[key] = threading.Event()
                    break
            starting.wait()
        try:
            server = ServerProcess(
                target,
                startup_timeout=self.startup_timeout,
                args=[*server_args, "--per-client", "--max-connections", str(MAX_CLIENTS)],
            )
            with self._lock:
                self._servers.setdefault(key, []).append(_Shared(server, users=1))
                self._keys[server] = key
            return server
        finally:
            with self._lock:
                del self._starting[key]
            starting.set()

    def release(self, server: ServerProcess) -> None:
        """One environment of ``server`` closed; the server stops with the last of them."""
        with self._lock:
            key = self._keys.get(server)
            if key is None:
                return
            entry = next(entry for entry in self._servers[key] if entry.server is server)
            entry.users -= 1
            if entry.users > 0:
                return
            del self._keys[server]
            self._servers[key].remove(entry)
            if not self._servers[key]:
                del self._servers[key]
        server.close(timeout=1.0)

    def __contains__(self, server: object) -> bool:
        """Whether ``server`` is one of these shared servers."""
        with self._lock:
            return server in self._keys

    def servers(self) -> list[ServerProcess]:
        """Every shared server of this process."""
        with self._lock:
            return list(self._keys)

    def _forget(self) -> None:
        """Start empty (and, in a child made by ``fork``, leave the parent's servers alone)."""
        self._lock = threading.Lock()
        self._servers: dict[tuple[str, tuple[str, ...]], list[_Shared]] = {}
        self._keys: dict[ServerProcess, tuple[str, tuple[str, ...]]] = {}
        self._starting: dict[tuple[str, tuple[str, ...]], threading.Event] = {}  # set: started


shared_servers = SharedServers()
"""This process's shared servers (what :class:`~rlenv_client.env.RemoteEnv` leases)."""

os.register_at_fork(after_in_child=shared_servers._forget)
