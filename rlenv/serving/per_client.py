"""A server whose every client gets an environment of its own (``rlenv serve --per-client``).

Several environments a trainer makes one by one (``gymnasium.make`` in a loop, SB3's
``make_vec_env``, CleanRL's ``SyncVectorEnv``) step one after the other. With a server each,
every step wakes another process; here they share one, which stays awake between them. Each
connection gets a :class:`~rlenv.serving._host.Host` of its own, built when the client's first
request comes and closed when the client leaves: the client controls it alone, and sees the
same hello, answers and errors as from a server of its own. Only the process is shared: what
one client's environment does to the process (a crash, a loop) its neighbours feel.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from rlenv.protocol import ErrorReply, Request
from rlenv.protocol.errors import ErrorCode
from rlenv.serving._endpoint import Endpoint, Peer
from rlenv.serving._host import Host

__all__ = ["HostPerClient"]

logger = logging.getLogger(__name__)


class HostPerClient:
    """A :class:`Host` per client connection, each built by ``build``.

    Args:
        build: makes a host (the environment's instances, in trees of their own), with its
            driven agents if any (``rlenv serve --per-client --policy NAME=...``: each
            client's environment drives its own ``NAME``).

    Raises:
        ValueError: the hosts' policies drive every agent (no client could control one).

    Attributes:
        hello: what every client is told (the first host's: every host says the same).
    """

    def __init__(self, build: Callable[[], Host]) -> None:
        self._build = build
        self._spare: Host | None = build()  # proves the environment loads; the first client's
        if self._spare.driver is not None:
            self._spare.close()
            raise ValueError(
                "--policy drives every agent, so the server plays its episodes "
                "itself and no client controls them: leave out --per-client, or "
                "drive fewer agents"
            )
        self.hello = self._spare.hello
        self._hosts: dict[Peer, Host] = {}

    @property
    def hosts(self) -> list[Host]:
        """The hosts of the clients connected now."""
        return list(self._hosts.values())

    def serve_forever(self, endpoint: Endpoint) -> None:
        """Answer every client's requests with its own host, until interrupted."""
        endpoint.on_drop = self._dropped
        while True:
            got = endpoint.receive(self._time_to_next_tick())
            if got is None:
                for each in self._hosts.values():
                    each.catch_up()
                continue
            peer, request = got
            host = self._hosts.get(peer) or self._seat(endpoint, peer, request)
            if host is not None:
                host.handle(endpoint, peer, request)

    def _seat(self, endpoint: Endpoint, peer: Peer, request: Request) -> Host | None:
        """The new client's host; ``None`` (the client told why) if none could be built."""
        try:
            host = self._spare or self._build()
        except Exception as error:  # the environment failed to build: this client is told
            logger.exception("no environment for client %s", peer.address)
            endpoint.reply(
                peer,
                ErrorReply(
                    request.id,
                    ErrorCode.ENVIRONMENT_ERROR,
                    f"the server could not build an environment for this client: {error}",
                    fatal=True,
                ),
            )
            return None
        self._spare = None
        self._hosts[peer] = host
        logger.info(
            "client %s has an environment of its own (%d clients)", peer.address, len(self._hosts)
        )
        return host

    def _dropped(self, peer: Peer) -> None:
        host = self._hosts.pop(peer, None)
        if host is not None:
            host.close()

    def _time_to_next_tick(self) -> float | None:
        waits = [
            wait for host in self._hosts.values() if (wait := host.time_to_next_tick()) is not None
        ]
        return min(waits, default=None)

    def close(self) -> None:
        """Close every client's environment."""
        for host in [*self._hosts.values(), *([self._spare] if self._spare else [])]:
            host.close()
        self._hosts.clear()
        self._spare = None
