"""Errors shared by the server and the client, and the error codes that travel on the wire.

Two families, as in h11: a :class:`LocalProtocolError` means *we* broke the protocol (a bug on
this side), a :class:`RemoteProtocolError` means the peer sent something that is not the
protocol. A :class:`RequestError` is a well-formed request the environment refuses (a wrong
action shape, a step before reset); the server turns it into an error reply and keeps serving.
On the client, an error reply becomes a :class:`RemoteError` carrying the server's code and
message.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = [
    "ConnectionLost",
    "ErrorCode",
    "LocalProtocolError",
    "ProtocolError",
    "ProtocolVersionError",
    "RemoteError",
    "RemoteProtocolError",
    "RequestError",
    "RequestTimeout",
    "RlenvError",
]


class ErrorCode(StrEnum):
    """Machine-readable reason carried by every error reply."""

    BAD_FRAME = "bad_frame"
    """The bytes are not a frame: bad length prefix, invalid msgpack, trailing bytes."""
    BAD_REQUEST = "bad_request"
    """A frame that decodes but is not a valid request: unknown key, wrong type."""
    INVALID_ACTION = "invalid_action"
    """The action does not belong to the agent's action space."""
    INVALID_CONFIG = "invalid_config"
    """A configuration key or value the environment does not accept."""
    RESET_REQUIRED = "reset_required"
    """A step or observation was asked for before the first reset or after the episode ended."""
    BUSY = "busy"
    """Another client already controls this environment."""
    UNAUTHORIZED = "unauthorized"
    """The server requires a token and the first request did not carry the right one."""
    TIMEOUT = "timeout"
    """The client took too long: a frame did not complete in time, or it stayed idle."""
    ENVIRONMENT_ERROR = "environment_error"
    """User code inside the environment raised; the message names the node and the traceback."""


class RlenvError(Exception):
    """Base class of every error rlenv raises on purpose."""


class ProtocolError(RlenvError):
    """The byte stream or a message in it does not follow the protocol.

    Attributes:
        code: the error code an error reply for this problem carries.
        fatal: the stream cannot be read further (broken framing); the connection must close.
        request_id: the id of the request at fault, when it could be read.
    """

    def __init__(
        self,
        message: str,
        code: ErrorCode = ErrorCode.BAD_FRAME,
        *,
        fatal: bool = False,
        request_id: int | None = None,
    ) -> None:
        super().__init__(message)
        self.code = code
        self.fatal = fatal
        self.request_id = request_id


class LocalProtocolError(ProtocolError):
    """This side tried to do something the protocol forbids (a bug on this side)."""


class RemoteProtocolError(ProtocolError):
    """The peer sent bytes or a message that the protocol forbids."""


class ProtocolVersionError(RlenvError):
    """The peer speaks an incompatible major version of the protocol."""


class RequestError(RlenvError):
    """A well-formed request that the environment refuses; it changes no state.

    Attributes:
        code: the error code of the reply.
    """

    def __init__(self, code: ErrorCode, message: str) -> None:
        super().__init__(message)
        self.code = code


class RemoteError(RlenvError):
    """The server answered a request with an error reply.

    Unless ``fatal``, the connection stays open and the client can go on: a refused request
    changed nothing (after an ``environment_error`` while acting, reset first).

    Attributes:
        code: the server's error code (an :class:`ErrorCode` value when known).
        message: the server's explanation.
        fatal: whether the server closes the connection after this error.
    """

    def __init__(self, code: str, message: str, fatal: bool = False) -> None:
        super().__init__(f"[{code}] {message}")
        self.code = code
        self.message = message
        self.fatal = fatal


class ConnectionLost(RlenvError, ConnectionError):
    """The connection to the peer closed or broke (also a ``ConnectionError``)."""


class RequestTimeout(RlenvError, TimeoutError):
    """The peer did not answer within the deadline; the connection was closed.

    Also a ``TimeoutError``. Closing it means a late answer is never taken for the answer to a
    later request: connect again to go on.
    """
