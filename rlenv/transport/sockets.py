"""Socket settings both ends use, and how they wait for the other end's next bytes.

A socket in Python's timeout mode makes CPython call ``poll()`` before every read and write;
a blocking socket with ``SO_RCVTIMEO`` / ``SO_SNDTIMEO`` waits in the read or write itself, and
a read or write that times out raises ``BlockingIOError``.

A process that blocks in a read sleeps, and waking it takes the kernel tens to hundreds of
microseconds on a small virtual machine: more than a step of a simple environment. So an
:class:`AnswerWaiter` spins for a short, bounded while before it blocks, but only when the
other end answered within that window the previous time, and it yields its core at every
turn (a process waiting for the core runs first). A client spins up to :data:`SPIN_WINDOW` for
an answer (a server stepping a trainer's 8 CartPoles takes ~150 us); a server spins up to
:data:`REQUEST_SPIN_WINDOW` for its controller's next request, which comes after the trainer's
own work on the answer (a policy's forward pass, a vector's bookkeeping): measured here, a 1 ms
window made SB3 PPO on one environment and an 8-environment vector a fifth to a half faster
than 100 us. But spinning only pays on a core nobody else wants: a yield that let another
process run (torch's own spinning threads, another program) ends the spin, and a waiter that
gives way often blocks for a while (``docs/training-fast.md`` has the figures).
"""

from __future__ import annotations

import ipaddress
import os
import socket
import struct
import time
from collections.abc import Callable
from typing import TypeVar

__all__ = [
    "CONTENDED",
    "GAVE_WAY",
    "REQUEST_SPIN_WINDOW",
    "SPIN_WINDOW",
    "AnswerWaiter",
    "configure_socket",
    "is_loopback",
    "readable_now",
]

SPIN_WINDOW = 300e-6
"""Seconds after a request within which a client spins for its answer (if the last came so)."""

REQUEST_SPIN_WINDOW = 1e-3
"""Seconds after an answer within which a server spins for the next request (likewise)."""

GAVE_WAY = 50e-6
"""A yield that took longer than this (seconds) let another process run on this core."""

CONTENDED = 1e-3
"""Seconds lost to other processes while spinning (halving every :data:`CONTENDED_HALF_LIFE`)
beyond which a waiter stops spinning for :data:`CONTENDED_BACKOFF`."""

CONTENDED_HALF_LIFE = 20e-3
CONTENDED_BACKOFF = 50e-3

_DONTWAIT = socket.MSG_DONTWAIT
_PEEK = socket.MSG_PEEK | socket.MSG_DONTWAIT
_yield = os.sched_yield
_Got = TypeVar("_Got")


class AnswerWaiter:
    """Reads a socket's next bytes, spinning first when they came quickly the last time.

    Call :meth:`sent` when the other end was asked something, then :meth:`recv`; a waiter
    that watches more than a socket (:func:`rlenv.transport.lanes.wait_for`) calls :meth:`spin`,
    then blocks its own way, then :meth:`ended`.

    Args:
        clock: monotonic time in seconds (tests pass their own).
        window: seconds after :meth:`sent` within which an answer counts as quick.

    Attributes:
        calm_at: until when the waiter blocks at once (it gave way too often).
        clock: as given.
        lost: seconds other processes took from this one's spins lately (decaying).
        lost_at: when :attr:`lost` was last added to.
        quick: the last answer came within ``window`` of its question, so the next one is
            spun for.
        since: when the other end was last asked (:meth:`sent`).
        window: as given.
    """

    __slots__ = ("calm_at", "clock", "lost", "lost_at", "quick", "since", "window")

    def __init__(
        self, clock: Callable[[], float] = time.perf_counter, window: float = SPIN_WINDOW
    ) -> None:
        self.clock = clock
        self.window = window
        self.quick = False
        self.since = 0.0
        self.calm_at = 0.0
        self.lost = 0.0
        self.lost_at = 0.0

    def sent(self) -> None:
        """The other end was just asked: its answer is awaited from now."""
        self.since = self.clock()

    def spin(self, attempt: Callable[[], _Got | None]) -> _Got | None:
        """Call ``attempt`` until it gives something, while the answer may still come quickly.

        Only when the last answer was quick, and only until ``window`` after :meth:`sent`,
        yielding the core between attempts; ``None`` if nothing came in that time. A yield
        that let another process run (:data:`GAVE_WAY`) ends the spin at once: that process
        needs this core, and a process that spins keeps it from it (it waits its turn instead
        of being woken). When that happens often (:data:`CONTENDED`), spinning stops for a
        while: the waiter then blocks at once.
        """
        if not self.quick:
            return None
        now = self.clock
        before = now()
        if before < self.calm_at:
            return None
        deadline = self.since + self.window
        while before < deadline:
            got = attempt()
            if got is not None:
                return got
            _yield()  # a process waiting for this core runs first
            after = now()
            if after - before > GAVE_WAY:  # another process ran here: leave it the core
                self._gave_way(after, after - before)
                return None
            before = after
        return None

    def _gave_way(self, now: float, lost: float) -> None:
        """A yield let another process run for ``lost`` seconds; too often, and spinning stops."""
        self.lost = self.lost * 0.5 ** ((now - self.lost_at) / CONTENDED_HALF_LIFE) + lost
        self.lost_at = now
        if self.lost >= CONTENDED:
            self.lost = 0.0
            self.calm_at = now + CONTENDED_BACKOFF

    def ended(self) -> None:
        """The wait ended (answered, timed out or failed): note whether it was quick."""
        self.quick = self.clock() - self.since < self.window

    def recv(self, sock: socket.socket, size: int) -> bytes:
        """What ``sock`` has next, at most ``size`` bytes (blocking, with its kernel timeout).

        Raises:
            BlockingIOError: the socket's receive timeout passed.
            OSError: the connection failed.
        """
        try:
            data = self.spin(lambda: _received_now(sock, size))
            return sock.recv(size) if data is None else data
        finally:  # a timeout or an error counts as a slow answer
            self.ended()


def _received_now(sock: socket.socket, size: int) -> bytes | None:
    """What ``sock`` has now (``b""``: it reached its end), or ``None`` if nothing yet."""
    try:
        return sock.recv(size, _DONTWAIT)
    except BlockingIOError:
        return None


def readable_now(sock: socket.socket) -> bool:
    """Whether reading ``sock`` would not block: it has bytes, reached its end, or failed.

    One non-blocking peek at a byte, which stays unread: reading then gets the bytes, the end
    or the error.
    """
    try:
        sock.recv(1, _PEEK)
    except BlockingIOError:
        return False
    except OSError:  # reading says what failed, at once
        pass
    return True


def configure_socket(sock: socket.socket, receive_timeout: float, send_timeout: float) -> None:
    """Set ``TCP_NODELAY`` and blocking mode with per-call timeouts on reads and writes.

    Args:
        sock: a connected TCP socket.
        receive_timeout: seconds a read may wait (``BlockingIOError`` after that).
        send_timeout: seconds a write may wait.
    """
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    sock.settimeout(None)
    for option, seconds in (
        (socket.SO_RCVTIMEO, receive_timeout),
        (socket.SO_SNDTIMEO, send_timeout),
    ):
        whole = int(seconds)
        micros = int(round((seconds - whole) * 1e6))
        if whole == 0 and micros == 0:
            micros = 1  # zero would mean "wait forever"
        sock.setsockopt(socket.SOL_SOCKET, option, struct.pack("ll", whole, micros))


def format_address(host: str, port: int) -> str:
    """``HOST:PORT``, the IPv6 host in brackets (``[::1]:5000``)."""
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def address_family(host: str) -> socket.AddressFamily:
    """``AF_INET6`` for an IPv6 address (it holds a colon), else ``AF_INET``."""
    return socket.AF_INET6 if ":" in host else socket.AF_INET


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address, or ``localhost``) is a loopback address."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
