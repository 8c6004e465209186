"""The clients connected to an endpoint: admitting them, reading, writing, lanes, dropping.

Each client is a :class:`Peer`: its socket, its sans-IO :class:`~rlenv.protocol.Connection`,
whether it authenticated, its shared-memory lane if it asked for one
(:mod:`rlenv.transport.lanes`, opened and served by :class:`~rlenv.serving._peer_lanes.PeerLanes`),
and how it waits. :class:`Connections` holds them for the
:class:`~rlenv.serving._endpoint.Endpoint` (which adds listening, waiting and control): up to
:attr:`Limits.max_connections` of them, each answered on its own connection, in arrival order,
so that a misbehaving client never disturbs another; a connection beyond the cap takes the
place of the oldest client that has sent no request yet, or is told ``busy`` and closed, never
silently queued. Sockets stay in blocking mode with kernel timeouts;
frames go out with one ``sendall`` (``TCP_NODELAY``) and come in at most 64 KiB at a time.
Requests taken from a lane go through the same door as any other, and their answers back into
the lane when they fit (else on the socket).
"""

from __future__ import annotations

import logging
import os
import select
import selectors
import socket
import time
from collections.abc import Callable
from dataclasses import replace

from rlenv.protocol import Connection, ErrorReply, Hello, Reply, Request, Role
from rlenv.protocol.errors import ErrorCode, LocalProtocolError
from rlenv.serving._access import Limits
from rlenv.serving._peer_lanes import PeerLanes
from rlenv.serving._token_check import TokenCheck
from rlenv.transport.lanes import Lane, LaneClosed, wait_for
from rlenv.transport.sockets import REQUEST_SPIN_WINDOW, AnswerWaiter, configure_socket

__all__ = ["HOUSEKEEPING_INTERVAL", "Connections", "Peer"]

logger = logging.getLogger(__name__)

HOUSEKEEPING_INTERVAL = 0.01
"""Seconds between looks at everything but the controller while the controller is busy."""
_READ_SIZE = 64 * 1024
_PROBE_READS = 16


class Peer:
    """One connected client, as the endpoint sees it.

    Attributes:
        lane: its shared-memory lane (:mod:`rlenv.transport.lanes`), if it asked for one.
        lane_kind: the kind of the request taken from the lane and not answered yet (0: none).
    """

    __slots__ = (
        "active",
        "address",
        "authenticated",
        "connection",
        "frame_started",
        "host",
        "lane",
        "lane_kind",
        "lane_seen",
        "last_request",
        "sock",
        "waiter",
    )

    def __init__(
        self, sock: socket.socket, host: str, port: int, max_frame_size: int, now: float
    ) -> None:
        self.sock = sock
        self.host = host
        self.address = f"{host}:{port}"
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


class Connections:
    """The clients of an endpoint, and their I/O (see the module docstring).

    Args:
        hello: what each client is told on connecting (``None``: set :attr:`hello` before
            serving; a self-hosting environment binds before its hello is known).
        limits: sizes and deadlines; see :class:`Limits` (its defaults if ``None``).
        token: the secret the client's first request must carry (``None``: no token needed,
            only allowed on loopback addresses).
        clock: monotonic time in seconds (injectable for tests).
        per_client: every client controls an environment of its own
            (:mod:`rlenv.serving.per_client`), rather than the first one the only one.

    Attributes:
        on_drop: told of each client that left (or was dropped), after it was.
    """

    def __init__(
        self,
        hello: Hello | None,
        limits: Limits | None = None,
        token: str | None = None,
        clock: Callable[[], float] = time.monotonic,
        per_client: bool = False,
    ) -> None:
        self.limits = limits or Limits()
        self.per_client = per_client
        self.on_drop: Callable[[Peer], None] | None = None
        self._waiter = AnswerWaiter(window=REQUEST_SPIN_WINDOW)
        self._spin_poll = select.poll()
        self._by_fd: dict[int, Peer] = {}
        self._token = token
        self._token_check = TokenCheck(token, clock)
        self._hello: Hello | None = None
        if hello is not None:
            self.hello = hello
        self._clock = clock
        self._selector = selectors.DefaultSelector()
        self._lanes = PeerLanes(self._selector, clock)
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
        self._hello = replace(
            hello,
            token_required=hello.token_required or self._token is not None,
            limits={**hello.limits, **self.limits.to_wire()},
        )

    @property
    def connections(self) -> int:
        """How many clients are connected."""
        return len(self._peers)

    def reply(self, peer: Peer, message: Reply) -> None:
        """Send ``peer`` the answer to its oldest request (dropped if the client is gone)."""
        if peer.sock in self._peers:
            self._send(peer, message)

    def close(self) -> None:
        """Disconnect every client and stop listening."""
        for peer in list(self._peers.values()):
            self._drop(peer, "server closing")
        self._token_check.close()
        if self._listener is not None:
            self._selector.unregister(self._listener)
            self._listener.close()
            self._listener = None
        self._selector.close()

    # --- connections -----------------------------------------------------------------------

    def _accept(self) -> None:
        """Accept every pending connection."""
        assert self._listener is not None
        while True:
            try:
                sock, address = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            self._admit(sock, address[0], address[1])

    def _admit(self, sock: socket.socket, host: str, port: int) -> None:
        configure_socket(sock, HOUSEKEEPING_INTERVAL, self.limits.write_timeout)
        peer = Peer(sock, host, port, self.limits.max_first_frame_size, self._clock())
        address = peer.address
        if len(self._peers) >= self.limits.max_connections:
            for other in list(self._order):
                if self._has_left(other):
                    self._drop(other, "client closed the connection")
        if len(self._peers) >= self.limits.max_connections:
            self._make_room()
        if len(self._peers) >= self.limits.max_connections:
            logger.info("refused %s: %d clients connected", address, len(self._peers))
            self._send(
                peer,
                ErrorReply(
                    None,
                    ErrorCode.BUSY,
                    f"this server already has {len(self._peers)} clients "
                    "connected, its limit; close one or start another server",
                    fatal=True,
                ),
            )
            return
        self._peers[sock] = peer
        self._order.append(peer)
        self._selector.register(sock, selectors.EVENT_READ)
        self._spin_poll.register(sock, select.POLLIN)
        self._by_fd[sock.fileno()] = peer
        logger.info("client %s connected", address)
        assert self._hello is not None, "set the endpoint's hello before serving"
        self._write(peer, peer.connection.send(self._hello))

    def _make_room(self) -> None:
        """Drop the oldest client that has not sent its first request, if any.

        Such a client holds a slot without having shown it may (the token), so a newcomer takes
        its place, as the oldest of the connections not yet admitted is the first to go past
        OpenSSH's ``MaxStartups``: silent connections cannot keep a client with the token out.
        """
        waiting = next((peer for peer in self._order if not peer.authenticated), None)
        # (a client whose wrong token was compared is held apart, in no slot: see _hold)
        if waiting is not None:
            self._send(
                waiting,
                ErrorReply(
                    None,
                    ErrorCode.BUSY,
                    f"this server is full ({self.limits.max_connections} "
                    "clients) and this connection had sent no request: a newer one took its place",
                    fatal=True,
                ),
                "made room for a newer connection",
            )

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
            self._lanes.close(peer, str(error))
            return
        except OSError as error:
            logger.info("client %s: %s", peer.address, error)
            data = b""
        peer.active = True
        peer.connection.receive_data(data)
        if not block:  # a look around: whatever came is served in turn, before blocking again
            self._backlog = True

    # --- shared-memory lanes (opened, read and written by PeerLanes) ------------------------

    def _open_lane(self, peer: Peer, request: Request) -> None:
        """Answer a ``shared_memory`` request: hand the client a lane, or say why not."""
        assert self._hello is not None
        self._send(peer, self._lanes.open(peer, request, self._hello))

    def _lane_request(self, peer: Peer) -> Request | None:
        """Take the request waiting on ``peer``'s lane.

        ``None`` when it was refused (answered on the socket), or when the connection takes no
        more requests (the lane is closed).
        """
        request = self._lanes.take_request(peer)
        if isinstance(request, ErrorReply):
            self._send(peer, request)
            return None
        return request

    def _ring_heard(self, peer: Peer) -> None:
        """``peer``'s doorbell rang while the endpoint looked around: serve its lane in turn."""
        if self._lanes.heard(peer):
            self._backlog = True

    def _authenticate(self, peer: Peer, request: Request) -> bool:
        """Check the first request's token; on success lift the frame size limit.

        Every token is compared (in constant time): the right one is let in whatever its
        address sent before. A wrong one's refusal is held as long as its address's penalty
        says (:mod:`rlenv.serving._penalties`), the connection out of its slot meanwhile.
        """
        why, delay = self._token_check.refusal(peer, request.token)
        if why is not None:
            refusal = ErrorReply(request.id, ErrorCode.UNAUTHORIZED, why, fatal=True)
            if delay > 0.0:
                self._forget(peer, "wrong token (its answer held)")
                self._token_check.hold(peer, refusal, delay)
            else:
                self._send(peer, refusal)
            return False
        peer.authenticated = True
        peer.connection.max_frame_size = self.limits.max_frame_size
        return True

    def _may_compare(self, peer: Peer) -> bool:
        """Whether ``peer``'s token may be compared now (its address holds few answers)."""
        return self._token_check.may_compare(peer)

    def _release_held(self) -> None:
        """Send the held refusals that are due, and close their connections."""
        if self._token_check.release_due():
            self._backlog = True  # tokens that waited for this may be compared now

    def _next_release(self) -> float | None:
        """When the next held refusal is due."""
        return self._token_check.next_release()

    # --- writing ----------------------------------------------------------------------------

    def _send(
        self, peer: Peer, message: Reply, why_fatal: str = "error reply closed the connection"
    ) -> None:
        """Send ``message``; a fatal error reply then closes the connection (``why_fatal``)."""
        if self._lanes.answer(peer, message):  # the answer to the lane's request, in it
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
                data = peer.connection.send(
                    ErrorReply(
                        message.id,
                        ErrorCode.ENVIRONMENT_ERROR,
                        f"the answer could not be sent: {error}",
                    )
                )
            peer.sock.sendall(data)
            peer.waiter.sent()
            self._waiter.sent()
        except (TypeError, LocalProtocolError) as error:
            logger.warning("not sent to %s: %s", peer.address, error)
        except OSError as error:
            logger.info("client %s: send failed: %s", peer.address, error)
            self._drop(peer, "send failed")
            return
        if message.__class__ is ErrorReply and message.fatal:
            self._drop(peer, why_fatal)

    def _write(self, peer: Peer, data: bytes) -> None:
        try:
            peer.sock.sendall(data)
        except OSError as error:
            logger.info("client %s: send failed: %s", peer.address, error)
            self._drop(peer, "send failed")

    def _drop(self, peer: Peer, reason: str) -> None:
        self._forget(peer, reason)
        peer.sock.close()

    def _forget(self, peer: Peer, reason: str) -> None:
        """Take ``peer`` out of every list (its socket stays open)."""
        self._lanes.close(peer, reason)
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
