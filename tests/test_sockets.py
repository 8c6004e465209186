"""How both ends wait for the other's next bytes: a bounded spin, only after quick answers."""

from __future__ import annotations

import socket

import pytest

from rlenv.protocol.sockets import REQUEST_SPIN_WINDOW, SPIN_WINDOW, AnswerWaiter, configure_socket
from rlenv.testing import ManualClock


@pytest.fixture
def pair() -> tuple[socket.socket, socket.socket]:
    """Two ends of a loopback TCP connection; ours times out reads after 50 ms."""
    with socket.create_server(("127.0.0.1", 0)) as listener:
        theirs = socket.create_connection(listener.getsockname())
        ours, _ = listener.accept()
    configure_socket(ours, 0.05, 1.0)
    yield ours, theirs
    ours.close()
    theirs.close()


def test_it_spins_only_after_an_answer_that_came_within_the_window(pair) -> None:
    ours, theirs = pair
    clock = ManualClock()
    waiter = AnswerWaiter(clock)
    assert not waiter.quick  # nothing known yet: block
    waiter.sent()
    theirs.sendall(b"one")
    clock.advance(SPIN_WINDOW / 2)
    assert waiter.recv(ours, 64) == b"one" and waiter.quick
    waiter.sent()
    theirs.sendall(b"two")  # spun for: already there
    assert waiter.recv(ours, 64) == b"two"
    waiter.sent()
    theirs.sendall(b"three")
    clock.advance(SPIN_WINDOW * 3)  # the window is over: a slow answer, blocked for
    assert waiter.recv(ours, 64) == b"three" and not waiter.quick


def test_a_spinning_wait_still_ends_with_the_sockets_timeout(pair) -> None:
    ours, _ = pair
    waiter = AnswerWaiter()
    waiter.quick = True
    waiter.sent()
    with pytest.raises(BlockingIOError):  # spun for the window, then blocked 50 ms
        waiter.recv(ours, 64)
    assert not waiter.quick


def test_a_closed_peer_reads_as_the_end_of_the_stream(pair) -> None:
    ours, theirs = pair
    waiter = AnswerWaiter()
    waiter.quick = True
    waiter.sent()
    theirs.close()
    assert waiter.recv(ours, 64) == b""


def test_a_servers_window_is_its_own(pair) -> None:
    ours, theirs = pair
    clock = ManualClock()
    waiter = AnswerWaiter(clock, window=REQUEST_SPIN_WINDOW)
    waiter.sent()
    theirs.sendall(b"next request")
    clock.advance(REQUEST_SPIN_WINDOW / 2)  # slower than a client's window, quick for a server
    assert REQUEST_SPIN_WINDOW / 2 > SPIN_WINDOW
    assert waiter.recv(ours, 64) == b"next request" and waiter.quick
