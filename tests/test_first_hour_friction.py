"""What a new user hit next (issue 32, F): statistics, hints, a port in use, Ctrl-C, replays,
addresses, a normal close taken for a failure.

Stable-Baselines3's episode statistics are tested in ``test_sb3`` (they need the extra).
"""

from __future__ import annotations

import mmap
import re
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from conftest import Serve
from gymnasium import spaces

from examples.cartpole import TARGET
from rlenv.protocol import Connection, Hello, Role
from rlenv.protocol.shared_memory import Layout, Slots
from rlenv.transport.lanes import Lane, LaneClosed
from rlenv_client import Client, RemoteEnv
from rlenv_client.replay import RecordEpisodes

ROOT = Path(__file__).resolve().parent.parent


# --- a recorded episode names its target ------------------------------------------------------


def test_an_episode_recorded_from_a_remote_env_replays_with_no_target_given(tmp_path: Path) -> None:
    env = RecordEpisodes(RemoteEnv(TARGET, repeat_action=2), tmp_path)
    try:
        env.reset(seed=3)
        terminated = truncated = False
        while not (terminated or truncated):
            _, _, terminated, truncated, _ = env.step(np.array([0.5], np.float32))
    finally:
        env.close()
    result = subprocess.run(
        [sys.executable, "-m", "rlenv", "replay", str(tmp_path / "episode-0001.rlenv")],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert result.returncode == 0, result.stderr
    assert "every observation identical" in result.stdout


# --- one address or two arguments ----------------------------------------------------------------


def test_a_client_takes_the_address_a_server_process_gives(serve: Serve) -> None:
    server = serve()
    with (
        Client(server.address, timeout=10) as joined,
        Client(server.host, server.port, timeout=10) as split,
    ):
        assert joined.address == split.address == server.address
        assert joined.hello.environment == split.hello.environment


@pytest.mark.parametrize(
    ("address", "message"),
    [
        ("127.0.0.1", "expected HOST:PORT, e.g. 127.0.0.1:5000, got '127.0.0.1'"),
        ("127.0.0.1:http", "expected HOST:PORT, e.g. 127.0.0.1:5000, got '127.0.0.1:http'"),
        (":5000", "expected HOST:PORT, e.g. 127.0.0.1:5000, got ':5000'"),
        ("127.0.0.1:70000", "'127.0.0.1:70000' has no port: ports run from 1 to 65535"),
        (
            "::1:5000",
            "expected HOST:PORT, got '::1:5000': an IPv6 host goes in brackets, as in [::1]:5000",
        ),
    ],
)
def test_a_malformed_address_is_refused_before_connecting(address: str, message: str) -> None:
    with pytest.raises(ValueError) as error:
        Client(address)
    assert str(error.value) == message


def _ipv6_loopback() -> bool:
    try:
        with socket.create_server(("::1", 0), family=socket.AF_INET6):
            return True
    except OSError:
        return False


@pytest.mark.skipif(not _ipv6_loopback(), reason="no IPv6 loopback here")
def test_an_ipv6_address_in_brackets_reaches_the_server() -> None:
    hello = Hello("Six", spaces.Discrete(2), spaces.Discrete(2))
    with socket.create_server(("::1", 0), family=socket.AF_INET6) as listener:
        address = f"[::1]:{listener.getsockname()[1]}"
        listener.settimeout(10)

        def say_hello() -> None:  # a server that greets once: any server of IPv6
            accepted, _ = listener.accept()
            with accepted:
                accepted.sendall(Connection(Role.SERVER).send(hello))
                accepted.recv(1)  # until the client closes

        greeter = threading.Thread(target=say_hello)
        greeter.start()
        try:
            with Client(address, timeout=10, shared_memory=False) as client:
                assert client.hello.environment == "Six" and client.address == address
        finally:
            greeter.join(10)


@pytest.mark.skipif(not _ipv6_loopback(), reason="no IPv6 loopback here")
def test_rlenv_serve_listens_on_an_ipv6_address(serve) -> None:
    server = serve("examples.cartpole:CartPoleEnvironment", host="::1")
    assert server.host == "::1" and server.address == f"[::1]:{server.port}"
    with Client(server.address, timeout=10) as client:
        observation, _ = client.reset(seed=1)
        assert client.step(np.zeros(1, np.float32))[0].shape == observation.shape


# --- a normal close is no failure -------------------------------------------------------------


def test_a_lane_closed_with_rings_unread_is_a_close_not_a_failure() -> None:
    hello = Hello(
        "Test", spaces.Box(-1.0, 1.0, (1,), np.float32), spaces.Box(-1.0, 1.0, (1,), np.float32)
    )
    layout = Layout.for_hello(hello)
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    tcp_ours, tcp_theirs = socket.socketpair()
    memory = mmap.mmap(-1, layout.size)
    lane = Lane(memory, ours, Slots(memory, layout, hello), tcp_ours)
    try:
        lane.ring()  # the other end never reads this ring: its close then resets the lane
        theirs.close()
        with pytest.raises(LaneClosed) as closed:
            lane.drain()
        assert str(closed.value) == "the other end closed the shared-memory lane"
    finally:
        lane.close()
        tcp_ours.close()
        tcp_theirs.close()


# --- a port in use, and Ctrl-C as soon as it listens -------------------------------------------


def _in_use_line(command: str, port: int) -> str:
    return (
        f"{command}: port {port} is in use on 127.0.0.1 (by another server?): choose "
        "another port, or 0 for a free one"
    )


@pytest.mark.parametrize("command", ["rlenv http", "rlenv.run"])
def test_a_port_in_use_is_one_line_everywhere(command: str) -> None:
    if command == "rlenv http":
        pytest.importorskip("uvicorn")
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        args = (
            ["-m", "rlenv", "http", TARGET, "--port", str(port)]
            if command == "rlenv http"
            else ["-m", "examples.pusher", str(port)]
        )
        result = subprocess.run(
            [sys.executable, *args], capture_output=True, text=True, timeout=120, cwd=ROOT
        )
    assert result.returncode == 2
    assert result.stderr.splitlines() == [_in_use_line(command, port)]


@pytest.mark.parametrize(
    "args",
    [["-m", "rlenv", "serve", TARGET], ["-m", "examples.pusher", "0"]],
    ids=["rlenv serve", "rlenv.run"],
)
def test_ctrl_c_as_soon_as_it_listens_exits_with_status_0(args: list[str]) -> None:
    process = subprocess.Popen(
        [sys.executable, *args],
        cwd=ROOT,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert process.stdout is not None
        seen = []
        for line in process.stdout:  # the first line that says where it listens
            seen.append(line)
            if line.startswith("listening on "):
                break
        process.send_signal(signal.SIGINT)
        rest = process.communicate(timeout=60)[0]
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 0, "".join(seen) + rest
    assert "Traceback" not in rest


# --- MODULE:CLASS: a file path, a near miss ---------------------------------------------------


@pytest.mark.parametrize(
    ("target", "line"),
    [
        (
            "examples/cartpole.py:CartPoleEnvironment",
            "rlenv serve: 'examples/cartpole.py:CartPoleEnvironment' names a file; MODULE:CLASS "
            "names a module as Python imports it: drop .py (examples.cartpole:CartPoleEnvironment)",
        ),
        (
            "examples.cartpole:CartpoleEnvironment",
            "rlenv serve: module 'examples.cartpole' has no attribute 'CartpoleEnvironment': did "
            "you mean CartPoleEnvironment?",
        ),
        (
            "examples.cartpole:Nope",
            "rlenv serve: module 'examples.cartpole' has no attribute 'Nope'",
        ),
    ],
    ids=["file path", "near miss", "nothing near"],
)
def test_a_target_that_does_not_load_gets_the_hint_that_helps(target: str, line: str) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "rlenv", "serve", target],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert result.returncode == 2
    assert result.stderr.splitlines() == [line]


@pytest.mark.parametrize(
    "target", ["examples/cartpole.py:CartPoleEnvironment", "examples.cartpole:CartpoleEnvironment"]
)
def test_the_python_api_gives_the_same_hint(target: str) -> None:
    import rlenv
    from rlenv_client import LocalClient

    hint = (
        "drop .py"
        if target.endswith(".py:CartPoleEnvironment")
        else "did you mean CartPoleEnvironment?"
    )
    for start in (rlenv.Server, LocalClient):
        with pytest.raises(ImportError, match=re.escape(hint)):
            start(target)


# --- what the HTTP gateway takes as an action ---------------------------------------------------


def test_the_gateway_takes_a_discrete_action_as_an_integer_as_docs_http_says() -> None:
    pytest.importorskip("uvicorn")
    from http_gateway import Gateway, assert_problem

    docs = (ROOT / "docs" / "http.md").read_text()
    assert "actions are always lists" not in docs
    assert "a Discrete action an integer (`1`, not `[1]`" in docs
    gateway = Gateway("examples.classic_cartpole:ClassicCartPoleEnvironment")
    try:
        session = gateway.session()
        gateway.post(f"/v1/envs/{session}/reset", {"seed": 0})
        assert gateway.post(f"/v1/envs/{session}/step", {"action": 1})["info"]["frames"] >= 1
        refused = gateway.request("POST", f"/v1/envs/{session}/step", {"action": [1]})
        problem = assert_problem(refused, 422, "invalid_action")
        assert "action must be an integer, got list" in problem["detail"]
    finally:
        gateway.close()
