"""How both ends wait for the other's next bytes: a bounded spin, only after quick answers."""

from __future__ import annotations

import socket

import pytest

from rlenv.testing import ManualClock
from rlenv.transport.sockets import (
    CONTENDED,
    GAVE_WAY,
    REQUEST_SPIN_WINDOW,
    SPIN_WINDOW,
    AnswerWaiter,
    configure_socket,
)


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


class ScriptedClock:
    """Returns the given times in turn (a yield that took long is a jump between two)."""

    def __init__(self, *times: float) -> None:
        self.times = list(times)

    def __call__(self) -> float:
        return self.times.pop(0) if len(self.times) > 1 else self.times[0]


def spinning(waiter: AnswerWaiter) -> list[int]:
    """Spin once with an attempt that never succeeds; how many attempts it made."""
    attempts = [0]

    def attempt() -> None:
        attempts[0] += 1

    waiter.quick = True
    assert waiter.spin(attempt) is None
    return attempts


def test_a_yield_that_let_another_process_run_ends_the_spin_at_once() -> None:
    #                     before, after 1st yield, after 2nd (another process ran 200 us)
    waiter = AnswerWaiter(ScriptedClock(0.0, 1e-6, 2e-6 + GAVE_WAY * 4), window=1.0)
    assert spinning(waiter) == [2]  # not the whole second of its window
    assert 0 < waiter.lost < CONTENDED  # once is no contention: the next wait spins again
    waiter.clock = ScriptedClock(0.001, 0.001001, 0.001002, 2.0)
    assert spinning(waiter) == [3]


def test_a_waiter_that_gives_way_often_blocks_for_a_while() -> None:
    start, lost = 0.0, CONTENDED * 0.6
    waiter = AnswerWaiter(ScriptedClock(start, start + lost), window=1.0)
    assert spinning(waiter) == [1]
    waiter.clock = ScriptedClock(start + lost, start + 2 * lost + 1e-6)  # again, soon after
    assert spinning(waiter) == [1]
    waiter.clock = ScriptedClock(start + 0.01)
    assert spinning(waiter) == [0]  # contended: blocks at once, without spinning
    waiter.clock = ScriptedClock(0.5, 0.5 + 1e-6, 0.9)  # long after: spins again
    assert spinning(waiter) == [2]
