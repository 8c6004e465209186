"""The environment's TCP endpoint: socket I/O only; the protocol lives in :mod:`rlenv.protocol`.

An environment server is a network service and is treated like one:

- **One controller, several connections.** Up to :attr:`Limits.max_connections` clients may be
  connected; each is answered on its own connection, in arrival order, so a misbehaving client
  never disturbs another. The first client to send a request that changes the environment
  (``config``, ``reset`` or ``action``) controls it until it disconnects; such a request from
  anyone else gets a ``busy`` error reply (observing is open to all). A connection beyond the
  cap is told ``busy`` and closed, never silently queued.
- **Limits before allocation.** A frame's length is checked before its body is read: at most
  :attr:`Limits.max_unauthenticated_frame_size` bytes until the client has authenticated (or
  when no token is needed, until its first request), :attr:`Limits.max_frame_size` after.
- **Deadlines.** A frame that has started must complete within :attr:`Limits.frame_deadline`
  (a client that trickles bytes is dropped); a client silent between requests for
  :attr:`Limits.idle_timeout` is dropped; a write that cannot complete within
  :attr:`Limits.write_timeout` drops the client.
- **Access.** The server binds 127.0.0.1 unless told otherwise, and refuses to bind anything else
  without a token. With a token, the client's first request must carry it (compared in constant
  time), or the connection is refused.

A client that breaks the framing, times out or fails to authenticate gets one fatal error reply
and is disconnected; a client that sends a bad but well-framed request gets an error reply and
stays. Either way the endpoint keeps serving. Sockets: ``TCP_NODELAY``, one ``sendall`` per frame,
reads of at most 64 KiB, blocking waits in ``select`` (never busy-waiting).
"""

from __future__ import annotations

import hmac
import ipaddress
import logging
import os
import select
import selectors
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Protocol

from rlenv.errors import ErrorCode, LocalProtocolError, ProtocolError
from rlenv.protocol import (
    CONNECTION_CLOSED,
    DEFAULT_MAX_FRAME_SIZE,
    NEED_DATA,
    Connection,
    ErrorReply,
    Hello,
    Reply,
    Request,
    Response,
    Role,
)

__all__ = ["DEFAULT_HOST", "Communication", "Endpoint", "InsecureBindError", "Limits"]

logger = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"
_READ_SIZE = 64 * 1024
_PROBE_READS = 16


@dataclass(frozen=True)
class Limits:
    """How much and how long the endpoint tolerates from a client.

    Attributes:
        max_frame_size: largest request frame once the client is authenticated.
        max_unauthenticated_frame_size: largest frame before that (the first request).
        frame_deadline: seconds within which a frame, once started, must be complete.
        idle_timeout: seconds a client may stay silent between requests (``None``: forever).
        write_timeout: seconds a reply may take to be written.
        max_connections: clients connected at once.
    """

    max_frame_size: int = DEFAULT_MAX_FRAME_SIZE
    max_unauthenticated_frame_size: int = 64 * 1024
    frame_deadline: float = 10.0
    idle_timeout: float | None = 3600.0
    write_timeout: float = 10.0
    max_connections: int = 8


class InsecureBindError(RuntimeError):
    """Binding an address other than loopback was asked for without a token."""


class Endpoint(Protocol):
    """What an environment needs from its transport: requests in, answers out."""

    def poll(self, timeout: float | None) -> Request | None:
        """Wait up to ``timeout`` seconds (``None``: as long as it takes) for a request."""

    def send(self, message: Response | ErrorReply) -> None:
        """Answer the request being served."""

    def close(self) -> None:
        """Release the transport."""


class _Peer:
    __slots__ = ("address", "authenticated", "connection", "frame_started", "last_request",
                 "sock")

    def __init__(self, sock: socket.socket, address: str, max_frame_size: int,
                 now: float) -> None:
        self.sock = sock
        self.address = address
        self.connection = Connection(Role.SERVER, max_frame_size)
        self.authenticated = False
        self.last_request = now
        self.frame_started: float | None = None


class Communication:
    """Accepts the controlling client and moves frames between it and the environment.

    Args:
        hello: builds the hello sent to each client that connects.
        limits: sizes and deadlines; see :class:`Limits` (its defaults if ``None``).
        token: the secret the client's first request must carry (``None``: no token needed,
            only allowed on loopback addresses).
        clock: monotonic time in seconds (injectable for tests).
    """

    def __init__(
        self, hello: Callable[[], Hello], limits: Limits | None = None,
        token: str | None = None, clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._hello = hello
        self.limits = limits or Limits()
        self._token = token
        self._clock = clock
        self._selector = selectors.DefaultSelector()
        self._listener: socket.socket | None = None
        self._peers: dict[socket.socket, _Peer] = {}
        self._controller: _Peer | None = None
        self._serving: _Peer | None = None  # whose request the environment is answering
        self._turn = 0  # round robin over peers with buffered requests
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
        return self._controller.address if self._controller is not None else None

    @property
    def connections(self) -> int:
        """How many clients are connected."""
        return len(self._peers)

    def start_server(self, port: int = 0, host: str = DEFAULT_HOST) -> tuple[str, int]:
        """Listen on ``host:port`` (port 0 picks a free port) and return the bound address.

        Raises:
            InsecureBindError: ``host`` is not a loopback address and no token is set.
            OSError: the address cannot be bound.
        """
        if self._listener is not None:
            raise RuntimeError(f"already listening on {self.address}")
        if self._token is None and not _is_loopback(host):
            raise InsecureBindError(
                f"refusing to listen on {host}: anyone who can reach it could drive this "
                "environment. Set a token (rlenv serve --token, or RLENV_TOKEN) that clients "
                "must present, or bind 127.0.0.1"
            )
        listener = socket.create_server((host, port), backlog=16)
        listener.setblocking(False)
        self._listener = listener
        self._selector.register(listener, selectors.EVENT_READ)
        logger.info("listening on %s:%d%s", *self.address,
                    " (token required)" if self._token else "")
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

        Accepts connections, answers framing errors, bad requests, timeouts and failed
        authentication itself, and returns the first valid request of the controlling client,
        or ``None`` when the time is up.
        """
        deadline = None if timeout is None else self._clock() + timeout
        while True:
            request = self._next_request()
            if request is not None:
                return request
            now = self._clock()
            wake = self._next_wake(deadline)
            ready = {key.fileobj for key, _ in
                     self._selector.select(None if wake is None else max(0.0, wake - now))}
            for sock in [sock for sock in self._peers if sock in ready]:
                self._read(self._peers[sock])  # before accepting: a client may leave as one comes
            if self._listener in ready:
                self._accept()
            if self._lifeline is not None and self._lifeline in ready:
                self._check_lifeline(self._lifeline)
            self._enforce_deadlines()
            if deadline is not None and self._clock() >= deadline:
                return self._next_request()

    def send(self, message: Reply) -> None:
        """Answer the request being served, on its client's connection.

        A client that is gone is dropped; the answer is then discarded.
        """
        peer = self._serving
        if peer is None or peer.sock not in self._peers:
            logger.debug("no client to send %r to", message)
            return
        self._send_to(peer, message)

    def close(self) -> None:
        """Disconnect every client and stop listening."""
        for peer in list(self._peers.values()):
            self._drop(peer, "server closing")
        if self._listener is not None:
            self._selector.unregister(self._listener)
            self._listener.close()
            self._listener = None
        self._selector.close()

    # --- internals --------------------------------------------------------------------------

    def _accept(self) -> None:
        """Accept every pending connection."""
        assert self._listener is not None
        while True:
            try:
                sock, address = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            self._admit(sock, address)

    def _admit(self, sock: socket.socket, address: tuple[str, int]) -> None:
        address_text = f"{address[0]}:{address[1]}"
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(self.limits.write_timeout)
        peer = _Peer(sock, address_text, self.limits.max_unauthenticated_frame_size,
                     self._clock())
        if len(self._peers) >= self.limits.max_connections:
            for other in list(self._peers.values()):
                if self._has_left(other):
                    self._drop(other, "client closed the connection")
        if len(self._peers) >= self.limits.max_connections:
            logger.info("refused %s: %d clients connected", address_text, len(self._peers))
            self._send_to(peer, ErrorReply(
                None, ErrorCode.BUSY, f"this server already has {len(self._peers)} clients "
                "connected, its limit; close one or start another server", fatal=True))
            return
        self._peers[sock] = peer
        self._selector.register(sock, selectors.EVENT_READ)
        logger.info("client %s connected", address_text)
        hello = self._hello()
        if self._token is not None:
            hello = replace(hello, token_required=True)
        self._write(peer, peer.connection.send(hello))

    def _next_wake(self, deadline: float | None) -> float | None:
        """The earliest of the caller's deadline and every peer's frame and idle deadlines."""
        times = [] if deadline is None else [deadline]
        times += [due for peer in self._peers.values()
                  if (due := self._peer_deadline(peer)) is not None]
        return min(times, default=None)

    def _peer_deadline(self, peer: _Peer) -> float | None:
        """When ``peer`` times out: its frame's deadline while a frame arrives, else idling's."""
        if peer.frame_started is not None:
            return peer.frame_started + self.limits.frame_deadline
        if self.limits.idle_timeout is not None:
            return peer.last_request + self.limits.idle_timeout
        return None

    def _enforce_deadlines(self) -> None:
        now = self._clock()
        for peer in list(self._peers.values()):
            due = self._peer_deadline(peer)
            if due is None or now < due:
                continue
            if peer.frame_started is not None:
                message = (f"a frame was not completed within {self.limits.frame_deadline} s "
                           f"({peer.connection.buffered} bytes received); is the client stalled?")
            else:
                message = f"no request for {self.limits.idle_timeout} s"
            logger.info("client %s timed out: %s", peer.address, message)
            self._send_to(peer, ErrorReply(None, ErrorCode.TIMEOUT, message, fatal=True),
                          "timed out")

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
        """The next valid request of any peer, taking peers in turn."""
        peers = list(self._peers.values())
        for offset in range(len(peers)):
            peer = peers[(self._turn + offset) % len(peers)]
            request = self._request_from(peer)
            if request is not None:
                self._turn = (self._turn + offset + 1) % len(peers)
                self._serving = peer
                return request
        return None

    def _request_from(self, peer: _Peer) -> Request | None:
        """``peer``'s next valid request; answers its bad frames and refusals on the way."""
        while peer.sock in self._peers:
            try:
                message = peer.connection.next_message()
            except ProtocolError as error:
                logger.info("client %s: %s", peer.address, error)
                peer.frame_started = None
                self._send_to(peer, ErrorReply(error.request_id, error.code, str(error),
                                               fatal=error.fatal), "broken framing")
                continue
            if message is NEED_DATA:
                if peer.connection.buffered and peer.frame_started is None:
                    peer.frame_started = self._clock()
                return None
            if message is CONNECTION_CLOSED:
                self._drop(peer, "client closed the connection")
                return None
            assert isinstance(message, Request)
            peer.frame_started = None
            peer.last_request = self._clock()
            if not peer.authenticated and not self._authenticate(peer, message):
                continue
            if _controls(message) and not self._take_control(peer, message):
                continue
            return message
        return None

    def _take_control(self, peer: _Peer, request: Request) -> bool:
        """Make ``peer`` the controller if nobody is; otherwise answer ``busy``."""
        controller = self._controller
        if controller is not None and controller is not peer and self._has_left(controller):
            self._drop(controller, "client closed the connection")
            controller = None
        if controller is None:
            self._controller = peer
            logger.info("client %s controls the environment", peer.address)
            return True
        if controller is peer:
            return True
        self._send_to(peer, ErrorReply(
            request.id, ErrorCode.BUSY,
            f"this environment is controlled by another client ({controller.address}); only "
            "observing is open to others. Start another server for another trainer",
        ))
        return False

    def _authenticate(self, peer: _Peer, request: Request) -> bool:
        """Check the first request's token; on success lift the frame size limit."""
        if self._token is not None and not (
            request.token is not None
            and hmac.compare_digest(request.token.encode(), self._token.encode())
        ):
            logger.warning("client %s: refused, %s token", peer.address,
                           "no" if request.token is None else "wrong")
            self._send_to(peer, ErrorReply(
                request.id, ErrorCode.UNAUTHORIZED,
                "this server requires a token: pass token=... to the client (or set RLENV_TOKEN)"
                if request.token is None else "wrong token", fatal=True,
            ))
            return False
        peer.authenticated = True
        peer.connection.max_frame_size = self.limits.max_frame_size
        return True

    def _send_to(self, peer: _Peer, message: Reply,
                 why_fatal: str = "error reply closed the connection") -> None:
        """Send ``message``; a fatal error reply then closes the connection (``why_fatal``)."""
        try:
            self._write(peer, peer.connection.send(message))
        except LocalProtocolError as error:  # e.g. the client hung up in the middle of a frame
            logger.warning("not sent to %s: %s", peer.address, error)
        if message.__class__ is ErrorReply and message.fatal:
            self._drop(peer, why_fatal)

    def _write(self, peer: _Peer, data: bytes) -> None:
        try:
            peer.sock.sendall(data)
        except OSError as error:
            logger.info("client %s: send failed: %s", peer.address, error)
            self._drop(peer, "send failed")

    def _drop(self, peer: _Peer, reason: str) -> None:
        if self._peers.pop(peer.sock, None) is not None:
            self._selector.unregister(peer.sock)
            logger.info("client %s disconnected: %s", peer.address, reason)
        if self._controller is peer:
            self._controller = None
        peer.sock.close()


def _controls(request: Request | None) -> bool:
    """Whether ``request`` changes the environment (only its controller may send those)."""
    if request is None:
        return False
    if request.batch is not None:
        return any(_controls(part) for part in request.batch)
    return (request.config is not None or request.reset is not None
            or request.action is not None or request.restore is not None
            or request.steps is not None
            or (request.inspect is not None and "set" in request.inspect))


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
