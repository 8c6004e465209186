"""The server's TCP endpoint: socket I/O only; the protocol lives in :mod:`rlenv.protocol`.

An environment server is a network service and is treated like one:

- **One controller, several connections.** Up to :attr:`Limits.max_connections` clients may be
  connected; each is answered on its own connection, in arrival order, so a misbehaving client
  never disturbs another. The first client whose accepted request changes the environment
  controls it until it disconnects (:meth:`Endpoint.take_control`; which requests change it is
  the host's call, and a refused request takes no control); such a request from anyone else
  gets a ``busy`` error reply. A connection beyond the cap is told ``busy`` and closed, never
  silently queued.
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

**The hot path.** While the controller keeps sending, the endpoint blocks in ``recv`` on the
controller's socket alone (one system call per request, no selector); the others (new
connections, observers, the lifeline, deadlines) are looked after every
:data:`HOUSEKEEPING_INTERVAL` seconds, and at once whenever the controller pauses that long.
Sockets stay in blocking mode; the kernel enforces their timeouts (``SO_RCVTIMEO``,
``SO_SNDTIMEO``), so Python never polls before a read or a write. A controller with a
shared-memory lane (:mod:`rlenv.protocol.lanes`) is waited for on its lane and its socket
together; requests taken from a lane go through the same door, and their answers back into the
lane when they fit (else on the socket). Frames are sent with one
``sendall`` (``TCP_NODELAY``), read at most 64 KiB at a time.
"""

from __future__ import annotations

import errno
import hmac
import logging
import os
import select
import selectors
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

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
from rlenv.protocol.errors import ErrorCode, LocalProtocolError, ProtocolError
from rlenv.protocol.lanes import Lane, LaneClosed, open_lane, wait_for
from rlenv.protocol.sockets import (
    REQUEST_SPIN_WINDOW,
    AnswerWaiter,
    configure_socket,
    is_loopback,
)

__all__ = ["DEFAULT_HOST", "HOUSEKEEPING_INTERVAL", "Endpoint", "InsecureBindError", "Limits",
           "Peer"]

logger = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"
HOUSEKEEPING_INTERVAL = 0.01
"""Seconds between looks at everything but the controller while the controller is busy."""
_READ_SIZE = 64 * 1024
_PROBE_READS = 16


@dataclass(frozen=True)
class Limits:
    """How much and how long the endpoint tolerates from a client.

    Attributes:
        max_frame_size: largest request frame once the client is authenticated.
        max_unauthenticated_frame_size: largest frame before that (the first request); never
            more than ``max_frame_size`` (see :attr:`max_first_frame_size`).
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

    @property
    def max_first_frame_size(self) -> int:
        """The largest frame before the first request: the smaller of the two limits."""
        return min(self.max_unauthenticated_frame_size, self.max_frame_size)

    def to_wire(self) -> dict[str, Any]:
        """The limits as the hello announces them (see :class:`rlenv.protocol.Hello`)."""
        return {"max_frame_size": self.max_frame_size,
                "max_first_frame_size": self.max_first_frame_size,
                "max_reply_size": DEFAULT_MAX_FRAME_SIZE,
                "frame_deadline": self.frame_deadline, "idle_timeout": self.idle_timeout,
                "write_timeout": self.write_timeout, "max_connections": self.max_connections}


class InsecureBindError(RuntimeError):
    """Binding an address other than loopback was asked for without a token."""


class Peer:
    """One connected client, as the endpoint sees it.

    Attributes:
        lane: its shared-memory lane (:mod:`rlenv.protocol.lanes`), if it asked for one.
        lane_kind: the kind of the request taken from the lane and not answered yet (0: none).
    """

    __slots__ = ("active", "address", "authenticated", "connection", "frame_started",
                 "lane", "lane_kind", "lane_seen", "last_request", "sock", "waiter")

    def __init__(self, sock: socket.socket, address: str, max_frame_size: int,
                 now: float) -> None:
        self.sock = sock
        self.address = address
        self.connection = Connection(Role.SERVER, max_frame_size)
        self.authenticated = False
        self.last_request = now
        self.frame_started: float | None = None
        self.active = False  # sending requests back to back: worth blocking on alone
        self.waiter = AnswerWaiter(window=REQUEST_SPIN_WINDOW)  # its next request
        self.lane: Lane | None = None
        self.lane_kind = 0
        self.lane_seen = 0  # the lane's request sequence number last taken

    def lane_ready(self) -> bool:
        """Whether the lane holds a request not taken yet."""
        return self.lane is not None and self.lane.slots.request_sequence != self.lane_seen


class Endpoint:
    """Accepts clients and moves frames between them and the host.

    Args:
        hello: what each client is told on connecting (``None``: set :attr:`hello` before
            serving; a self-hosting environment binds before its hello is known).
        limits: sizes and deadlines; see :class:`Limits` (its defaults if ``None``).
        token: the secret the client's first request must carry (``None``: no token needed,
            only allowed on loopback addresses).
        clock: monotonic time in seconds (injectable for tests).
    """

    def __init__(
        self, hello: Hello | None, limits: Limits | None = None, token: str | None = None,
        clock: Callable[[], float] = time.monotonic, per_client: bool = False,
    ) -> None:
        self.limits = limits or Limits()
        self.per_client = per_client
        self.on_drop: Callable[[Peer], None] | None = None
        self._waiter = AnswerWaiter(window=REQUEST_SPIN_WINDOW)
        self._spin_poll = select.poll()
        self._by_fd: dict[int, Peer] = {}
        self._token = token
        self._hello: Hello | None = None
        if hello is not None:
            self.hello = hello
        self._clock = clock
        self._selector = selectors.DefaultSelector()
        self._listener: socket.socket | None = None
        self._peers: dict[socket.socket, Peer] = {}
        self._order: list[Peer] = []  # the peers, in turn order
        self._controller: Peer | None = None
        self._turn = 0  # round robin over peers with buffered requests
        self._lifeline: int | None = None
        self._housekeeping_at = 0.0
        self._backlog = False  # frames may be buffered on other peers than the controller

    @property
    def hello(self) -> Hello | None:
        """What each client is told on connecting (with the token rule and the limits)."""
        return self._hello

    @hello.setter
    def hello(self, hello: Hello) -> None:
        self._hello = replace(hello, token_required=hello.token_required or
                              self._token is not None, limits=self.limits.to_wire())

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
    def connections(self) -> int:
        """How many clients are connected."""
        return len(self._peers)

    def start_server(self, port: int = 0, host: str = DEFAULT_HOST) -> tuple[str, int]:
        """Listen on ``host:port`` (port 0 picks a free port) and return the bound address.

        Raises:
            ValueError: ``port`` is not in 0..65535.
            InsecureBindError: ``host`` is not a loopback address and no token is set.
            OSError: the address cannot be bound; the message says why first ("port 4000 is
                in use on 127.0.0.1 ...").
        """
        if self._listener is not None:
            raise RuntimeError(f"already listening on {self.address}")
        if type(port) is not int or not 0 <= port <= 65535:
            raise ValueError(f"port must be an integer from 0 to 65535, got {port!r:.40}")
        if self._token is None and not is_loopback(host):
            raise InsecureBindError(
                f"refusing to listen on {host}: anyone who can reach it could drive this "
                "environment. Set a token (rlenv serve --token, or RLENV_TOKEN) that clients "
                "must present, or bind 127.0.0.1"
            )
        try:
            listener = socket.create_server((host, port), backlog=16)
        except OSError as error:
            raise _bind_error(error, host, port) from None
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

    def receive(self, timeout: float | None) -> tuple[Peer, Request] | None:
        """Wait up to ``timeout`` seconds (``None``: as long as it takes) for the next request.

        Accepts connections, answers framing errors, bad envelopes, timeouts and failed
        authentication itself, and returns the next request to answer with its peer, or
        ``None`` when the time is up.
        """
        deadline = None if timeout is None else self._clock() + timeout
        while True:
            if self._backlog:  # frames read while looking around: served in turn first
                got = self._next_request()
                if got is not None:
                    return got
            controller = self._controller
            if deadline is None and controller is not None and controller.active and \
                    self._clock() < self._housekeeping_at:
                if not controller.connection.buffered and not controller.lane_ready():
                    self._read(controller, block=True)  # nothing pipelined: wait for it
                request = self._request_from(controller)
                if request is not None:
                    if controller.connection.buffered:  # pipelined: more may be whole already
                        self._backlog = True
                    return controller, request
                continue
            if self.per_client and deadline is None and self._clock() < self._housekeeping_at:
                got = self._spin_for_request()
                if got is not None:
                    return got
            self._wait(deadline)
            if deadline is not None and self._clock() >= deadline:
                return self._next_request()

    def _spin_for_request(self) -> tuple[Peer, Request] | None:
        peers = [peer for peer in self._order if peer.lane is not None]
        poll, by_fd = self._spin_poll.poll, self._by_fd

        def attempt() -> Peer | None:
            for peer in peers:
                if peer.lane_ready():
                    return peer
            ready = poll(0)
            return by_fd[ready[0][0]] if ready else None

        waiter = self._waiter
        peer = waiter.spin(attempt)
        waiter.ended()
        if peer is None:
            return None
        if not peer.lane_ready():
            self._read(peer, block=False)
            self._backlog = False
        request = self._request_from(peer)
        if request is None:
            return None
        if peer.connection.buffered:
            self._backlog = True
        return peer, request

    def reply(self, peer: Peer, message: Reply) -> None:
        """Send ``peer`` the answer to its oldest request (dropped if the client is gone)."""
        if peer.sock in self._peers:
            self._send(peer, message)

    def controls(self, peer: Peer) -> bool:
        """Whether ``peer`` controls the environment."""
        return self.per_client or peer is self._controller

    def take_control(self, peer: Peer, request_id: int) -> bool:
        """Let ``peer``'s request change the environment, if ``peer`` may.

        The first client to ask controls the environment until it leaves; anyone else is
        answered ``busy`` (and this returns False).
        """
        controller = self._controller
        if controller is peer or self.per_client:
            return True
        if controller is not None and self._has_left(controller):
            self._drop(controller, "client closed the connection")
            controller = None
        if controller is None:
            self._controller = peer
            logger.info("client %s controls the environment", peer.address)
            return True
        self._send(peer, ErrorReply(
            request_id, ErrorCode.BUSY,
            f"this environment is controlled by another client ({controller.address}); only "
            "observing is open to others. Start another server for another trainer",
        ))
        return False

    def close(self) -> None:
        """Disconnect every client and stop listening."""
        for peer in list(self._peers.values()):
            self._drop(peer, "server closing")
        if self._listener is not None:
            self._selector.unregister(self._listener)
            self._listener.close()
            self._listener = None
        self._selector.close()

    # --- waiting ----------------------------------------------------------------------------

    def _wait(self, deadline: float | None) -> None:
        """Block until a socket is readable or the next deadline (ours or a peer's); act on it."""
        now = self._clock()
        wake = self._next_deadline()
        if deadline is not None:
            wake = deadline if wake is None else min(wake, deadline)
        self._look_around(None if wake is None else max(0.0, wake - now))

    def _look_around(self, timeout: float | None) -> None:
        """Everything but the controller's fast path: reads, accepts, the lifeline, deadlines."""
        ready = {key.fileobj for key, _ in self._selector.select(timeout)}
        for peer in [peer for peer in self._order if peer.lane is not None and
                     peer.lane.doorbell in ready]:
            self._ring_heard(peer)
        for peer in [peer for peer in self._order if peer.sock in ready]:
            self._read(peer, block=False)  # before accepting: a client may leave as one comes
        if self._listener in ready:
            self._accept()
        if self._lifeline is not None and self._lifeline in ready:
            self._check_lifeline(self._lifeline)
        self._enforce_deadlines()
        self._housekeeping_at = self._clock() + HOUSEKEEPING_INTERVAL

    def _next_deadline(self) -> float | None:
        """When the earliest peer times out (a frame's deadline, or its idle timeout)."""
        return min((due for peer in self._order if (due := self._due(peer)) is not None),
                   default=None)

    def _due(self, peer: Peer) -> float | None:
        if peer.frame_started is not None:
            return peer.frame_started + self.limits.frame_deadline
        if self.limits.idle_timeout is not None:
            return peer.last_request + self.limits.idle_timeout
        return None

    def _enforce_deadlines(self) -> None:
        now = self._clock()
        for peer in list(self._order):
            due = self._due(peer)
            if due is None or now < due:
                continue
            if peer.frame_started is not None:
                message = (f"a frame was not completed within {self.limits.frame_deadline} s "
                           f"({peer.connection.buffered} bytes received); is the client stalled?")
            else:
                message = f"no request for {self.limits.idle_timeout} s"
            logger.info("client %s timed out: %s", peer.address, message)
            self._send(peer, ErrorReply(None, ErrorCode.TIMEOUT, message, fatal=True),
                       "timed out")

    # --- connections ------------------------------------------------------------------------

    def _accept(self) -> None:
        """Accept every pending connection."""
        assert self._listener is not None
        while True:
            try:
                sock, address = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            self._admit(sock, f"{address[0]}:{address[1]}")

    def _admit(self, sock: socket.socket, address: str) -> None:
        configure_socket(sock, HOUSEKEEPING_INTERVAL, self.limits.write_timeout)
        peer = Peer(sock, address, self.limits.max_first_frame_size, self._clock())
        if len(self._peers) >= self.limits.max_connections:
            for other in list(self._order):
                if self._has_left(other):
                    self._drop(other, "client closed the connection")
        if len(self._peers) >= self.limits.max_connections:
            logger.info("refused %s: %d clients connected", address, len(self._peers))
            self._send(peer, ErrorReply(
                None, ErrorCode.BUSY, f"this server already has {len(self._peers)} clients "
                "connected, its limit; close one or start another server", fatal=True))
            return
        self._peers[sock] = peer
        self._order.append(peer)
        self._selector.register(sock, selectors.EVENT_READ)
        self._spin_poll.register(sock, select.POLLIN)
        self._by_fd[sock.fileno()] = peer
        logger.info("client %s connected", address)
        assert self._hello is not None, "set the endpoint's hello before serving"
        self._write(peer, peer.connection.send(self._hello))

    def _check_lifeline(self, fd: int) -> None:
        if not os.read(fd, 4096):
            logger.warning("the process that started this server is gone; exiting")
            raise SystemExit(0)

    def _has_left(self, peer: Peer) -> bool:
        """Whether ``peer`` closed its end; reads what it sent meanwhile (without blocking)."""
        for _ in range(_PROBE_READS):
            if peer.connection.peer_closed or not select.select([peer.sock], [], [], 0)[0]:
                break
            self._read(peer, block=False)
        return peer.connection.peer_closed

    def _read(self, peer: Peer, block: bool) -> None:
        """One read from ``peer``; blocking reads give up after the housekeeping interval.

        A blocking read of a peer with a lane also ends when a request comes on the lane.
        """
        try:
            if not block:
                data = peer.sock.recv(_READ_SIZE, socket.MSG_DONTWAIT)
            elif peer.lane is None:
                data = peer.waiter.recv(peer.sock, _READ_SIZE)
            elif wait_for(peer.lane_ready, peer.lane, peer.waiter, HOUSEKEEPING_INTERVAL):
                peer.active = True  # a request on the lane
                return
            else:
                data = peer.sock.recv(_READ_SIZE, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            peer.active = False  # it paused: look after everything else from now on
            return
        except LaneClosed as error:
            self._close_lane(peer, str(error))
            return
        except OSError as error:
            logger.info("client %s: %s", peer.address, error)
            data = b""
        peer.active = True
        peer.connection.receive_data(data)
        if not block:  # a look around: whatever came is served in turn, before blocking again
            self._backlog = True

    # --- requests ---------------------------------------------------------------------------

    def _next_request(self) -> tuple[Peer, Request] | None:
        """The next valid request of any peer, taking peers in turn."""
        peers = self._order[:]  # answering may drop a peer
        count = len(peers)
        for offset in range(count):
            index = (self._turn + offset) % count
            peer = peers[index]
            request = self._request_from(peer)
            if request is not None:
                self._turn = index + 1
                return peer, request
        self._backlog = False  # every buffered request has been taken
        return None

    def _request_from(self, peer: Peer) -> Request | None:
        """``peer``'s next valid request; answers its bad frames and refusals on the way."""
        if peer.lane_ready():
            request = self._lane_request(peer)
            if request is not None:
                return request
        connection = peer.connection
        while peer.sock in self._peers:
            try:
                message = connection.next_message()
            except ProtocolError as error:
                logger.info("client %s: %s", peer.address, error)
                peer.frame_started = None
                if connection.peer_closed:  # it hung up in the middle of a frame
                    self._drop(peer, "client closed the connection mid-frame")
                    return None
                self._send(peer, ErrorReply(error.request_id, error.code, str(error),
                                            fatal=error.fatal), "broken framing")
                continue
            if message is NEED_DATA:
                if connection.buffered and peer.frame_started is None:
                    peer.frame_started = self._clock()
                return None
            if message is CONNECTION_CLOSED:
                self._drop(peer, "client closed the connection")
                return None
            assert message.__class__ is Request
            peer.frame_started = None
            peer.last_request = self._clock()
            if not peer.authenticated and not self._authenticate(peer, message):  # type: ignore[arg-type]
                continue
            if "shared_memory" in message.parts:  # type: ignore[union-attr]
                self._open_lane(peer, message)  # type: ignore[arg-type]
                continue
            return message  # type: ignore[return-value]
        return None

    # --- shared-memory lanes ----------------------------------------------------------------

    def _open_lane(self, peer: Peer, request: Request) -> None:
        """Answer a ``shared_memory`` request: hand the client a lane, or say why not."""
        value = request.parts["shared_memory"]
        try:
            host = peer.sock.getpeername()[0]
        except OSError:  # it left meanwhile: the refusal's send drops it
            host = "an address no longer connected"
        why = None
        if len(request.parts) != 1:
            why = "'shared_memory' goes alone in a request"
        elif not isinstance(value, dict):
            why = "'shared_memory' must be a map with 'address' and 'key'"
        elif not is_loopback(host):
            why = f"shared memory is for clients on this machine; this one is at {host}"
        elif peer.lane is not None:
            why = "this connection has a shared-memory lane already"
        if why is None:
            assert self._hello is not None
            try:
                peer.lane = open_lane(value.get("address"), value.get("key"), self._hello,
                                      peer.sock)
            except ValueError as error:
                why = str(error)
            except OSError as error:
                why = f"the client's lane socket cannot be reached: {error}"
        if why is not None:
            self._send(peer, ErrorReply(request.id, ErrorCode.BAD_REQUEST, why))
            return
        assert peer.lane is not None
        peer.lane_seen = peer.lane.slots.request_sequence
        self._selector.register(peer.lane.doorbell, selectors.EVENT_READ)
        logger.info("client %s steps through shared memory", peer.address)
        self._send(peer, Response(request.id, info={
            "shared_memory": peer.lane.slots.layout.to_wire()}))

    def _lane_request(self, peer: Peer) -> Request | None:
        """Take the request waiting on ``peer``'s lane.

        ``None`` when it was refused (answered on the socket), or when the connection takes no
        more requests (the lane is closed).
        """
        lane = peer.lane
        assert lane is not None
        slots = lane.slots
        peer.lane_seen = slots.request_sequence  # first: the client wrote it last
        peer.last_request = self._clock()
        try:
            peer.connection.note_request(slots.request_id)
        except LocalProtocolError as error:
            self._close_lane(peer, str(error))
            return None
        try:
            request = slots.read_request()
        except ValueError as error:  # slots no client of ours writes: refused on the socket
            self._send(peer, ErrorReply(slots.request_id, ErrorCode.BAD_REQUEST, str(error)))
            return None
        peer.lane_kind = slots.request_kind
        peer.active = True  # sending requests back to back: wait on its lane and socket alone
        return request

    def _ring_heard(self, peer: Peer) -> None:
        """``peer``'s doorbell rang while the endpoint looked around: serve its lane in turn."""
        assert peer.lane is not None
        try:
            peer.lane.drain()
        except LaneClosed as error:
            self._close_lane(peer, str(error))
            return
        if peer.lane_ready():
            self._backlog = True

    def _close_lane(self, peer: Peer, reason: str) -> None:
        lane = peer.lane
        if lane is None:
            return
        peer.lane = None
        self._selector.unregister(lane.doorbell)
        lane.close()
        logger.info("client %s: shared-memory lane closed: %s", peer.address, reason)

    def _authenticate(self, peer: Peer, request: Request) -> bool:
        """Check the first request's token; on success lift the frame size limit."""
        if self._token is not None and not (
            request.token is not None
            and hmac.compare_digest(request.token.encode(), self._token.encode())
        ):
            logger.warning("client %s: refused, %s token", peer.address,
                           "no" if request.token is None else "wrong")
            self._send(peer, ErrorReply(
                request.id, ErrorCode.UNAUTHORIZED,
                "this server requires a token: pass token=... to the client (or set RLENV_TOKEN)"
                if request.token is None else "wrong token", fatal=True,
            ))
            return False
        peer.authenticated = True
        peer.connection.max_frame_size = self.limits.max_frame_size
        return True

    # --- writing ----------------------------------------------------------------------------

    def _send(self, peer: Peer, message: Reply,
              why_fatal: str = "error reply closed the connection") -> None:
        """Send ``message``; a fatal error reply then closes the connection (``why_fatal``)."""
        kind = peer.lane_kind
        if kind and message.id is not None:  # the answer to the lane's request
            peer.lane_kind = 0
            lane = peer.lane
            if lane is not None and lane.slots.write_answer(message, kind):
                peer.connection.note_reply(message.id)
                lane.ring()
                peer.waiter.sent()
                self._waiter.sent()
                return
        try:
            try:
                data = peer.connection.send(message)
            except (TypeError, LocalProtocolError) as error:
                if message.__class__ is ErrorReply or message.id is None:
                    raise
                # A value in the answer that cannot travel, or an answer over the frame
                # limit: the client learns why instead of waiting for an answer.
                logger.error("answer to %s not sent: %s", peer.address, error)
                data = peer.connection.send(ErrorReply(
                    message.id, ErrorCode.ENVIRONMENT_ERROR,
                    f"the answer could not be sent: {error}"))
            peer.sock.sendall(data)
            peer.waiter.sent()
            self._waiter.sent()
        except (TypeError, LocalProtocolError) as error:
            logger.warning("not sent to %s: %s", peer.address, error)
        except OSError as error:
            logger.info("client %s: send failed: %s", peer.address, error)
            self._drop(peer, "send failed")
            return
        if message.__class__ is ErrorReply and message.fatal:  # type: ignore[union-attr]
            self._drop(peer, why_fatal)

    def _write(self, peer: Peer, data: bytes) -> None:
        try:
            peer.sock.sendall(data)
        except OSError as error:
            logger.info("client %s: send failed: %s", peer.address, error)
            self._drop(peer, "send failed")

    def _drop(self, peer: Peer, reason: str) -> None:
        self._close_lane(peer, reason)
        if self._peers.pop(peer.sock, None) is not None:
            self._selector.unregister(peer.sock)
            self._spin_poll.unregister(peer.sock)
            del self._by_fd[peer.sock.fileno()]
            self._order.remove(peer)
            if self.on_drop is not None:
                self.on_drop(peer)
            logger.info("client %s disconnected: %s", peer.address, reason)
        if self._controller is peer:
            self._controller = None
        peer.sock.close()


def _bind_error(error: OSError, host: str, port: int) -> OSError:
    """``error`` (from binding ``host:port``) with its cause said first, in words."""
    reasons = {
        errno.EADDRINUSE: f"port {port} is in use on {host} (by another server?): choose "
                          "another port, or 0 for a free one",
        errno.EADDRNOTAVAIL: f"{host} is not an address of this machine",
        errno.EACCES: f"port {port} on {host} needs privileges: choose a port above 1023",
    }
    reason = reasons.get(error.errno) if error.errno is not None else None
    if reason is None:
        if isinstance(error, socket.gaierror):
            reason = f"cannot resolve the host {host!r}: {error.strerror}"
        else:
            reason = f"cannot listen on {host}:{port}: {error.strerror or error}"
    clear = OSError(reason)
    clear.errno = error.errno
    return clear
