"""How the gateway reaches below uvicorn's public API, in one place, on tested versions only.

uvicorn's HTTP protocols (httptools and h11) are subclassed for two things its configuration
does not offer:

- **One write per response** (:class:`_OneWrite`). uvicorn writes a response's head when the
  application starts it and its body when the application sends it: two ``write`` system calls,
  two TCP segments, two wake-ups of the client for one answer. On the development VM a write to
  a loopback socket cost tens of microseconds, as much as the rest of the HTTP layer. The
  protocol gets a transport that gathers what is written during one step of the event loop and
  sends it at the end of that step, in one write: a head and its body, or a WebSocket's frames.
  Closing sends what is pending first. Connections also set ``TCP_NODELAY`` (see
  :func:`rlenv_tools.http.app.serve`), so a stream's later writes never wait for an acknowledgement.
- **A deadline on every request head, and a bound on open connections** (:func:`_bounded`).
  uvicorn times out idle keep-alive connections, but not a request head that never ends: a
  connection that sent ``GET / HTTP/1.1`` and nothing more was kept forever, and 300 of them
  kept every real request out of a gateway limited to 256 open files. So a connection must
  complete its request head within ``head_timeout`` seconds of connecting, or of sending the
  first bytes of its next request, else it is closed; and at most ``max_connections`` are
  open: a connection beyond that closes the oldest one still waiting for its head (else, every
  one being busy with a request, it is itself closed at once), so that real requests get in
  while unfinished heads pile up. Each request head starts a new request cycle (``self.cycle``,
  in uvicorn's httptools and h11 protocols alike): a deadline finds the cycle unchanged when no
  head completed since it was set.

Both rely on uvicorn's internals (``connection_made``, ``cycle``, ``connections``,
``on_response_complete``...), which change between releases: they are taken only on the
versions the tests passed on, :data:`TESTED`. On any other, :func:`http_protocol` gives
uvicorn's own protocol and :func:`connection_limit` uvicorn's public ``limit_concurrency``
(beyond it, uvicorn answers 503): two writes per response, and no deadline on request heads,
which a warning says once.
"""

from __future__ import annotations

import asyncio
import importlib.util
import logging
from typing import Any

import uvicorn

__all__ = ["FAST", "TESTED", "connection_limit", "http_protocol"]

logger = logging.getLogger(__name__)

TESTED = ((0, 30, 0), (0, 54, 0))
"""The first and last uvicorn versions whose protocols this module was tested with."""


def _version(text: str) -> tuple[int, ...]:
    return tuple(int(part) for part in text.split(".")[:3] if part.isdigit())


FAST = TESTED[0] <= _version(uvicorn.__version__) <= TESTED[1]
"""Whether uvicorn's protocols are subclassed (its version is in :data:`TESTED`)."""


def http_protocol(http: str, *, head_timeout: float, max_connections: int) -> type | str:
    """What ``uvicorn.Config(http=...)`` takes, for uvicorn's protocol ``http``.

    ``http`` is ``auto``, ``httptools`` or ``h11``; the protocol writes once a step, with the
    head deadline and the connection bound; on a version not in :data:`TESTED`, uvicorn's own
    ``http``.

    Raises:
        ValueError: an unknown implementation.
    """
    if http == "auto":
        http = "httptools" if importlib.util.find_spec("httptools") else "h11"
    if http not in ("httptools", "h11"):
        raise ValueError(f"unknown HTTP implementation {http!r}: auto, httptools or h11")
    if not FAST:
        logger.warning(
            "uvicorn %s is not a version rlenv was tested with (%s to %s): responses "
            "take two writes, and request heads have no deadline",
            uvicorn.__version__,
            *(".".join(map(str, v)) for v in TESTED),
        )
        return http
    if http == "httptools":
        from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol as base
    else:
        from uvicorn.protocols.http.h11_impl import H11Protocol as base  # type: ignore[assignment]
    return _bounded(_one_write(base), head_timeout=head_timeout, max_connections=max_connections)


def connection_limit(max_connections: int) -> int | None:
    """What ``uvicorn.Config(limit_concurrency=...)`` takes.

    None where :func:`http_protocol` bounds connections itself, else uvicorn's public bound.
    """
    return None if FAST else max_connections


class _OneWrite:
    """A transport whose writes within one event loop step leave in one system call."""

    def __init__(self, transport: asyncio.Transport) -> None:
        self._transport = transport
        self._pending: list[bytes] = []
        self._loop = asyncio.get_running_loop()

    def write(self, data: bytes | bytearray | memoryview) -> None:
        """Queue ``data``; it leaves with the step's other writes."""
        if not self._pending:
            self._loop.call_soon(self._flush)
        self._pending.append(bytes(data))

    def writelines(self, lines: Any) -> None:
        """Queue every line."""
        for line in lines:
            self.write(line)

    def _flush(self) -> None:
        if self._pending:
            data = b"".join(self._pending)
            self._pending.clear()
            if not self._transport.is_closing():
                self._transport.write(data)

    def close(self) -> None:
        """Send what is pending, then close."""
        self._flush()
        self._transport.close()

    def write_eof(self) -> None:
        """Send what is pending, then end the stream."""
        self._flush()
        self._transport.write_eof()

    def abort(self) -> None:
        """Drop what is pending and the connection."""
        self._pending.clear()
        self._transport.abort()

    def __getattr__(self, name: str) -> Any:  # the rest of the transport, as it is
        return getattr(self._transport, name)


def _one_write(base: type[Any]) -> type[asyncio.Protocol]:
    """Uvicorn's protocol ``base``, its writes within one event loop step sent at once."""

    class OneWriteProtocol(base):
        def connection_made(self, transport: asyncio.BaseTransport) -> None:
            super().connection_made(_OneWrite(transport))  # type: ignore[arg-type]

    OneWriteProtocol.__name__ = OneWriteProtocol.__qualname__ = f"OneWrite{base.__name__}"
    return OneWriteProtocol


def _bounded(
    base: type[Any], *, head_timeout: float, max_connections: int
) -> type[asyncio.Protocol]:
    """The protocol ``base`` (uvicorn's) with the head deadline and the connection bound."""

    class BoundedProtocol(base):
        _head_deadline: asyncio.TimerHandle | None = None
        _head_cycle: object = None
        _head_since = 0.0
        _between_requests = False

        def connection_made(self, transport: asyncio.BaseTransport) -> None:
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
