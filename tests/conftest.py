"""Shared fixtures: real servers in subprocesses, each ended after the test."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import pytest

from examples.cartpole import TARGET
from rlenv.transport._procfs import alive as alive  # the tests import it from here
from rlenv.tree import SceneTree
from rlenv_client import Client, ServerProcess

Serve = Callable[..., ServerProcess]


def wait_until(condition: Callable[[], bool], message: str, seconds: float = 30.0) -> None:
    """Poll ``condition`` until it holds (no fixed sleep)."""
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, message
        time.sleep(0.05)


@pytest.fixture
def serve() -> Iterator[Serve]:
    """Start servers for ``MODULE:CLASS`` targets; all are closed when the test ends."""
    started: list[ServerProcess] = []

    def start(target: str = TARGET, **kwargs: object) -> ServerProcess:
        process = ServerProcess(target, **kwargs)  # type: ignore[arg-type]
        started.append(process)
        return process

    yield start
    for process in started:
        process.close()


@pytest.fixture(autouse=True)
def _sessions_closed(request: pytest.FixtureRequest) -> Iterator[None]:
    """A test's HTTP gateway sessions are deleted after it, as a user's would be: a module's
    shared ``gateway`` holds at most so many sessions per client."""
    yield
    if "gateway" in request.fixturenames:
        close = getattr(request.getfixturevalue("gateway"), "close_sessions", None)
        if close is not None:
            close()


@pytest.fixture
def server(serve: Serve) -> ServerProcess:
    """A fresh CartPole server on a free port."""
    return serve()


@pytest.fixture
def client(server: ServerProcess) -> Iterator[Client]:
    """A client connected to a fresh CartPole server."""
    with Client(server.host, server.port, timeout=10) as connected:
        yield connected


@pytest.fixture
def tree() -> SceneTree:
    """An empty scene tree at 60 physics ticks per second."""
    return SceneTree(60)


@pytest.fixture
def log() -> list:
    """A list that test nodes record their calls into."""
    return []


_FIGURES: dict[str, str] = {}


@pytest.fixture
def figures() -> dict[str, str]:
    """Figures a test measured; printed at the end of the run (``name -> one line``)."""
    return _FIGURES


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    """Print the figures the tests recorded."""
    if _FIGURES:
        terminalreporter.section("figures")
        for name, line in _FIGURES.items():
            terminalreporter.write_line(f"{name}: {line}")
