"""A deadline on every request head, and a bound on open connections.

uvicorn times out idle keep-alive connections, but not a request head that never ends: a
connection that sent ``GET / HTTP/1.1`` and nothing more was kept forever, and 300 of them
kept every real request out of a gateway limited to 256 open files.
:func:`bounded_protocol` gives uvicorn's protocol (see :mod:`rlenv.http.writes`) two rules:

- a connection must complete its request head within ``head_timeout`` seconds of connecting,
  or of sending the first bytes of its next request; else it is closed;
- at most ``max_connections`` are open: a connection beyond that closes the oldest one still
  waiting for its head (else, every one being busy with a request, it is itself closed at
  once), so that real requests get in while unfinished heads pile up.

Each request head starts a new request cycle (``self.cycle``, in uvicorn's httptools and h11
protocols alike): a deadline finds the cycle unchanged when no head completed since it was set.
"""

from __future__ import annotations

import asyncio
from typing import Any

__all__ = ["bounded_protocol"]


def bounded_protocol(base: type[Any], *, head_timeout: float,
                     max_connections: int) -> type[asyncio.Protocol]:
    """The protocol ``base`` (uvicorn's) with the two rules of the module docstring."""

    class BoundedProtocol(base):  # type: ignore[valid-type,misc]
        _head_deadline: asyncio.TimerHandle | None = None
        _head_cycle: object = None
        _head_since = 0.0
        _between_requests = False

        def connection_made(self, transport: asyncio.BaseTransport) -> None:  # type: ignore[override]
            super().connection_made(transport)
            self._arm()
            if len(self.connections) > max_connections:
                waiting = [c for c in self.connections if c is not self and c._awaiting_head()]
                (min(waiting, key=lambda c: c._head_since) if waiting else self)._close()

        def data_received(self, data: bytes) -> None:
            if self._between_requests:  # the first bytes of the next request
                self._between_requests = False
                self._arm()
            super().data_received(data)

        def on_response_complete(self) -> None:
            super().on_response_complete()
            self._between_requests = True  # uvicorn's keep-alive timeout governs until then
            self._disarm()

        def handle_websocket_upgrade(self, *event: Any) -> None:
            self._disarm()  # the WebSocket's own protocol owns the connection from now on
            super().handle_websocket_upgrade(*event)

        def connection_lost(self, exc: Exception | None) -> None:
            self._disarm()
            super().connection_lost(exc)

        def _arm(self) -> None:
            self._disarm()
            self._head_cycle = self.cycle
            self._head_since = self.loop.time()
            self._head_deadline = self.loop.call_later(head_timeout, self._head_late)

        def _disarm(self) -> None:
            if self._head_deadline is not None:
                self._head_deadline.cancel()
                self._head_deadline = None

        def _awaiting_head(self) -> bool:
            return self._head_deadline is not None and self.cycle is self._head_cycle

        def _head_late(self) -> None:
            self._head_deadline = None
            if self.cycle is self._head_cycle:  # no request head completed in time
                self._close()

        def _close(self) -> None:
            self._disarm()
            self.transport.close()

    BoundedProtocol.__name__ = BoundedProtocol.__qualname__ = f"Bounded{base.__name__}"
    return BoundedProtocol
