"""The environments of one process share a server per target (``rlenv_client.sharing``)."""

from __future__ import annotations

import os
import signal
import threading
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conftest import wait_until

import rlenv_client  # noqa: F401  (registers the ids)
from rlenv_client.launcher import ServerProcess
from rlenv_client.sharing import SharedServers, shared_servers

ID = "rlenv/CartPole-v1"


def test_environments_of_one_target_share_a_server_and_it_stops_with_the_last() -> None:
    envs = [gym.make(ID) for _ in range(3)]
    other = gym.make(ID, server_args=["--idle-timeout", "100"])
    alone = gym.make(ID, share_server=False)
    try:
        servers = {env.unwrapped.server for env in envs}
        assert len(servers) == 1
        (server,) = servers
        assert other.unwrapped.server is not server and alone.unwrapped.server is not server
        assert server in shared_servers and alone.unwrapped.server not in shared_servers
        observations = [env.reset(seed=seed)[0] for seed, env in enumerate(envs)]
        assert len({observation.tobytes() for observation in observations}) == 3
        for env in envs[:-1]:
            env.close()
        assert server.is_alive()
        envs[-1].step(0)
    finally:
        for env in [*envs, other, alone]:
            env.close()
    wait_until(lambda: not server.is_alive(), "the shared server outlived its environments")
    assert server not in shared_servers


def test_a_lost_shared_server_is_replaced_once_for_all_its_environments() -> None:
    envs = [gym.make(ID) for _ in range(2)]
    try:
        for seed, env in enumerate(envs):
            env.reset(seed=seed)
        lost = envs[0].unwrapped.server
        os.killpg(lost.pid, signal.SIGKILL)
        lost.process.wait()
        for env in envs:
            observation, reward, terminated, truncated, info = env.step(1)
            assert truncated and not terminated and reward == 0.0
            assert "restarted (1 of 3)" in info["server_restarted"]
        replacement = envs[0].unwrapped.server
        assert replacement is envs[1].unwrapped.server and replacement.is_alive()
        assert lost not in shared_servers
        for env in envs:
            env.reset(seed=0)
        assert np.array_equal(envs[0].step(1)[0], envs[1].step(1)[0])
    finally:
        for env in envs:
            env.close()


def test_a_forked_child_starts_servers_of_its_own() -> None:
    env = gym.make(ID)
    try:
        read, write = os.pipe()
        child = os.fork()
        if child == 0:  # pragma: no cover (the child reports through the pipe)
            os.write(write, bytes([len(shared_servers.servers())]))
            os._exit(0)
        os.close(write)
        assert os.read(read, 1) == b"\x00"
        os.close(read)
        os.waitpid(child, 0)
        assert env.unwrapped.server in shared_servers
    finally:
        env.close()


def test_a_server_that_starts_holds_up_only_those_that_wait_for_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A target whose import waits for a gate file: its server takes as long as the test says.
    started, gate = tmp_path / "started", tmp_path / "gate"
    (tmp_path / "gated_cartpole.py").write_text(
        "import pathlib, time\n"
        f"pathlib.Path({str(started)!r}).touch()\n"
        "deadline = time.monotonic() + 120\n"
        f"while not pathlib.Path({str(gate)!r}).exists() and time.monotonic() < deadline:\n"
        "    time.sleep(0.01)\n"
        "from examples.cartpole import CartPoleEnvironment\n"
    )
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])
    )
    shared = SharedServers()
    leased: dict[str, ServerProcess] = {}

    def lease(name: str, target: str) -> None:
        leased[name] = shared.lease(target)

    gated = "gated_cartpole:CartPoleEnvironment"
    first = threading.Thread(target=lease, args=("first", gated))
    first.start()
    try:
        wait_until(started.exists, "the gated server did not start")
        other = threading.Thread(
            target=lease, args=("other", "examples.cartpole:CartPoleEnvironment")
        )
        other.start()
        other.join(timeout=60)
        assert not other.is_alive() and first.is_alive()  # served while the first still starts
        assert shared.servers() == [leased["other"]]
        second = threading.Thread(target=lease, args=("second", gated))
        second.start()
        gate.touch()
        first.join(timeout=120)
        second.join(timeout=120)
        assert leased["second"] is leased["first"]  # waited for it, then shared it
        assert set(shared.servers()) == {leased["first"], leased["other"]}
    finally:
        gate.touch()
        first.join(timeout=120)
        for server in leased.values():
            shared.release(server)
    for server in leased.values():
        wait_until(lambda server=server: not server.is_alive(), "a server outlived its lease")
