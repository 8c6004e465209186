"""The Godot seed's contract: an environment that hosts itself, its hooks, constants, layout.

Self-hosting scripts run as real subprocesses (``python script.py PORT``), as a Godot project
runs; the same classes are then served by ``rlenv serve``, whose address wins.
"""

from __future__ import annotations

import importlib
import os
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from conftest import Serve, wait_until

import rlenv
from rlenv.protocol.errors import ErrorCode
from rlenv_client import Client, RemoteError

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
HOOKED = "seed_hooks:HookedEnvironment"
ACTION = np.array([0.5], np.float32)


class SelfHosted:
    """A script hosting its environment, started as ``python ARGS...``; where it listens."""

    def __init__(self, *args: str) -> None:
        self.process = subprocess.Popen(
            [sys.executable, *args],
            cwd=ROOT,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONPATH": str(TESTS)},
        )
        self.lines: list[str] = []
        while True:
            line = self.process.stderr.readline()
            assert line, f"it exited before listening: {''.join(self.lines)}"
            self.lines.append(line)
            if line.startswith("listening on "):
                host, port = line.split()[-1].rsplit(":", 1)
                self.host, self.port = host, int(port)
                return

    def stop(self, signum: int) -> str:
        """Send ``signum``; what it wrote until it exited (it must exit with status 0)."""
        self.process.send_signal(signum)
        rest = self.process.communicate(timeout=20)[1]
        assert self.process.returncode == 0, rest
        return "".join(self.lines) + rest


@contextmanager
def self_hosted(*args: str) -> Iterator[SelfHosted]:
    hosted = SelfHosted(*args)
    try:
        yield hosted
    finally:
        if hosted.process.poll() is None:
            hosted.process.kill()
            hosted.process.communicate()


def _episode(client: Client) -> list[str]:
    """Configure the agent, reset with a seed, three steps of 4 ticks, observe; every call."""
    client.configure(agent={"gain": 2.0})
    observation, info = client.reset(seed=7)
    assert info["frames"] == 0
    for step in range(1, 4):
        observation, reward, _, _, info = client.step(ACTION, repeat_action=4)
        assert info["frames"] == 4 and reward == 4.0
        assert observation[0] == pytest.approx(observation[1] + step * 4 / 60, abs=1e-5)
    observed = client.observe()
    assert observed["world"]["x"] == pytest.approx(float(observed["agent"][0]), abs=1e-5)
    return client.poll()[4]["calls"]


EXPECTED = [
    "_on_got_connection:config",
    "_configure:agent",
    "_send_response:-",
    "_after_send_response",
    "_on_got_connection:reset,observation",
    "_reset",
    "_send_response:agent",
    "_after_send_response",
    *[
        "_on_got_connection:repeat_action,action,observation",
        "_step:4",
        "_send_response:agent",
        "_after_send_response",
    ]
    * 3,
    "_on_got_connection:observation",
    "_send_response:agent,world",
    "_after_send_response",
    "_on_got_connection:action,observation",
    "_send_response:agent",
]


def test_a_script_hosts_itself_and_every_hook_runs() -> None:
    with self_hosted(str(TESTS / "seed_hooks.py"), "0") as hosted:
        with Client(hosted.host, hosted.port, timeout=10) as client:
            assert client.hello.environment == "Hooked"
            assert _episode(client) == EXPECTED
        output = hosted.stop(signal.SIGTERM)
    assert "stopped" in output
    with pytest.raises(ConnectionRefusedError):  # the socket is closed
        socket.create_connection((hosted.host, hosted.port), timeout=5).close()


def test_the_same_class_under_rlenv_serve_runs_the_same_hooks(serve: Serve) -> None:
    with socket.create_server(("127.0.0.1", 0)) as probe:
        asked = probe.getsockname()[1]  # the port _ready asks for: rlenv serve's address wins
    server = serve(HOOKED, env={"PYTHONPATH": str(TESTS), "SEED_HOOKS_PORT": str(asked)})
    assert server.port != asked
    with Client(server.host, server.port, timeout=10) as client:
        assert _episode(client) == EXPECTED
    with socket.create_server(("127.0.0.1", asked)):  # nothing was bound there
        pass


def test_sigint_ends_a_self_hosted_environment_cleanly() -> None:
    with self_hosted("-m", "examples.pusher", "0") as hosted:
        with Client(hosted.host, hosted.port, timeout=10) as client:
            client.reset(seed=0)
            client.step(np.zeros(2, np.float32))
        assert "stopped" in hosted.stop(signal.SIGINT)


def test_the_pusher_hosts_itself_and_serves_under_rlenv_serve_alike(serve: Serve) -> None:
    from examples.pusher import TARGET, towards_goal

    def play(client: Client) -> list[float]:
        observation, _ = client.reset(seed=3)
        trajectory = []
        for _ in range(5):
            observation, _, _, _, info = client.step(towards_goal(observation))
            trajectory.extend(observation.tolist())
            assert len(client.observe()["world"]["trail"]) == 0  # sent, then cleared
        assert info["actions"] == 5
        return trajectory

    with self_hosted("-m", "examples.pusher", "0") as hosted:
        with Client(hosted.host, hosted.port, timeout=10) as client:
            hosted_run = play(client)
        hosted.stop(signal.SIGTERM)
    server = serve(TARGET)
    with Client(server.host, server.port, timeout=10) as client:
        assert play(client) == hosted_run


def test_a_self_hosted_environment_in_real_time_ticks_by_the_clock() -> None:
    with self_hosted(str(TESTS / "seed_hooks.py"), "0") as hosted:
        with Client(hosted.host, hosted.port, timeout=10) as client:
            client.reset(seed=0)
            client.configure(real_time=True)
            ticks = 0

            def ticked() -> bool:
                nonlocal ticks
                ticks += client.poll()[4]["frames"]
                return ticks >= 6

            wait_until(ticked, "ticks to follow the clock", seconds=10)
        hosted.stop(signal.SIGTERM)


def test_rlenv_run_needs_start_server_in_ready(tmp_path: Path) -> None:
    script = tmp_path / "forgot.py"
    script.write_text(
        "import rlenv\nfrom rlenv.examples.cartpole import CartPoleEnvironment\n"
        "rlenv.run(CartPoleEnvironment())\n"
    )
    result = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    assert result.returncode != 0
    assert (
        "CartPoleEnvironment._ready did not call self.communication.start_server(port, "
        "host)" in result.stderr
    )


def test_a_hook_that_forgets_super_gets_a_clear_error(serve: Serve) -> None:
    server = serve("seed_hooks:SilentEnvironment", env={"PYTHONPATH": str(TESTS)})
    with Client(server.host, server.port, timeout=10) as client:
        with pytest.raises(RemoteError) as error:
            client.reset(seed=0)
        assert error.value.code == ErrorCode.ENVIRONMENT_ERROR
        assert (
            "SilentEnvironment._on_got_connection sent no answer: call "
            "super()._on_got_connection(request)" in error.value.message
        )


def test_an_after_send_response_that_raises_ends_the_episode(serve: Serve) -> None:
    server = serve("seed_hooks:StubbornEnvironment", env={"PYTHONPATH": str(TESTS)})
    with Client(server.host, server.port, timeout=10) as client:
        client.reset(seed=0)
        client.step(ACTION)  # its answer goes out, then _after_send_response raises
        with pytest.raises(RemoteError) as error:
            client.step(ACTION)
        assert error.value.code == ErrorCode.RESET_REQUIRED
        assert (
            "_after_send_response raised RuntimeError: the trail would not clear"
            in error.value.message
        )
        client.reset(seed=0)
        client.step(ACTION)


def test_the_seeds_constants_and_the_design_cards_layout() -> None:
    keys = {
        "CONFIG_KEY": "config",
        "RESET_KEY": "reset",
        "ACTION_KEY": "action",
        "OBSERVATION_KEY": "observation",
        "WORLD_KEY": "world",
        "AGENT_KEY": "agent",
        "ENVIRONMENT_KEY": "environment",
    }
    for name, value in keys.items():
        assert getattr(rlenv.RLEnvironment, name) == value
    for module, name in [
        ("rlenv.node", "Node"),
        ("rlenv.environment", "RLEnvironment"),
        ("rlenv.agent", "RLAgent"),
        ("rlenv.world", "RLEnvWorld"),
        ("rlenv.communication", "Communication"),
    ]:
        cls = getattr(importlib.import_module(module), name)
        assert cls.__module__ == module and getattr(rlenv, name) is cls
    assert isinstance(rlenv.RLEnvironment().communication, rlenv.Communication)
    assert callable(rlenv.run)
