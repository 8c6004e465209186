"""The shared-memory lanes of an endpoint's clients: opening them, their requests and answers.

A client on the server's machine may ask for a lane (a ``shared_memory`` request, alone in its
request; :mod:`rlenv.transport.lanes`). :class:`PeerLanes` opens it, has the endpoint's selector
watch its doorbell, takes the requests the client writes into it and writes their answers back
when they fit. It sends nothing on a socket: what it answers,
:class:`~rlenv.serving._connections.Connections` sends.
"""

from __future__ import annotations

import logging
import selectors
from collections.abc import Callable
from typing import TYPE_CHECKING

from rlenv.protocol import ErrorReply, Hello, Reply, Request, Response
from rlenv.protocol.errors import ErrorCode, LocalProtocolError
from rlenv.transport.lanes import LaneClosed, open_lane
from rlenv.transport.sockets import is_loopback

if TYPE_CHECKING:
    from rlenv.serving._connections import Peer

__all__ = ["PeerLanes"]

logger = logging.getLogger(__name__)


class PeerLanes:
    """The lanes of one endpoint's clients (see the module docstring).

    Args:
        selector: the endpoint's selector, told to watch each lane's doorbell.
        clock: monotonic time in seconds (a request taken from a lane is its client's latest).
    """

    def __init__(self, selector: selectors.BaseSelector, clock: Callable[[], float]) -> None:
        self._selector = selector
        self._clock = clock

    def open(self, peer: Peer, request: Request, hello: Hello) -> Reply:
        """Open the lane ``peer``'s ``shared_memory`` request asks for: its layout, or why not."""
        value = request.parts["shared_memory"]
        why = _lane_refusal(peer, request)
        if why is None:
            try:
                peer.lane = open_lane(value.get("address"), value.get("key"), hello, peer.sock)
            except ValueError as error:
                why = str(error)
            except OSError as error:
                why = f"the client's lane socket cannot be reached: {error}"
        if why is not None:
            return ErrorReply(request.id, ErrorCode.BAD_REQUEST, why)
        assert peer.lane is not None
        peer.lane_seen = peer.lane.slots.request_sequence
        self._selector.register(peer.lane.doorbell, selectors.EVENT_READ)
        logger.info("client %s steps through shared memory", peer.address)
        return Response(request.id, info={"shared_memory": peer.lane.slots.layout.to_wire()})

    def take_request(self, peer: Peer) -> Request | ErrorReply | None:
        """Take the request waiting on ``peer``'s lane.

        Returns:
            The request; or its refusal, to send on the socket; or ``None`` when the connection
            takes no more requests (the lane is closed).
        """
        lane = peer.lane
        assert lane is not None
        slots = lane.slots
        peer.lane_seen = slots.request_sequence  # first: the client wrote it last
        peer.last_request = self._clock()
        try:
            peer.connection.note_request(slots.request_id)
        except LocalProtocolError as error:
            self.close(peer, str(error))
            return None
        try:
            request = slots.read_request()
        except ValueError as error:  # slots no client of ours writes: refused on the socket
            return ErrorReply(slots.request_id, ErrorCode.BAD_REQUEST, str(error))
        peer.lane_kind = slots.request_kind
        peer.active = True  # sending requests back to back: wait on its lane and socket alone
        return request

    def heard(self, peer: Peer) -> bool:
        """``peer``'s doorbell rang: whether its lane now holds a request not taken yet."""
        assert peer.lane is not None
        try:
            peer.lane.drain()
        except LaneClosed as error:
            self.close(peer, str(error))
            return False
        return peer.lane_ready()

    def answer(self, peer: Peer, message: Reply) -> bool:
        """Whether ``message`` went into ``peer``'s lane: the answer to its request, if it fits.

        Once asked, the lane's request counts as answered: an answer that does not fit (or one
        whose lane closed meanwhile) goes on the socket.
        """
        kind = peer.lane_kind
        if not kind or message.id is None:
            return False
        peer.lane_kind = 0
        lane = peer.lane
        if lane is None or not lane.slots.write_answer(message, kind):
            return False
        peer.connection.note_reply(message.id)
        lane.ring()
        peer.waiter.sent()
        return True

    def close(self, peer: Peer, reason: str) -> None:
        """Close ``peer``'s lane, if it has one (its socket stays open)."""
        lane = peer.lane
        if lane is None:
            return
        peer.lane = None
        self._selector.unregister(lane.doorbell)
        lane.close()
        logger.info("client %s: shared-memory lane closed: %s", peer.address, reason)


def _lane_refusal(peer: Peer, request: Request) -> str | None:
    """Why ``peer``'s ``shared_memory`` request is refused before its lane is opened, or None."""
    try:
        host = peer.sock.getpeername()[0]
    except OSError:  # it left meanwhile: the refusal's send drops it
        host = "an address no longer connected"
    if len(request.parts) != 1:
        return "'shared_memory' goes alone in a request"
    if not isinstance(request.parts["shared_memory"], dict):
        return "'shared_memory' must be a map with 'address' and 'key'"
    if not is_loopback(host):
        return f"shared memory is for clients on this machine; this one is at {host}"
    if peer.lane is not None:
        return "this connection has a shared-memory lane already"
    return None
