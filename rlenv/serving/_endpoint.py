"""The server's TCP endpoint: socket I/O only; the protocol lives in :mod:`rlenv.protocol`.

An environment server is a network service and is treated like one:

- **One controller, several connections.** Up to :attr:`Limits.max_connections` clients may be
  connected; each is answered on its own connection, in arrival order, so a misbehaving client
  never disturbs another. The first client whose accepted request changes the environment
  controls it until it disconnects (:meth:`Endpoint.take_control`; which requests change it is
  the host's call, and a refused request takes no control); such a request from anyone else
  gets a ``busy`` error reply. A connection beyond the cap takes the place of the oldest client
  that has sent no request yet, or is told ``busy`` and closed, never silently queued.
- **Limits before allocation.** A frame's length is checked before its body is read: at most
  :attr:`Limits.max_unauthenticated_frame_size` bytes until the client has authenticated (or
  when no token is needed, until its first request), :attr:`Limits.max_frame_size` after.
- **Deadlines.** A frame that has started must complete within :attr:`Limits.frame_deadline`
  (a client that trickles bytes is dropped); when a token is required, a client that has not
  sent it (in its first request) within :attr:`Limits.first_request_timeout` of connecting is
  dropped; a client silent between requests for
  :attr:`Limits.idle_timeout` is dropped; a write that cannot complete within
  :attr:`Limits.write_timeout` drops the client.
- **Access.** The server binds 127.0.0.1 unless told otherwise, and refuses to bind anything else
  without a token. With a token, the client's first request must carry it (compared in constant
  time), or the connection is refused; past a few wrong tokens from an address, each refusal is
  held apart (no slot) and sent late (:mod:`rlenv.serving._penalties`).

**The hot path.** While the controller keeps sending, the endpoint blocks in ``recv`` on the
controller's socket alone (one system call per request, no selector); the others (new
connections, observers, the lifeline, deadlines) are looked after every
:data:`HOUSEKEEPING_INTERVAL` seconds, and at once whenever the controller pauses that long.
Sockets stay in blocking mode; the kernel enforces their timeouts (``SO_RCVTIMEO``,
``SO_SNDTIMEO``), so Python never polls before a read or a write. A controller with a
shared-memory lane (:mod:`rlenv.transport.lanes`) is waited for on its lane and its socket
together; requests taken from a lane go through the same door, and their answers back into the
lane when they fit (else on the socket). Frames are sent with one
``sendall`` (``TCP_NODELAY``), read at most 64 KiB at a time.
"""

from __future__ import annotations

import logging
import selectors
import socket

from rlenv.protocol import CONNECTION_CLOSED, NEED_DATA, ErrorReply, Request
from rlenv.protocol.errors import ErrorCode, ProtocolError
from rlenv.serving._access import DEFAULT_HOST, InsecureBindError, Limits, bind_error
from rlenv.serving._connections import HOUSEKEEPING_INTERVAL, Connections, Peer
from rlenv.transport.sockets import address_family, format_address, is_loopback

__all__ = [
    "DEFAULT_HOST",
    "HOUSEKEEPING_INTERVAL",
    "Endpoint",
    "InsecureBindError",
    "Limits",
    "Peer",
]

logger = logging.getLogger(__name__)


class Endpoint(Connections):
    """Accepts clients and moves frames between them and the host.

    It listens (:meth:`start_server`), waits for the next request of any client
    (:meth:`receive`), enforces deadlines, and knows which client controls the environment;
    its clients and their I/O are :class:`~rlenv.serving._connections.Connections`' (whose
    arguments it takes).
    """

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
            listener = socket.create_server((host, port), family=address_family(host), backlog=16)
        except OSError as error:
            raise bind_error(error, host, port) from None
        listener.setblocking(False)
        self._listener = listener
        self._selector.register(listener, selectors.EVENT_READ)
        logger.info(
            "listening on %s%s",
            format_address(*self.address),
            " (token required)" if self._token else "",
        )
        return self.address

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
            if (
                deadline is None
                and controller is not None
                and controller.active
                and self._clock() < self._housekeeping_at
            ):
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
        """A per-client server's wait: spin over every lane and socket for the next request.

        Clients that step one after the other find the server awake. ``None`` when the spin
        ended without one (then the selector waits).
        """
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
            self._backlog = False  # receive() found none before the spin: only this peer's
        request = self._request_from(peer)
        if request is None:
            return None
        if peer.connection.buffered:
            self._backlog = True
        return peer, request

    def controls(self, peer: Peer) -> bool:
        """Whether ``peer`` controls the environment."""
        return self.per_client or peer is self._controller

    _reserved: str | None = None  # why no client may take control (see reserve)

    def reserve(self, why: str) -> None:
        """Let no client control the environment (the server drives it): ``busy``, saying why."""
        self._reserved = why

    def take_control(self, peer: Peer, request_id: int) -> bool:
        """Let ``peer``'s request change the environment, if ``peer`` may.

        The first client to ask controls the environment until it leaves; anyone else is
        answered ``busy`` (and this returns False), as everyone is after :meth:`reserve`.
        """
        if self._reserved is not None:
            self._send(
                peer,
                ErrorReply(
                    request_id,
                    ErrorCode.BUSY,
                    f"this environment cannot be controlled: {self._reserved}",
                ),
            )
            return False
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
        self._send(
            peer,
            ErrorReply(
                request_id,
                ErrorCode.BUSY,
                f"this environment is controlled by another client ({controller.address}); only "
                "observing is open to others. Start another server for another trainer",
            ),
        )
        return False

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
        for peer in [
            peer for peer in self._order if peer.lane is not None and peer.lane.doorbell in ready
        ]:
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
        """When the next peer times out (a frame's deadline, its idle timeout) or refusal is due."""
        dues = [due for peer in self._order if (due := self._due(peer)) is not None]
        release = self._next_release()
        if release is not None:
            dues.append(release)
        return min(dues, default=None)

    def _due(self, peer: Peer) -> float | None:
        if not peer.authenticated and self._token is not None:  # last_request: its connecting
            if peer.connection.buffered and not self._may_compare(peer):
                return None  # it sent in time; its token waits for a held answer to go out
            due = peer.last_request + self.limits.first_request_timeout
            if peer.frame_started is not None:
                due = min(due, peer.frame_started + self.limits.frame_deadline)
            return due
        if peer.frame_started is not None:
            return peer.frame_started + self.limits.frame_deadline
        if self.limits.idle_timeout is not None:
            return peer.last_request + self.limits.idle_timeout
        return None

    def _enforce_deadlines(self) -> None:
        self._release_held()
        now = self._clock()
        for peer in list(self._order):
            due = self._due(peer)
            if due is None or now < due:
                continue
            if (
                not peer.authenticated
                and self._token is not None
                and now >= peer.last_request + self.limits.first_request_timeout
            ):
                message = (
                    f"no request with the right token within "
                    f"{self.limits.first_request_timeout} s of connecting"
                )
            elif peer.frame_started is not None:
                message = (
                    f"a frame was not completed within {self.limits.frame_deadline} s "
                    f"({peer.connection.buffered} bytes received); is the client stalled?"
                )
            else:
                message = f"no request for {self.limits.idle_timeout} s"
            logger.info("client %s timed out: %s", peer.address, message)
            self._send(peer, ErrorReply(None, ErrorCode.TIMEOUT, message, fatal=True), "timed out")

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
        if (
            not peer.authenticated
            and self._token is not None
            and connection.buffered
            and not self._may_compare(peer)
        ):
            return None  # its address's wrong answers are held: compared once one goes out
        while peer.sock in self._peers:
            try:
                message = connection.next_message()
            except ProtocolError as error:
                logger.info("client %s: %s", peer.address, error)
                peer.frame_started = None
                if connection.peer_closed:  # it hung up in the middle of a frame
                    self._drop(peer, "client closed the connection mid-frame")
                    return None
                self._send(
                    peer,
                    ErrorReply(error.request_id, error.code, str(error), fatal=error.fatal),
                    "broken framing",
                )
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
            if not peer.authenticated and not self._authenticate(peer, message):
                continue
            if "shared_memory" in message.parts:
                self._open_lane(peer, message)
                continue
            return message
        return None
