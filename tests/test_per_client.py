"""``rlenv serve --per-client``: every client an environment of its own, in one process."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import Serve

from examples.cartpole import TARGET
from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv_client import Client
from rlenv_tools._bench import ENDLESS

PER_CLIENT = ["--per-client"]


def trajectory(client: Client, seed: int, actions: np.ndarray) -> list[bytes]:
    client.configure(**ENDLESS)
    observation, _ = client.reset(seed=seed)
    seen = [observation.tobytes()]
    for action in actions:
        observation, reward, terminated, truncated, info = client.step(action)
        seen.append(
            observation.tobytes()
            + np.float64(reward).tobytes()
            + bytes([terminated, truncated, info["frames"]])
        )
    return seen


@pytest.mark.parametrize("shared_memory", [True, False])
def test_interleaved_clients_step_exactly_as_alone(serve: Serve, shared_memory: bool) -> None:
    actions = np.random.default_rng(5).uniform(-1, 1, (40, 1)).astype(np.float32)
    alone = serve()
    with Client(alone.host, alone.port, shared_memory=shared_memory) as client:
        expected = {seed: trajectory(client, seed, actions) for seed in (1, 2, 3)}
    server = serve(args=PER_CLIENT)
    clients = {
        seed: Client(server.host, server.port, shared_memory=shared_memory) for seed in (1, 2, 3)
    }
    try:
        for client in clients.values():
            client.configure(**ENDLESS)
        seen = {seed: [client.reset(seed=seed)[0].tobytes()] for seed, client in clients.items()}
        for action in actions:  # one step each, in turn: none sees another's
            for seed, client in clients.items():
                observation, reward, terminated, truncated, info = client.step(action)
                seen[seed].append(
                    observation.tobytes()
                    + np.float64(reward).tobytes()
                    + bytes([terminated, truncated, info["frames"]])
                )
    finally:
        for client in clients.values():
            client.close()
    assert seen == expected


def test_no_client_is_busy_and_each_environment_is_its_own(serve: Serve) -> None:
    server = serve(args=PER_CLIENT)
    with Client(server.host, server.port) as first, Client(server.host, server.port) as second:
        assert first.hello == second.hello
        first.configure(**ENDLESS)
        first.reset(seed=0)
        with pytest.raises(RemoteError) as error:  # the second's has not started an episode
            second.step(np.zeros(1, np.float32))
        assert error.value.code == ErrorCode.RESET_REQUIRED
        second.reset(seed=1)
        before = second.observe()["agent"]
        for _ in range(5):
            first.step(np.ones(1, np.float32))
        assert second.observe()["agent"].tobytes() == before.tobytes()


def test_a_client_that_leaves_frees_its_place_and_the_next_starts_afresh(serve: Serve) -> None:
    server = serve(args=[*PER_CLIENT, "--max-connections", "2"])
    with Client(server.host, server.port) as staying:
        staying.reset(seed=0)
        with Client(server.host, server.port) as leaving:
            leaving.reset(seed=1)
            with pytest.raises(RemoteError) as error:
                Client(server.host, server.port, timeout=5)
            assert error.value.code == ErrorCode.BUSY
        with Client(server.host, server.port) as next_one:
            with pytest.raises(RemoteError) as error:
                next_one.observe()
            assert error.value.code == ErrorCode.RESET_REQUIRED  # a new environment
            next_one.reset(seed=1)
        staying.step(np.zeros(1, np.float32))


def test_a_client_whose_environment_cannot_be_built_is_told_and_the_others_go_on(
    serve: Serve,
) -> None:
    server = serve(
        "per_client_envs:OnlyOneEnvironment",
        args=PER_CLIENT,
        env={"PYTHONPATH": os.path.dirname(__file__)},
    )
    with Client(server.host, server.port) as first:
        first.reset(seed=0)
        second = Client(server.host, server.port)
        with pytest.raises(RemoteError) as error:
            second.reset(seed=0)
        assert error.value.code == ErrorCode.ENVIRONMENT_ERROR and error.value.fatal
        assert (
            "could not build an environment for this client: only one of these fits"
            in error.value.message
        )
        first.step(np.zeros(1, np.float32))


def test_per_client_and_inspect_are_refused_together() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "rlenv", "serve", TARGET, "--per-client", "--inspect"],
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )
    assert result.returncode == 2
    assert "rlenv serve: --inspect watches the environment of a controller" in result.stderr
