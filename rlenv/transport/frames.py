"""Reading one whole frame from a blocking socket: the codec's framing, for simple peers.

A peer that waits for each answer in turn (the tools' forked copies, the tests' and the
compliance checks' raw connections) reads with :func:`receive_frame`: the 4-byte length of
:data:`rlenv.protocol.codec.HEADER`, then that many bytes. The server and the client read
through the sans-IO :class:`~rlenv.protocol.Connection` instead, which also splits frames
that arrive together and bounds what a peer may send.
"""

from __future__ import annotations

import socket

from rlenv.protocol.codec import HEADER

__all__ = ["receive_exactly", "receive_frame"]

_CHUNK = 1 << 20
"""The most bytes one ``recv`` asks for."""


def receive_exactly(sock: socket.socket, size: int) -> bytes | None:
    """``size`` bytes from ``sock``; ``None`` if the peer closes the connection first."""
    chunks = []
    while size:
        chunk = sock.recv(min(size, _CHUNK))
        if not chunk:
            return None
        chunks.append(chunk)
        size -= len(chunk)
    return b"".join(chunks)


def receive_frame(sock: socket.socket) -> bytes | None:
    """The body of the next frame on ``sock``, undecoded; ``None`` if the peer closes first.

    Raises:
        OSError: the socket's own errors (its timeout among them).
    """
    header = receive_exactly(sock, HEADER.size)
    if header is None:
        return None
    return receive_exactly(sock, HEADER.unpack(header)[0])
