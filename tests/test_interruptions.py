"""Ctrl-C while a client waits for an answer: every client path stays in step afterwards.

Each test runs a client process (``tests/interrupted.py``) against real servers, holds one
answer back by stopping a server (SIGSTOP) once the request sits in that server's receive
queue (or, through a shared-memory lane, once the client sleeps waiting for the answer), sends
the client a real SIGINT, and lets the server go on. The client catches the
``KeyboardInterrupt`` as a notebook does and makes its next calls: each must get its own answer
(the observations count the ticks since the reset, so a stale answer would show), never the
interrupted request's.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import pytest

from rlenv_client import ServerProcess

TESTS = Path(__file__).resolve().parent
COUNTING = "examples.faulty:CountingEnvironment"
DEADLINE = 20.0
TRANSPORTS = pytest.mark.parametrize("transport", ["socket", "lane"])


@contextmanager
def servers(count: int) -> Iterator[list[ServerProcess]]:
    started = [ServerProcess(COUNTING) for _ in range(count)]
    try:
        yield started
    finally:
        for server in started:
            os.kill(server.pid, signal.SIGCONT)
            server.close()


def queued_bytes(port: int) -> int:
    """Bytes waiting in the receive queue of the server's connections on ``port``."""
    total = 0
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with open(table) as rows:
            next(rows)
            for row in rows:
                fields = row.split()
                local_port = int(fields[1].rsplit(":", 1)[1], 16)
                if local_port == port and fields[3] == "01":  # ESTABLISHED
                    total += int(fields[4].split(":")[1], 16)
    return total


_POLL = "7"  # the poll system call's number on x86-64 (a lane's client sleeps in it)


def sleeps_in_poll(pid: int) -> bool:
    """Whether the process's main thread is blocked in ``poll`` (what a lane's client waits in)."""
    with open(f"/proc/{pid}/syscall") as call:
        return call.read().split()[0] == _POLL


def until(condition: object, what: str) -> None:
    deadline = time.monotonic() + DEADLINE
    while not condition():  # type: ignore[operator]
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.002)  # a polling interval, not a wait for something to happen


def interrupt(path: str, addresses: Sequence[str], held: ServerProcess, transport: str) -> dict:
    """Run the client process; interrupt its call that ``held`` (stopped) must answer.

    ``transport`` is ``socket`` (``RLENV_SHARED_MEMORY=0``) or ``lane`` (the default).
    """
    environment = {**os.environ, "RLENV_SHARED_MEMORY": "0" if transport == "socket" else "1"}
    process = subprocess.Popen(
        [sys.executable, str(TESTS / "interrupted.py"), path, *addresses],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=environment,
    )
    try:
        assert process.stdout.readline().strip() == "ready", process.stderr.read()
        os.kill(held.pid, signal.SIGSTOP)
        queued = queued_bytes(held.port)
        process.stdin.write("go\n")
        process.stdin.flush()
        assert process.stdout.readline().strip() == "waiting"
        if transport == "socket":
            until(lambda: queued_bytes(held.port) > queued, "the request to reach the server")
        else:  # the request is in memory once sent; the client then sleeps on the doorbell
            until(
                lambda: all(sleeps_in_poll(process.pid) for _ in range(3)),
                "the client to wait for the held answer",
            )
        process.send_signal(signal.SIGINT)
        assert process.stdout.readline().strip() == "interrupted"
        os.kill(held.pid, signal.SIGCONT)  # the held answer comes now, before the next ones
        out, err = process.communicate(timeout=DEADLINE)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 0, err
    return json.loads(out.strip().splitlines()[-1])


@TRANSPORTS
def test_the_client_drops_the_interrupted_answer(transport: str) -> None:
    with servers(1) as (server,):
        result = interrupt("client", [server.address], server, transport)
    assert result["interrupted"] == "KeyboardInterrupt"
    assert result["reset"] == [0.0] and result["reset_frames"] == 0  # not the held step's 12
    assert result["step"] == [2.0] and result["step_frames"] == 2


@TRANSPORTS
def test_remote_env_stays_in_step(transport: str) -> None:
    with servers(1) as (server,):
        result = interrupt("env", [server.address], server, transport)
    assert result["interrupted"] == "KeyboardInterrupt"
    assert result["reset"] == [0.0]
    assert result["step"] == [4.0] and result["step_frames"] == 4
    assert not result["restarted"]


@TRANSPORTS
def test_the_vector_ends_the_interrupted_episodes_and_goes_on(transport: str) -> None:
    with servers(2) as (first, second):
        result = interrupt("vector", [first.address, second.address], second, transport)
    assert result["interrupted"] == "KeyboardInterrupt"
    assert result["after"] == [[4.0], [4.0]]  # the last observations the trainer saw
    assert result["truncated"] == [True, True]
    assert all("interrupted (KeyboardInterrupt)" in why for why in result["why"])
    assert result["reset"] == [[0.0], [0.0]]  # the autoreset, not the held answer's [8.0]
    assert result["reset_truncated"] == [False, False] and result["reset_frames"] == [0, 0]
    assert result["stepped"] == [[4.0], [4.0]]


@TRANSPORTS
def test_sb3_vec_env_ends_the_interrupted_episodes_and_goes_on(transport: str) -> None:
    pytest.importorskip("stable_baselines3")
    with servers(2) as (first, second):
        result = interrupt("sb3", [first.address, second.address], second, transport)
    assert result["interrupted"] == "KeyboardInterrupt"
    assert result["dones"] == [True, True]
    assert all(why and "interrupted" in why for why in result["why"])
    assert result["after"] == [[0.0], [0.0]]  # SB3's convention: the next episode's first
    assert result["stepped"] == [[4.0], [4.0]]


def test_the_inspectors_watcher_pairs_each_answer_with_its_request() -> None:
    with servers(1) as (server,):
        result = interrupt("watcher", [server.address], server, "socket")  # no lane: observers
    assert result["interrupted"] == "KeyboardInterrupt"
    assert {"episodes", "steps", "current"} <= set(result["stats_keys"])  # not the snapshot
    assert result["node_path"].endswith("/World")
