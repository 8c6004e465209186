"""Testing support, shipped so that any rlenv server and client can be tested the way ours are.

The compliance suite for a running server, which drives it as a client does, is
:func:`rlenv_tools.compliance.check_server`. Here:

- :func:`connection_pair`: a client and a server :class:`~rlenv.protocol.Connection` wired
  back to back, for protocol tests without sockets.
- :class:`ManualClock`: a clock that moves only when told, for deadline tests without sleeping;
- :func:`frame` and :func:`read_frame`: one frame on a raw socket, for hostile-client tests.
"""

from __future__ import annotations

import socket
from typing import Any

from rlenv.protocol import Connection, Hello, Role, unpack
from rlenv.protocol.codec import HEADER
from rlenv.transport.frames import receive_frame

__all__ = ["ManualClock", "connection_pair", "frame", "read_body", "read_frame"]


class ManualClock:
    """A monotonic clock for tests: it stands still until :meth:`advance` is called."""

    def __init__(self, start: float = 1000.0) -> None:
        self.now = start

    def __call__(self) -> float:
        """The current (manual) time, in seconds."""
        return self.now

    def advance(self, seconds: float) -> None:
        """Move the clock forward."""
        self.now += seconds


def connection_pair(hello: Hello) -> tuple[Connection, Connection]:
    """A (client, server) pair of connections after the handshake, for sans-IO tests."""
    client, server = Connection(Role.CLIENT), Connection(Role.SERVER)
    client.receive_data(server.send(hello))
    client.next_message()
    return client, server


def frame(body: bytes) -> bytes:
    """``body`` with its 4-byte length prefix: one frame, to send on a raw socket."""
    return HEADER.pack(len(body)) + body


def read_frame(sock: socket.socket) -> dict[str, Any]:
    """Read one frame from a raw socket and decode it (it must hold a map).

    Raises:
        AssertionError: the peer closed the connection first, or sent something else.
    """
    message = unpack(read_body(sock))
    assert isinstance(message, dict), f"the server sent a non-map {message!r:.100}"
    return message


def read_body(sock: socket.socket) -> bytes:
    """Read one frame from a raw socket; its body, undecoded.

    Raises:
        AssertionError: the peer closed the connection first.
    """
    body = receive_frame(sock)
    assert body is not None, "the server closed the connection without an answer"
    return body
