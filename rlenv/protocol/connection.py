"""The connection state machine, sans-IO: bytes in, messages out; messages in, bytes out.

Rule 1: everything that decides what may be sent or received, and when, lives in this module
(like h11's ``_state.py``). The server's endpoint and the client only move bytes between a
socket and a :class:`Connection`.

The states and what moves a connection between them, for each role, are one table,
:data:`TRANSITIONS`. A message that has no entry for the current state is refused: sending it
raises :class:`~rlenv.protocol.errors.LocalProtocolError` (a bug on this side), receiving it
raises :class:`~rlenv.protocol.errors.RemoteProtocolError` (the peer broke the protocol).
Besides the table, replies pair with requests: exactly one per request, in order.
"""

from __future__ import annotations

from collections import deque
from enum import StrEnum
from typing import Any, Final

from rlenv.protocol.codec import (
    DEFAULT_MAX_FRAME_SIZE,
    HEADER,
    MAX_FRAME_OBJECTS,
    count_objects,
    pack,
    unpack,
)
from rlenv.protocol.errors import LocalProtocolError, RemoteProtocolError
from rlenv.protocol.messages import (
    BatchResponse,
    ErrorReply,
    Hello,
    Message,
    Request,
    Response,
    StepsResponse,
)

__all__ = ["CONNECTION_CLOSED", "NEED_DATA", "TRANSITIONS", "Connection", "Event", "Role", "State"]


class _Sentinel:
    def __init__(self, name: str) -> None:
        self._name = name

    def __repr__(self) -> str:
        return self._name


NEED_DATA: Final = _Sentinel("NEED_DATA")
"""Returned by :meth:`Connection.next_message` when no whole frame is buffered yet."""

CONNECTION_CLOSED: Final = _Sentinel("CONNECTION_CLOSED")
"""Returned by :meth:`Connection.next_message` once the peer closed the stream cleanly."""


class Role(StrEnum):
    """Which end of the connection a :class:`Connection` plays."""

    CLIENT = "client"
    SERVER = "server"


class State(StrEnum):
    """Where a connection stands."""

    AWAIT_HELLO = "await_hello"
    READY = "ready"
    BROKEN = "broken"
    """The framing broke: nothing more is read; a server may send one last fatal error."""
    CLOSED = "closed"


class Event(StrEnum):
    """What happens on a connection: a message sent or received, or the stream breaking."""

    SEND_HELLO = "send hello"
    RECEIVE_HELLO = "receive hello"
    SEND_REQUEST = "send request"
    RECEIVE_REQUEST = "receive request"
    SEND_REPLY = "send reply"
    RECEIVE_REPLY = "receive reply"
    SEND_FATAL_ERROR = "send fatal error"
    RECEIVE_FATAL_ERROR = "receive fatal error"
    BREAK = "receive a broken frame"
    END = "reach the end of the stream"


_CLIENT, _SERVER = Role.CLIENT, Role.SERVER
_AWAIT, _READY, _BROKEN, _CLOSED = State.AWAIT_HELLO, State.READY, State.BROKEN, State.CLOSED

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
    # A frame that breaks the framing (its length over the limit) ends reading; the server
    # still says why, in one last fatal error.
    (_SERVER, _AWAIT, Event.BREAK): _BROKEN,
    (_SERVER, _READY, Event.BREAK): _BROKEN,
    (_SERVER, _BROKEN, Event.SEND_FATAL_ERROR): _CLOSED,  # the client reads it READY
    (_CLIENT, _AWAIT, Event.BREAK): _CLOSED,
    (_CLIENT, _READY, Event.BREAK): _CLOSED,
    # The end of the stream ends everything, in any state (a client is never BROKEN).
    **{
        (role, state, Event.END): _CLOSED
        for role in Role
        for state in State
        if (role, state) != (_CLIENT, _BROKEN)
    },
}
"""(role, state, event) -> the next state. Nothing else may happen."""

_COPIED = 64 * 1024  # frames up to this size are sliced out of the buffer, larger ones viewed
_PREFIX = HEADER.size
_read_prefix = HEADER.unpack_from
_write_prefix = HEADER.pack

_SENT: Final[dict[type, Event]] = {
    Hello: Event.SEND_HELLO,
    Request: Event.SEND_REQUEST,
    Response: Event.SEND_REPLY,
    BatchResponse: Event.SEND_REPLY,
    StepsResponse: Event.SEND_REPLY,
    ErrorReply: Event.SEND_REPLY,
}
_NEXT: Final[dict[tuple[Role, State], dict[Event, State]]] = {
    (role, state): {
        event: after for (r, s, event), after in TRANSITIONS.items() if (r, s) == (role, state)
    }
    for role in Role
    for state in State
}
"""The table, by (role, state): what may happen next, and where it leads."""

# The members used on every message, as module constants (an enum member's lookup is slow).
_SEND_HELLO = Event.SEND_HELLO
_RECEIVE_HELLO = Event.RECEIVE_HELLO
_SEND_REQUEST = Event.SEND_REQUEST
_RECEIVE_REQUEST = Event.RECEIVE_REQUEST
_SEND_REPLY = Event.SEND_REPLY
_RECEIVE_REPLY = Event.RECEIVE_REPLY
_SEND_FATAL_ERROR = Event.SEND_FATAL_ERROR
_RECEIVE_FATAL_ERROR = Event.RECEIVE_FATAL_ERROR
_BREAK = Event.BREAK


class Connection:
    """One end of an rlenv connection, with no I/O of its own (like h11's ``Connection``).

    Feed received bytes to :meth:`receive_data` and pull messages with :meth:`next_message`;
    turn messages into bytes to write with :meth:`send`.

    Args:
        role: which end this is.
        max_frame_size: largest frame body accepted; a larger length prefix is refused before
            any of the body is buffered.

    Attributes:
        max_send_size: largest frame body the peer accepts: the protocol's limit, until a
            client learns the server's from its hello.
    """

    def __init__(self, role: Role, max_frame_size: int = DEFAULT_MAX_FRAME_SIZE) -> None:
        self.role = role
        self.max_frame_size = max_frame_size
        self.max_send_size = DEFAULT_MAX_FRAME_SIZE
        self.state = _AWAIT
        self._next = _NEXT[(role, self.state)]
        self._buffer: bytes | bytearray = b""
        self._start = 0  # where the bytes not read yet begin in _buffer
        self._eof = False
        self._outstanding: deque[int] = deque()

    @property
    def outstanding(self) -> tuple[int, ...]:
        """Ids of the requests that have not been answered yet, oldest first."""
        return tuple(self._outstanding)

    @property
    def buffered(self) -> int:
        """Bytes received that do not form a whole frame yet."""
        return len(self._buffer) - self._start

    @property
    def peer_closed(self) -> bool:
        """Whether the peer closed its end of the stream (``receive_data(b"")`` was called)."""
        return self._eof

    def receive_data(self, data: bytes) -> None:
        """Buffer bytes read from the peer; ``b""`` means the peer closed its end."""
        buffer, start = self._buffer, self._start
        if not data:
            self._eof = True
        elif start == len(buffer):  # nothing left unread: the usual case
            self._buffer, self._start = data, 0
        else:
            if isinstance(buffer, bytes):  # a read's own bytes: copied once, to grow
                buffer = bytearray(memoryview(buffer)[start:])
                self._start = 0
            elif start > len(buffer) // 2:  # compacted once the read part is most of it
                del buffer[:start]
                self._start = 0
            buffer += data
            self._buffer = buffer

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
        state = self.state
        if state is _CLOSED or state is _BROKEN:
            if state is _BROKEN and self._eof:
                self._enter(_CLOSED)
            return CONNECTION_CLOSED
        body = self._next_frame()
        if isinstance(body, _Sentinel):
            return body
        wire = unpack(body, strict=self.role is _SERVER)
        if wire.__class__ is not dict:
            raise RemoteProtocolError(f"a frame must hold a map, got {type(wire).__name__}")
        if self.role is not _SERVER:
            return self._reply(wire)
        if _RECEIVE_REQUEST not in self._next:
            raise self._refusal(_RECEIVE_REQUEST, RemoteProtocolError)
        try:
            request = Request.from_wire(wire)
        except RemoteProtocolError as error:
            if error.request_id is not None:
                self._outstanding.append(error.request_id)  # the error reply answers it
            raise
        self._outstanding.append(request.id)
        return request

    def send(self, message: Message) -> bytes:
        """Return the frame that carries ``message``.

        Raises:
            LocalProtocolError: this side may not send ``message`` now, or it is larger than
                the peer's frame limit, or holds more objects than a frame may
                (:data:`~rlenv.protocol.codec.MAX_FRAME_OBJECTS`).
            TypeError: the message holds a value that cannot travel on the wire.
        """
        kind = message.__class__
        event = _SENT.get(kind)
        if event is None:
            raise LocalProtocolError(f"not a message: {message!r:.60}")
        if kind is ErrorReply and message.fatal:  # type: ignore[union-attr]
            event = _SEND_FATAL_ERROR
        state = self._next.get(event)
        if state is None:
            raise self._refusal(event, LocalProtocolError)
        outstanding = self._outstanding
        reply_id = None if kind is Hello or kind is Request else message.id  # type: ignore[union-attr]
        if reply_id is not None and (not outstanding or outstanding[0] != reply_id):
            raise LocalProtocolError(
                f"reply to request {reply_id} out of order; outstanding: {list(outstanding)}"
            )
        body = pack(message.to_wire())
        if len(body) > self.max_send_size:
            raise LocalProtocolError(
                f"message of {len(body)} bytes exceeds the peer's frame "
                f"limit of {self.max_send_size}"
            )
        if len(body) > MAX_FRAME_OBJECTS and count_objects(body) > MAX_FRAME_OBJECTS:
            raise LocalProtocolError(
                f"message holds more than {MAX_FRAME_OBJECTS} msgpack "
                "objects, the limit of a frame the peer reads"
            )
        if message.__class__ is Request:
            outstanding.append(message.id)
        elif reply_id is not None:
            outstanding.popleft()
        if state is not self.state:
            self._enter(state)
        return _write_prefix(len(body)) + body

    def note_request(self, request_id: int) -> None:
        """A request went by the shared-memory lane (:mod:`rlenv.transport.lanes`) instead.

        Its answer is awaited in turn, whichever way it comes back.

        Raises:
            LocalProtocolError: the connection is not ready for requests.
        """
        if self.state is not _READY:
            raise LocalProtocolError(
                f"no request may go while the connection is {self.state.value}"
            )
        self._outstanding.append(request_id)

    def note_reply(self, reply_id: int) -> None:
        """The answer to the oldest request came (or went) by the shared-memory lane.

        Raises:
            LocalProtocolError: it is not the oldest request's answer.
        """
        outstanding = self._outstanding
        if not outstanding or outstanding[0] != reply_id:
            raise LocalProtocolError(
                f"reply to request {reply_id} out of order; outstanding: {list(outstanding)}"
            )
        outstanding.popleft()

    # --- internals --------------------------------------------------------------------------

    def _refusal(self, event: Event, error: type[Exception]) -> Exception:
        """``error`` saying that ``event`` may not happen now (see :data:`TRANSITIONS`)."""
        return error(f"a {self.role.value} may not {event.value} in state {self.state.value}")

    def _enter(self, state: State) -> None:
        self.state = state
        self._next = _NEXT[(self.role, state)]

    def _next_frame(self) -> bytes | bytearray | memoryview | _Sentinel:
        """The next whole frame's body, or a sentinel.

        Pipelined frames are read at an offset into the buffer (:attr:`_start`): each costs
        its own bytes, whatever is buffered behind it.
        """
        buffer, start = self._buffer, self._start
        size = len(buffer)
        buffered = size - start
        if buffered >= _PREFIX:
            (length,) = _read_prefix(buffer, start)
            if length > self.max_frame_size:
                self._enter(self._next.get(_BREAK, _CLOSED))
                raise RemoteProtocolError(
                    f"frame length {length} exceeds the limit of {self.max_frame_size} bytes "
                    "(is the peer speaking the rlenv protocol?)",
                    fatal=True,
                )
            begin = start + _PREFIX
            end = begin + length
            if size == end:  # the last frame buffered (usually the only one of a read)
                self._buffer, self._start = b"", 0
                return buffer[begin:] if length <= _COPIED else memoryview(buffer)[begin:]
            if size > end:  # a copy: the buffer grows on (a view would pin it)
                self._start = end
                return buffer[begin:end]
        if not self._eof:
            return NEED_DATA
        self._enter(_CLOSED)
        if buffered:
            raise RemoteProtocolError(
                f"connection closed in the middle of a frame ({buffered} bytes buffered)",
                fatal=True,
            )
        return CONNECTION_CLOSED

    def _reply(self, wire: dict[str, Any]) -> Message:
        if "reward" in wire and self.state is _READY:  # a response: the usual case
            reply: Message = Response.from_wire(wire)
            event = _RECEIVE_REPLY
        elif "error" in wire:
            reply = ErrorReply.from_wire(wire)
            event = _RECEIVE_FATAL_ERROR if reply.fatal else _RECEIVE_REPLY
        elif self.state is _AWAIT:
            if "hello" not in wire:
                self._enter(_CLOSED)
                raise RemoteProtocolError("the server did not start with a hello", fatal=True)
            reply, event = Hello.from_wire(wire), _RECEIVE_HELLO
            limit = reply.limits.get("max_frame_size")
            if limit.__class__ is int and 0 < limit < DEFAULT_MAX_FRAME_SIZE:
                self.max_send_size = limit
        elif "steps" in wire:
            reply, event = StepsResponse.from_wire(wire), _RECEIVE_REPLY
        elif "batch" in wire:
            reply, event = BatchResponse.from_wire(wire), _RECEIVE_REPLY
        else:
            reply, event = Response.from_wire(wire), _RECEIVE_REPLY
        state = self._next.get(event)
        if state is None:
            raise self._refusal(event, RemoteProtocolError)
        reply_id = None if event is _RECEIVE_HELLO else reply.id  # type: ignore[union-attr]
        if reply_id is not None:
            outstanding = self._outstanding
            if not outstanding or outstanding[0] != reply_id:
                self._enter(_CLOSED)
                expected = outstanding[0] if outstanding else "none"
                raise RemoteProtocolError(
                    f"reply to request {reply_id}, expected {expected}", fatal=True
                )
            outstanding.popleft()
        if state is not self.state:
            self._enter(state)
        return reply
