"""Socket settings both ends use, and how they wait for the other end's next bytes.

A socket in Python's timeout mode makes CPython call ``poll()`` before every read and write;
a blocking socket with ``SO_RCVTIMEO`` / ``SO_SNDTIMEO`` waits in the read or write itself, and
a read or write that times out raises ``BlockingIOError``.

A process that blocks in a read sleeps, and waking it takes the kernel tens to hundreds of
microseconds on a small virtual machine: more than a step of a simple environment. So an
:class:`AnswerWaiter` spins for a short, bounded while (:data:`SPIN_WINDOW`) before it blocks,
but only when the other end answered within that window the previous time: a client stepping
a fast environment gets its answer without sleeping, and neither end burns a core waiting for
a peer that takes longer (a vector's servers, a trainer's forward pass).
"""

from __future__ import annotations

import socket
import struct
import time
from collections.abc import Callable

__all__ = ["SPIN_WINDOW", "AnswerWaiter", "configure_socket"]

SPIN_WINDOW = 100e-6
"""Seconds after sending within which an answer is expected quickly enough to spin for."""

_DONTWAIT = socket.MSG_DONTWAIT


class AnswerWaiter:
    """Reads a socket's next bytes, spinning first when they came quickly the last time.

    Call :meth:`sent` when the other end was asked something, then :meth:`recv`.

    Args:
        clock: monotonic time in seconds (tests pass their own).

    Attributes:
        quick: the last answer came within :data:`SPIN_WINDOW` of its question, so the next
            one is spun for.
    """

    __slots__ = ("_now", "_since", "quick")

    def __init__(self, clock: Callable[[], float] = time.perf_counter) -> None:
        self._now = clock
        self.quick = False
        self._since = 0.0

    def sent(self) -> None:
        """The other end was just asked: its answer is awaited from now."""
        self._since = self._now()

    def recv(self, sock: socket.socket, size: int) -> bytes:
        """What ``sock`` has next, at most ``size`` bytes (blocking, with its kernel timeout).

        Raises:
            BlockingIOError: the socket's receive timeout passed.
            OSError: the connection failed.
        """
        now = self._now
        if self.quick:
            deadline = self._since + SPIN_WINDOW
            while now() < deadline:
                try:
                    return sock.recv(size, _DONTWAIT)
                except BlockingIOError:
                    continue
        try:
            return sock.recv(size)
        finally:  # a timeout or an error counts as a slow answer
            self.quick = now() - self._since < SPIN_WINDOW


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
