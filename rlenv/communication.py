"""The environment's TCP endpoint: socket I/O only; the protocol lives in :mod:`rlenv.protocol`.

One client at a time controls an environment. A second client that connects meanwhile is told
``busy`` (a fatal error reply) and disconnected, never silently queued. A client that breaks
the framing gets a fatal error reply and is disconnected; a client that sends a bad but
well-framed request gets an error reply and stays. Either way the endpoint keeps serving.

Sockets: ``TCP_NODELAY``, one ``sendall`` per frame (header and body together), reads of at most
64 KiB, and blocking waits in ``select`` (never busy-waiting).
"""

from __future__ import annotations

import logging
import os
import select
import selectors
import socket
import time
from collections.abc import Callable
from typing import Protocol

from rlenv.errors import ErrorCode, LocalProtocolError, ProtocolError
from rlenv.protocol import (
    CONNECTION_CLOSED,
    DEFAULT_MAX_FRAME_SIZE,
    NEED_DATA,
    Connection,
    ErrorReply,
    Hello,
    Request,
    Response,
    Role,
)

__all__ = ["DEFAULT_HOST", "Communication", "Endpoint"]

logger = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"
_READ_SIZE = 64 * 1024
_WRITE_TIMEOUT = 10.0
_PROBE_READS = 16


class Endpoint(Protocol):
    """What an environment needs from its transport: requests in, answers out."""

    def poll(self, timeout: float | None) -> Request | None:
        """Wait up to ``timeout`` seconds (``None``: as long as it takes) for a request."""

    def send(self, message: Response | ErrorReply) -> None:
        """Answer the request being served."""

    def close(self) -> None:
        """Release the transport."""


class _Peer:
    __slots__ = ("address", "connection", "sock")

    def __init__(self, sock: socket.socket, address: str, max_frame_size: int) -> None:
        self.sock = sock
        self.address = address
        self.connection = Connection(Role.SERVER, max_frame_size)


class Communication:
    """Accepts the controlling client and moves frames between it and the environment.

    Args:
        hello: builds the hello sent to each client that connects.
        max_frame_size: largest request frame accepted.
    """

    def __init__(
        self, hello: Callable[[], Hello], max_frame_size: int = DEFAULT_MAX_FRAME_SIZE
    ) -> None:
        self._hello = hello
        self._max_frame_size = max_frame_size
        self._selector = selectors.DefaultSelector()
        self._listener: socket.socket | None = None
        self._peer: _Peer | None = None
        self._lifeline: int | None = None

    @property
    def is_listening(self) -> bool:
        """Whether :meth:`start_server` was called and :meth:`close` was not."""
        return self._listener is not None

    @property
    def address(self) -> tuple[str, int]:
        """The (host, port) the server listens on.

        Raises:
            RuntimeError: the server is not listening.
        """
        if self._listener is None:
            raise RuntimeError("the server is not listening; call start_server first")
        host, port = self._listener.getsockname()[:2]
        return host, port

    @property
    def client_address(self) -> str | None:
        """``host:port`` of the controlling client, or ``None``."""
        return self._peer.address if self._peer is not None else None

    def start_server(self, port: int = 0, host: str = DEFAULT_HOST) -> tuple[str, int]:
        """Listen on ``host:port`` (port 0 picks a free port) and return the bound address.

        Raises:
            OSError: the address cannot be bound.
        """
        if self._listener is not None:
            raise RuntimeError(f"already listening on {self.address}")
        listener = socket.create_server((host, port), backlog=16)
        listener.setblocking(False)
        self._listener = listener
        self._selector.register(listener, selectors.EVENT_READ)
        logger.info("listening on %s:%d", *self.address)
        return self.address

    def watch_lifeline(self, fd: int) -> None:
        """Exit (``SystemExit``) when the pipe ``fd`` reaches end of file.

        ``fd`` is the read end of a pipe whose write end only the process that started this
        server holds: end of file means that process is gone.
        """
        self._lifeline = fd
        self._selector.register(fd, selectors.EVENT_READ)

    def poll(self, timeout: float | None) -> Request | None:
        """Wait up to ``timeout`` seconds (``None``: forever) for the next request.

        Accepts connections, answers framing errors and bad requests itself, and returns the
        first valid request of the controlling client, or ``None`` when the time is up.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            request = self._next_request()
            if request is not None:
                return request
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready = {key.fileobj for key, _ in self._selector.select(remaining)}
            if self._peer is not None and self._peer.sock in ready:
                self._read(self._peer)  # before accepting: a client may leave as another comes
            if self._listener in ready:
                self._accept()
            if self._lifeline is not None and self._lifeline in ready:
                self._check_lifeline(self._lifeline)
            if deadline is not None and time.monotonic() >= deadline:
                return self._next_request()

    def send(self, message: Response | ErrorReply) -> None:
        """Send ``message`` to the controlling client; a client that is gone is dropped."""
        peer = self._peer
        if peer is None:
            logger.debug("no client to send %r to", message)
            return
        try:
            data = peer.connection.send(message)
        except LocalProtocolError as error:
            logger.warning("not sent to %s: %s", peer.address, error)
            return
        self._write(peer, data)
        if message.__class__ is ErrorReply and message.fatal:
            self._drop(peer, "error reply closed the connection")

    def close(self) -> None:
        """Disconnect the client and stop listening."""
        if self._peer is not None:
            self._drop(self._peer, "server closing")
        if self._listener is not None:
            self._selector.unregister(self._listener)
            self._listener.close()
            self._listener = None
        self._selector.close()

    # --- internals --------------------------------------------------------------------------

    def _accept(self) -> None:
        assert self._listener is not None
        try:
            sock, address = self._listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        address_text = f"{address[0]}:{address[1]}"
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(_WRITE_TIMEOUT)
        peer = _Peer(sock, address_text, self._max_frame_size)
        if self._peer is not None and self._has_left(self._peer):
            self._drop(self._peer, "client closed the connection")
        if self._peer is not None:
            logger.info("refused %s: busy with %s", address_text, self._peer.address)
            reply = ErrorReply(
                None,
                ErrorCode.BUSY,
                f"this environment is controlled by another client ({self._peer.address}); "
                "start another server for another client",
                fatal=True,
            )
            self._write(peer, peer.connection.send(reply), register=False)
            sock.close()
            return
        self._peer = peer
        self._selector.register(sock, selectors.EVENT_READ)
        logger.info("client %s connected", address_text)
        self._write(peer, peer.connection.send(self._hello()))

    def _check_lifeline(self, fd: int) -> None:
        if not os.read(fd, 4096):
            logger.warning("the process that started this server is gone; exiting")
            raise SystemExit(0)

    def _has_left(self, peer: _Peer) -> bool:
        """Whether ``peer`` closed its end; reads what it sent meanwhile (without blocking)."""
        for _ in range(_PROBE_READS):
            if peer.connection.peer_closed or not select.select([peer.sock], [], [], 0)[0]:
                break
            self._read(peer)
        return peer.connection.peer_closed

    def _read(self, peer: _Peer) -> None:
        try:
            data = peer.sock.recv(_READ_SIZE)
        except (BlockingIOError, InterruptedError, TimeoutError):
            return
        except OSError as error:
            logger.info("client %s: %s", peer.address, error)
            data = b""
        peer.connection.receive_data(data)

    def _next_request(self) -> Request | None:
        while (peer := self._peer) is not None:
            try:
                message = peer.connection.next_message()
            except ProtocolError as error:
                logger.info("client %s: %s", peer.address, error)
                self.send(ErrorReply(error.request_id, error.code, str(error), fatal=error.fatal))
                if error.fatal and self._peer is peer:
                    self._drop(peer, "broken framing")
                continue
            if message is NEED_DATA:
                return None
            if message is CONNECTION_CLOSED:
                self._drop(peer, "client closed the connection")
                return None
            assert isinstance(message, Request)
            return message
        return None

    def _write(self, peer: _Peer, data: bytes, register: bool = True) -> None:
        try:
            peer.sock.sendall(data)
        except OSError as error:
            logger.info("client %s: send failed: %s", peer.address, error)
            if register:
                self._drop(peer, "send failed")

    def _drop(self, peer: _Peer, reason: str) -> None:
        if self._peer is peer:
            self._peer = None
            self._selector.unregister(peer.sock)
        peer.sock.close()
        logger.info("client %s disconnected: %s", peer.address, reason)
