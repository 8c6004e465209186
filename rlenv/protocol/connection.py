"""The connection state machine, sans-IO: bytes in, messages out; messages in, bytes out.

Rule 1: everything that decides what may be sent or received, and when, lives in this module
(like h11's ``_state.py``). The server's endpoint and the client only move bytes between a
socket and a :class:`Connection`.

The states and what moves a connection between them, for each role, are one table,
:data:`TRANSITIONS`. A message that has no entry for the current state is refused: sending it
raises :class:`~rlenv.errors.LocalProtocolError` (a bug on this side), receiving it raises
:class:`~rlenv.errors.RemoteProtocolError` (the peer broke the protocol). Besides the table,
replies pair with requests: exactly one per request, in order.
"""

from __future__ import annotations

from collections import deque
from enum import Enum
from typing import Any, Final

from rlenv.errors import LocalProtocolError, RemoteProtocolError
from rlenv.protocol.codec import DEFAULT_MAX_FRAME_SIZE, HEADER, pack, unpack
from rlenv.protocol.messages import (
    BatchResponse,
    ErrorReply,
    Hello,
    Message,
    Request,
    Response,
    StepsResponse,
)

__all__ = ["CONNECTION_CLOSED", "NEED_DATA", "TRANSITIONS", "Connection", "Event", "Role",
           "State"]


class _Sentinel:
    def __init__(self, name: str) -> None:
        self._name = name

    def __repr__(self) -> str:
        return self._name


NEED_DATA: Final = _Sentinel("NEED_DATA")
"""Returned by :meth:`Connection.next_message` when no whole frame is buffered yet."""

CONNECTION_CLOSED: Final = _Sentinel("CONNECTION_CLOSED")
"""Returned by :meth:`Connection.next_message` once the peer closed the stream cleanly."""


class Role(Enum):
    """Which end of the connection a :class:`Connection` plays."""

    CLIENT = "client"
    SERVER = "server"


class State(Enum):
    """Where a connection stands."""

    AWAIT_HELLO = "await_hello"
    READY = "ready"
    CLOSED = "closed"


class Event(Enum):
    """What happens on a connection: a message sent or received, or the stream breaking."""

    SEND_HELLO = "send hello"
    RECEIVE_HELLO = "receive hello"
    SEND_REQUEST = "send request"
    RECEIVE_REQUEST = "receive request"
    SEND_REPLY = "send reply"
    RECEIVE_REPLY = "receive reply"
    SEND_FATAL_ERROR = "send fatal error"
    RECEIVE_FATAL_ERROR = "receive fatal error"
    END = "end of stream or broken framing"


_CLIENT, _SERVER = Role.CLIENT, Role.SERVER
_AWAIT, _READY, _CLOSED = State.AWAIT_HELLO, State.READY, State.CLOSED

TRANSITIONS: Final[dict[tuple[Role, State, Event], State]] = {
    # The server speaks first: a hello, or a fatal error refusing the connection (busy).
    (_SERVER, _AWAIT, Event.SEND_HELLO): _READY,
    (_SERVER, _AWAIT, Event.SEND_FATAL_ERROR): _CLOSED,
    (_CLIENT, _AWAIT, Event.RECEIVE_HELLO): _READY,
    (_CLIENT, _AWAIT, Event.RECEIVE_REPLY): _CLOSED,  # an error instead of the hello
    (_CLIENT, _AWAIT, Event.RECEIVE_FATAL_ERROR): _CLOSED,
    # Then requests, each answered by one reply (a response or an error), in order.
    (_CLIENT, _READY, Event.SEND_REQUEST): _READY,
    (_SERVER, _READY, Event.RECEIVE_REQUEST): _READY,
    (_SERVER, _READY, Event.SEND_REPLY): _READY,
    (_CLIENT, _READY, Event.RECEIVE_REPLY): _READY,
    # A fatal error ends the conversation (broken framing, timeouts, failed authentication).
    (_SERVER, _READY, Event.SEND_FATAL_ERROR): _CLOSED,
    (_CLIENT, _READY, Event.RECEIVE_FATAL_ERROR): _CLOSED,
    # So does the end of the stream, in any state.
    **{(role, state, Event.END): _CLOSED for role in Role for state in State},
}
"""(role, state, event) -> the next state. Nothing else may happen."""

_REPLIES = (Response, BatchResponse, StepsResponse, ErrorReply)


def _sent(message: Message) -> Event:
    kind = type(message)
    if kind is Hello:
        return Event.SEND_HELLO
    if kind is Request:
        return Event.SEND_REQUEST
    if kind is ErrorReply and message.fatal:  # type: ignore[union-attr]
        return Event.SEND_FATAL_ERROR
    if kind in _REPLIES:
        return Event.SEND_REPLY
    raise LocalProtocolError(f"not a message: {message!r:.60}")


class Connection:
    """One end of an rlenv connection, with no I/O of its own (like h11's ``Connection``).

    Feed received bytes to :meth:`receive_data` and pull messages with :meth:`next_message`;
    turn messages into bytes to write with :meth:`send`.

    Args:
        role: which end this is.
        max_frame_size: largest frame body accepted; a larger length prefix is refused before
            any of the body is buffered.
    """

    def __init__(self, role: Role, max_frame_size: int = DEFAULT_MAX_FRAME_SIZE) -> None:
        self.role = role
        self.max_frame_size = max_frame_size
        self.state = State.AWAIT_HELLO
        self._buffer: bytes | bytearray = b""
        self._eof = False
        self._broken = False  # the framing broke: nothing more is read (one reply may go out)
        self._outstanding: deque[int] = deque()

    @property
    def outstanding(self) -> tuple[int, ...]:
        """Ids of the requests that have not been answered yet, oldest first."""
        return tuple(self._outstanding)

    @property
    def buffered(self) -> int:
        """Bytes received that do not form a whole frame yet."""
        return len(self._buffer)

    @property
    def peer_closed(self) -> bool:
        """Whether the peer closed its end of the stream (``receive_data(b"")`` was called)."""
        return self._eof

    def receive_data(self, data: bytes) -> None:
        """Buffer bytes read from the peer; ``b""`` means the peer closed its end."""
        if not data:
            self._eof = True
        elif not self._buffer:
            self._buffer = data
        else:
            if type(self._buffer) is bytes:
                self._buffer = bytearray(self._buffer)
            self._buffer += data

    def next_message(self) -> Message | _Sentinel:
        """Return the next whole message, :data:`NEED_DATA` or :data:`CONNECTION_CLOSED`.

        Raises:
            RemoteProtocolError: the peer broke the protocol. ``error.fatal`` says the framing
                itself is broken (the stream cannot be resynchronised): nothing more is read, and
                this side may send one last fatal :class:`ErrorReply`. Otherwise the bad frame
                is consumed and the connection goes on. A request that could be read far enough
                carries its id in ``error.request_id``.
            ProtocolVersionError: the hello names another major version.
        """
        if self.state is State.CLOSED or self._broken:
            return CONNECTION_CLOSED
        body = self._next_frame()
        if body.__class__ is _Sentinel:
            return body  # type: ignore[return-value]
        wire = unpack(body, self.max_frame_size)
        if wire.__class__ is not dict:
            raise RemoteProtocolError(f"a frame must hold a map, got {type(wire).__name__}")
        if self.role is Role.SERVER:
            return self._request(wire)
        return self._reply(wire)

    def send(self, message: Message) -> bytes:
        """Return the frame that carries ``message``.

        Raises:
            LocalProtocolError: this side may not send ``message`` now, or it is larger than
                the protocol's frame limit.
            TypeError: the message holds a value that cannot travel on the wire.
        """
        event = _sent(message)
        state = self._next_state(event, LocalProtocolError)
        reply_id = getattr(message, "id", None)
        if event is not Event.SEND_HELLO and event is not Event.SEND_REQUEST and \
                reply_id is not None:
            if not self._outstanding or self._outstanding[0] != reply_id:
                raise LocalProtocolError(f"reply to request {reply_id} out of order; "
                                         f"outstanding: {list(self._outstanding)}")
        body = pack(message.to_wire())
        if len(body) > DEFAULT_MAX_FRAME_SIZE:
            raise LocalProtocolError(f"message of {len(body)} bytes exceeds the frame limit of "
                                     f"{DEFAULT_MAX_FRAME_SIZE}")
        if event is Event.SEND_REQUEST:
            self._outstanding.append(reply_id)  # type: ignore[arg-type]
        elif reply_id is not None and event is not Event.SEND_HELLO:
            self._outstanding.popleft()
        self.state = state
        return HEADER.pack(len(body)) + body

    # --- internals --------------------------------------------------------------------------

    def _next_state(self, event: Event, error: type[Exception]) -> State:
        state = TRANSITIONS.get((self.role, self.state, event))
        if state is None:
            raise error(f"a {self.role.value} may not {event.value} in state "
                        f"{self.state.value}")
        return state

    def _next_frame(self) -> bytes | memoryview | _Sentinel:
        buffer = self._buffer
        buffered = len(buffer)
        if buffered >= HEADER.size:
            (length,) = HEADER.unpack_from(buffer)
            if length > self.max_frame_size:
                self._broken = True
                raise RemoteProtocolError(
                    f"frame length {length} exceeds the limit of {self.max_frame_size} bytes "
                    "(is the peer speaking the rlenv protocol?)", fatal=True)
            end = HEADER.size + length
            if buffered == end:
                self._buffer = b""
                return memoryview(buffer)[HEADER.size:]
            if buffered > end:
                body = bytes(buffer[HEADER.size:end])
                self._buffer = buffer[end:]
                return body
        if not self._eof:
            return NEED_DATA
        self.state = State.CLOSED
        if buffered:
            raise RemoteProtocolError(
                f"connection closed in the middle of a frame ({buffered} bytes buffered)",
                fatal=True)
        return CONNECTION_CLOSED

    def _request(self, wire: dict[str, Any]) -> Request:
        self._next_state(Event.RECEIVE_REQUEST, RemoteProtocolError)
        try:
            request = Request.from_wire(wire)
        except RemoteProtocolError as error:
            if error.request_id is not None:
                self._outstanding.append(error.request_id)  # the error reply answers it
            raise
        self._outstanding.append(request.id)
        return request

    def _reply(self, wire: dict[str, Any]) -> Message:
        if "error" in wire:
            reply: Message = ErrorReply.from_wire(wire)
            event = Event.RECEIVE_FATAL_ERROR if reply.fatal else Event.RECEIVE_REPLY
        elif self.state is State.AWAIT_HELLO:
            if "hello" not in wire:
                self.state = State.CLOSED
                raise RemoteProtocolError("the server did not start with a hello", fatal=True)
            reply, event = Hello.from_wire(wire), Event.RECEIVE_HELLO
        elif "steps" in wire:
            reply, event = StepsResponse.from_wire(wire), Event.RECEIVE_REPLY
        elif "batch" in wire:
            reply, event = BatchResponse.from_wire(wire), Event.RECEIVE_REPLY
        else:
            reply, event = Response.from_wire(wire), Event.RECEIVE_REPLY
        state = self._next_state(event, RemoteProtocolError)
        reply_id = getattr(reply, "id", None)
        if event is not Event.RECEIVE_HELLO and reply_id is not None:
            if not self._outstanding or self._outstanding[0] != reply_id:
                self.state = State.CLOSED
                expected = self._outstanding[0] if self._outstanding else "none"
                raise RemoteProtocolError(f"reply to request {reply_id}, expected {expected}",
                                          fatal=True)
            self._outstanding.popleft()
        self.state = state
        return reply
