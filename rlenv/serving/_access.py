"""What an endpoint tolerates and whom it lets in: limits, the loopback rule, binding errors.

An environment server is a network service and is treated like one: a frame's length is checked
against :class:`Limits` before its body is read, a client that trickles bytes or stays silent
is dropped (soon, while it has not sent the token a server requires), and a server binds
127.0.0.1 unless told otherwise, and refuses to bind anything else without a token
(:class:`InsecureBindError`).
"""

from __future__ import annotations

import errno
import socket
from dataclasses import dataclass
from typing import Any

from rlenv.protocol import DEFAULT_MAX_FRAME_SIZE
from rlenv.protocol.codec import MAX_FRAME_OBJECTS

__all__ = ["DEFAULT_HOST", "InsecureBindError", "Limits", "bind_error"]

DEFAULT_HOST = "127.0.0.1"
"""The address a server binds unless told otherwise (only this machine can reach it)."""


@dataclass(frozen=True)
class Limits:
    """How much and how long the endpoint tolerates from a client.

    Attributes:
        max_frame_size: largest request frame once the client is authenticated.
        max_unauthenticated_frame_size: largest frame before that (the first request); never
            more than ``max_frame_size`` (see :attr:`max_first_frame_size`).
        frame_deadline: seconds within which a frame, once started, must be complete.
        first_request_timeout: when a token is required, seconds a client has, from
            connecting, to send it (in its first request).
        idle_timeout: seconds a client may stay silent between requests (``None``: forever).
        write_timeout: seconds a reply may take to be written.
        max_connections: clients connected at once.
    """

    max_frame_size: int = DEFAULT_MAX_FRAME_SIZE
    max_unauthenticated_frame_size: int = 64 * 1024
    frame_deadline: float = 10.0
    first_request_timeout: float = 10.0
    idle_timeout: float | None = 3600.0
    write_timeout: float = 10.0
    max_connections: int = 8

    @property
    def max_first_frame_size(self) -> int:
        """The largest frame before the first request: the smaller of the two limits."""
        return min(self.max_unauthenticated_frame_size, self.max_frame_size)

    def to_wire(self) -> dict[str, Any]:
        """The limits as the hello announces them (see :class:`rlenv.protocol.Hello`)."""
        return {
            "max_frame_size": self.max_frame_size,
            "max_first_frame_size": self.max_first_frame_size,
            "max_reply_size": DEFAULT_MAX_FRAME_SIZE,
            "max_frame_objects": MAX_FRAME_OBJECTS,
            "frame_deadline": self.frame_deadline,
            "first_request_timeout": self.first_request_timeout,
            "idle_timeout": self.idle_timeout,
            "write_timeout": self.write_timeout,
            "max_connections": self.max_connections,
        }


class InsecureBindError(RuntimeError):
    """Binding an address other than loopback was asked for without a token."""


def bind_error(error: OSError, host: str, port: int) -> OSError:
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
