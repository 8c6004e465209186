"""Socket settings both ends use: no Nagle delay, and timeouts the kernel enforces.

A socket in Python's timeout mode makes CPython call ``poll()`` before every read and write;
a blocking socket with ``SO_RCVTIMEO`` / ``SO_SNDTIMEO`` waits in the read or write itself, and
a read or write that times out raises ``BlockingIOError``.
"""

from __future__ import annotations

import socket
import struct

__all__ = ["configure_socket"]


def configure_socket(sock: socket.socket, receive_timeout: float, send_timeout: float) -> None:
    """Set ``TCP_NODELAY`` and blocking mode with per-call timeouts on reads and writes.

    Args:
        sock: a connected TCP socket.
        receive_timeout: seconds a read may wait (``BlockingIOError`` after that).
        send_timeout: seconds a write may wait.
    """
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    sock.settimeout(None)
    for option, seconds in ((socket.SO_RCVTIMEO, receive_timeout),
                            (socket.SO_SNDTIMEO, send_timeout)):
        whole = int(seconds)
        micros = int(round((seconds - whole) * 1e6))
        if whole == 0 and micros == 0:
            micros = 1  # zero would mean "wait forever"
        sock.setsockopt(socket.SOL_SOCKET, option, struct.pack("ll", whole, micros))
