"""The shared-memory lane's I/O, for both ends: the block, the doorbell, waiting on both.

How a lane is set up (protocol 2.3, ``docs/protocol.md``):

1. the client listens on an abstract Unix socket named ``rlenv-lane-<32 hex digits>``
   (:func:`listen_for_lane`) and sends the ``shared_memory`` request, naming it and a random
   16-byte key, on its TCP connection;
2. the server creates the block (``memfd_create``: no name in any file system, gone with the
   last mapping), connects to that socket and sends the key with the block's descriptor
   (``SCM_RIGHTS``) (:func:`open_lane`); then it answers the request with the layout;
3. the client accepts the connection, checks the key and maps the block
   (:func:`accept_lane`).

The Unix connection stays open as the lane's **doorbell**: after writing its slots, each end
sends one byte on it (:meth:`Lane.ring`), and an end that waits sleeps in ``poll`` on the
doorbell and its TCP socket together (:func:`wait_for`); either end's death closes it. An end
that spins (see :mod:`rlenv.transport.sockets`) sees the other's sequence number change in
memory without any system call; the bytes it did not need stay unread until it next sleeps.
"""

from __future__ import annotations

import mmap
import os
import re
import secrets
import select
import socket
from collections.abc import Callable

from rlenv.protocol.messages import Hello
from rlenv.protocol.shared_memory import Layout, Slots
from rlenv.transport.sockets import AnswerWaiter, readable_now

__all__ = [
    "LANE_NAME",
    "KEY_SIZE",
    "Lane",
    "LaneClosed",
    "accept_lane",
    "listen_for_lane",
    "open_lane",
    "wait_for",
]

LANE_NAME = re.compile(r"rlenv-lane-[0-9a-f]{32}")
"""The only names a server connects to (abstract Unix sockets, with this prefix)."""
KEY_SIZE = 16
"""Bytes of the key that proves the lane's connection came from the server."""

_DONTWAIT = socket.MSG_DONTWAIT
_RING = b"\x01"


class LaneClosed(ConnectionError):
    """The other end closed the lane (it exited, or closed its connection)."""


class Lane:
    """One end of a lane: the shared block's slots and the doorbell.

    Args:
        memory: the mapped block.
        doorbell: the Unix connection between the two ends.
        slots: the block, seen through its layout.
        sock: this end's TCP socket, watched with the doorbell while waiting.
    """

    def __init__(
        self, memory: mmap.mmap, doorbell: socket.socket, slots: Slots, sock: socket.socket
    ) -> None:
        self.memory, self.doorbell, self.slots, self.sock = memory, doorbell, slots, sock
        self.doorbell.setblocking(False)
        self._poll = select.poll()
        self._poll.register(doorbell, select.POLLIN)
        self._poll.register(sock, select.POLLIN)
        self._doorbell_fd = doorbell.fileno()

    def ring(self) -> None:
        """Wake the other end, if it sleeps (a full doorbell means it has bytes already)."""
        try:
            self.doorbell.send(_RING, _DONTWAIT)
        except OSError:  # full (BlockingIOError), or the other end is gone: waiting says so
            pass

    def sleep(self, timeout: float | None) -> bool:
        """Sleep until the doorbell rings or the socket has bytes; whether the socket has.

        Raises:
            LaneClosed: the other end closed the doorbell.
        """
        events = self._poll.poll(None if timeout is None else max(0, int(timeout * 1000) + 1))
        socket_ready = False
        for fd, _ in events:
            if fd == self._doorbell_fd:
                self.drain()
            else:
                socket_ready = True
        return socket_ready

    def drain(self) -> None:
        """Read the doorbell's waiting bytes.

        Raises:
            LaneClosed: the other end closed it.
        """
        try:
            if not self.doorbell.recv(4096, _DONTWAIT):
                raise LaneClosed("the other end closed the shared-memory lane")
        except (BlockingIOError, InterruptedError):
            pass
        except ConnectionResetError:  # it closed with rings unread: a close all the same
            raise LaneClosed("the other end closed the shared-memory lane") from None
        except OSError as error:
            raise LaneClosed(f"the shared-memory lane failed: {error}") from None

    def close(self) -> None:
        """Close the doorbell and unmap the block; safe to repeat.

        Views of an answer still held (``receive_steps(copy=False)``) keep the block mapped
        until they are gone.
        """
        if self.doorbell.fileno() < 0:
            return
        self.doorbell.close()
        self.slots.release()
        try:
            self.memory.close()
        except BufferError:  # views still held: the block goes with the last of them
            pass


def wait_for(
    ready: Callable[[], bool], lane: Lane, waiter: AnswerWaiter, timeout: float | None
) -> bool:
    """Wait until ``ready()`` (what was awaited is in the slots) or the lane's socket has bytes.

    Spins first (:meth:`AnswerWaiter.spin`), looking at the slots and the socket in turn; then
    sleeps on both.

    Returns:
        True once ``ready()``; False when reading the socket would not block: it has bytes,
        reached its end, or failed (reading it then says how).

    Raises:
        BlockingIOError: ``timeout`` seconds passed.
        LaneClosed: the other end closed the lane.
        OSError: polling the doorbell and the socket failed.
    """
    sock = lane.sock

    def attempt() -> bool | None:
        if ready():
            return True
        return False if readable_now(sock) else None

    now = waiter.clock
    try:
        got = waiter.spin(attempt)
        if got is not None:
            return got
        end = None if timeout is None else now() + timeout
        while not ready():
            left = None if end is None else end - now()
            if left is not None and left <= 0:
                raise BlockingIOError("timed out")
            if lane.sleep(left):
                return False
        return True
    finally:  # a timeout or an error counts as a slow answer
        waiter.ended()


def listen_for_lane() -> tuple[socket.socket, str, bytes]:
    """The client's first move: a listening socket, its name and the key to expect."""
    name = f"rlenv-lane-{secrets.token_hex(16)}"
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        listener.bind("\0" + name)
        listener.listen(1)
    except BaseException:
        listener.close()
        raise
    return listener, name, secrets.token_bytes(KEY_SIZE)


def open_lane(name: str, key: bytes, hello: Hello, sock: socket.socket) -> Lane:
    """The server's end: create the block, hand it to the client at ``name`` with ``key``.

    Raises:
        ValueError: ``name`` or ``key`` is not what a client sends, or no lane can carry this
            server's steps (the message says why).
        OSError: the client's socket cannot be reached.
    """
    if not isinstance(name, str) or not LANE_NAME.fullmatch(name):
        raise ValueError("shared_memory.address must be 'rlenv-lane-' and 32 hex digits")
    if not isinstance(key, bytes) or len(key) != KEY_SIZE:
        raise ValueError(f"shared_memory.key must be {KEY_SIZE} bytes")
    layout = Layout.for_hello(hello)
    block = os.memfd_create("rlenv-lane", os.MFD_CLOEXEC)
    try:
        doorbell = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            os.ftruncate(block, layout.size)
            memory = mmap.mmap(block, layout.size)
            doorbell.settimeout(1.0)
            doorbell.connect("\0" + name)
            socket.send_fds(doorbell, [key], [block])
        except BaseException:
            doorbell.close()
            raise
    finally:
        os.close(block)  # the mapping and the client's copy keep the block
    return Lane(memory, doorbell, Slots(memory, layout, hello), sock)


def accept_lane(
    listener: socket.socket, key: bytes, hello: Hello, sock: socket.socket, timeout: float
) -> Lane:
    """The client's end, once the server answered: take the block the server sent.

    Raises:
        OSError: the server did not connect, sent the wrong key, or a block of the wrong size.
    """
    layout = Layout.for_hello(hello)
    listener.settimeout(timeout)
    doorbell, _ = listener.accept()
    try:
        doorbell.settimeout(timeout)
        message, fds, _, _ = socket.recv_fds(doorbell, KEY_SIZE, 1)
        try:
            if message != key or len(fds) != 1:
                raise OSError("the shared-memory lane's connection did not carry its key")
            if os.fstat(fds[0]).st_size != layout.size:
                raise OSError(
                    f"the server's block is {os.fstat(fds[0]).st_size} bytes, "
                    f"expected {layout.size}"
                )
            memory = mmap.mmap(fds[0], layout.size)
        finally:
            for fd in fds:
                os.close(fd)
    except BaseException:
        doorbell.close()
        raise
    return Lane(memory, doorbell, Slots(memory, layout, hello), sock)
