"""Session: one environment reached by :func:`connect`, restartable.

A server that rlenv started itself can be restarted when it is lost (killed, crashed, stopped
past the deadline), within a budget. The session replays the configuration sent through it, so
the new server is set up like the old one. What happens to the interrupted episode is the
caller's business: :class:`~rlenv_client.env.RemoteEnv` and
:class:`~rlenv_client.vector.RemoteVectorEnv` end it as truncated, with ``info`` saying why,
and never send a request twice (no transition is invented or duplicated).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any, Protocol

from rlenv.protocol.errors import ConnectionLost, RequestTimeout
from rlenv_client._addresses import parse_address
from rlenv_client.base import BaseClient
from rlenv_client.client import Client
from rlenv_client.launcher import ServerProcess, with_server_story
from rlenv_client.sharing import shared_servers

__all__ = ["LOST", "ServerLost", "ServerSource", "Session", "as_lost", "connect"]

logger = logging.getLogger(__name__)

LOST = (ConnectionLost, RequestTimeout)
"""The errors that mean the server is gone or not answering."""


class ServerLost(ConnectionLost):
    """A server of a :class:`ServerSource` was lost more often than the restart budget allows."""


class ServerSource(Protocol):
    """Servers that something else runs and restarts (:class:`rlenv_client.ray.RayServerPool`).

    A session asks for a server's address every time it connects, never caching it: a server
    may come back elsewhere.
    """

    token: str
    instances_per_server: int

    @property
    def servers(self) -> int:
        """How many servers."""

    def address(self, index: int, timeout: float = ...) -> str:
        """``HOST:PORT`` of server ``index`` now; waits while it comes back."""

    def describe(self, index: int) -> str:
        """Which server ``index`` is, and where, for error messages."""


def connect(
    target: str | None = None,
    *,
    address: str | None = None,
    in_process: bool = False,
    timeout: float = 30.0,
    server_args: Sequence[str] = (),
    startup_timeout: float = 60.0,
    token: str | None = None,
    instances: int = 1,
    pool: ServerSource | None = None,
    index: int = 0,
    shared_memory: bool | None = None,
    share_server: bool = False,
) -> tuple[BaseClient, ServerProcess | None]:
    """Reach an environment the way :class:`RemoteEnv` does.

    An ``address`` wins over a ``target``, so that a registered id (whose target is fixed) can
    attach to a running server: ``gymnasium.make("rlenv/CartPole-v0", address="host:port")``.

    ``instances`` > 1 holds that many instances of the target behind the client (a server
    started with ``--instances``, or in this process). A ``pool`` wins over both: the client
    connects to its server ``index``, wherever that is now. ``shared_memory`` is
    :class:`~rlenv_client.client.Client`'s (a lane for steps to a server on this machine).
    ``share_server`` reaches a ``target`` of one instance through this process's shared server
    of it (:mod:`rlenv_client.sharing`) instead of a server of its own.

    Returns:
        The client, and the server process it started (``None`` when it started none).

    Raises:
        ValueError: neither ``target`` nor ``address``, or ``in_process`` with an address.
    """
    if pool is not None:
        host, port = parse_address(pool.address(index))
        return Client(
            host, port, timeout=timeout, token=pool.token, shared_memory=shared_memory
        ), None
    if address is not None:
        if in_process:
            raise ValueError("in_process=True needs a target, not an address")
        return Client(
            *parse_address(address), timeout=timeout, token=token, shared_memory=shared_memory
        ), None
    if target is None:
        raise ValueError("give target='MODULE:CLASS' or address='HOST:PORT'")
    if in_process:
        from rlenv_client.local import LocalClient

        return LocalClient(target, instances=instances), None
    if share_server and instances == 1:
        server = shared_servers.lease(target, server_args)
        try:
            return Client(
                server.host, server.port, timeout=timeout, shared_memory=shared_memory
            ), server
        except BaseException:
            shared_servers.release(server)
            raise
    if instances > 1:
        server_args = [*server_args, "--instances", str(instances)]
    server = ServerProcess(target, startup_timeout=startup_timeout, args=server_args)
    try:
        return Client(
            server.host, server.port, timeout=timeout, shared_memory=shared_memory
        ), server
    except BaseException:
        server.close()
        raise


class Session:
    """A client and, when rlenv started it, its server; see the module docstring.

    Args:
        target: ``MODULE:CLASS`` to serve (a server is started), or ``None`` with ``address``.
        address: ``HOST:PORT`` of a running server.
        in_process: run the environment in this process.
        max_restarts: how many times a lost server that this session started may be replaced.
        timeout: seconds to wait for each answer.
        server_args: extra arguments for ``rlenv serve``.
        token: the secret of a server that requires one.
        instances: how many instances of the target the server (or this process) holds.
        pool: servers run by someone else (a Ray pool), of which this session uses server
            ``index``; a lost one is reconnected wherever the pool says it is now.
        index: which server of ``pool``.
        shared_memory: step through a shared-memory lane (see
            :class:`~rlenv_client.client.Client`).
        share_server: reach ``target`` through this process's shared server of it (see
            :func:`connect`).
    """

    def __init__(
        self,
        target: str | None = None,
        *,
        address: str | None = None,
        in_process: bool = False,
        max_restarts: int = 0,
        timeout: float = 30.0,
        server_args: Sequence[str] = (),
        token: str | None = None,
        instances: int = 1,
        pool: ServerSource | None = None,
        index: int = 0,
        shared_memory: bool | None = None,
        share_server: bool = False,
    ) -> None:
        # connect's keyword arguments, as given.
        self._place: dict[str, Any] = {
            "target": target,
            "address": address,
            "in_process": in_process,
            "timeout": timeout,
            "server_args": server_args,
            "token": token,
            "instances": instances,
            "pool": pool,
            "index": index,
            "shared_memory": shared_memory,
            "share_server": share_server,
        }
        self._pool = pool
        self._connect()
        self.max_restarts = max_restarts
        self.restarts = 0
        self.on_restart: Callable[[], None] | None = None  # told once a restart reconnected
        self._configuration: list[dict[str, Any]] = []

    def configure(self, **settings: Any) -> None:
        """Configure the environment and remember it for a restarted server."""
        self.client.configure(**settings)
        self._configuration.append(settings)

    def can_restart(self) -> bool:
        """Whether the server is ours (or a pool's) and the budget allows one more restart."""
        return (
            self.server is not None or self._pool is not None
        ) and self.restarts < self.max_restarts

    def restart(self, error: Exception) -> str:
        """Replace the lost server with a new one; returns why, for ``info``.

        Raises:
            ConnectionLost: the budget is spent or the server is not ours (with the old server's
                exit story).
        """
        story = self.failure(error)
        if not self.can_restart():
            if self._pool is not None:
                raise ServerLost(
                    f"{self._pool.describe(self._place['index'])} lost ({error}) "
                    f"after {self.restarts} restarts; max_restarts is "
                    f"{self.max_restarts}"
                ) from None
            raise story
        self.restarts += 1
        reason = f"server lost ({error}); restarted ({self.restarts} of {self.max_restarts})"
        logger.warning("%s\n%s", reason, story)
        self.close()
        self._connect()
        for settings in self._configuration:
            self.client.configure(**settings)
        if self.on_restart is not None:
            self.on_restart()
        return reason

    def _connect(self) -> None:
        self.client, self.server = connect(**self._place)
        self._leased = self.server is not None and self.server in shared_servers  # release it

    @property
    def token(self) -> str | None:
        """The secret this session's servers need (``None``: none, or ``$RLENV_TOKEN``)."""
        return self._pool.token if self._pool is not None else self._place["token"]

    def failure(self, error: Exception) -> ConnectionLost:
        """``error`` as a ConnectionLost that says how the server exited, if it did."""
        return with_server_story(as_lost(error), [self.server] if self.server else [])

    def close(self) -> None:
        """Disconnect, and stop the server if this session started it."""
        self.client.close()
        if self._leased:
            self._leased = False
            shared_servers.release(self.server)  # type: ignore[arg-type]
        elif self.server is not None:
            self.server.close(timeout=1.0)


def as_lost(error: Exception) -> ConnectionLost:
    """A :data:`LOST` error as a ConnectionLost (a timeout keeps its message)."""
    return error if isinstance(error, ConnectionLost) else ConnectionLost(str(error))
