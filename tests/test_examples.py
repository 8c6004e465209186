"""The shipped examples, end to end over a socket."""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import Serve

from examples.reacher import reach
from examples.seeker import greedy
from rlenv_client import Client


def test_the_seeker_catches_the_apple_through_a_signal(serve: Serve) -> None:
    server = serve("examples.seeker:SeekerEnvironment")
    with Client(server.host, server.port, timeout=10, world_data=True) as client:
        for seed in range(3):
            observation, info = client.reset(seed=seed)
            apple = np.array(info["world"]["apple"])
            assert np.allclose(observation[:2] + observation[4:6], apple, atol=1e-5)
            assert np.hypot(*observation[4:6]) >= 2.0  # placed apart
            total, terminated, steps = 0.0, False, 0
            while not terminated and steps < 250:
                observation, reward, terminated, truncated, info = client.step(greedy(observation))
                total += reward
                steps += 1
            assert terminated and not truncated
            assert reward > 9.0  # the catch: +10, less the tick penalties
            assert info["frames"] <= 4


def test_the_seeker_stands_still_without_a_push(serve: Serve) -> None:
    server = serve("examples.seeker:SeekerEnvironment")
    with Client(server.host, server.port, timeout=10) as client:
        observation, _ = client.reset(seed=5)
        for _ in range(20):
            after, reward, terminated, _, _ = client.step(np.zeros(2, np.float32))
            assert not terminated and reward == pytest.approx(-0.04)
        assert np.allclose(after[:2], observation[:2])


def test_the_reacher_reaches_and_pays_for_effort(serve: Serve) -> None:
    server = serve("examples.reacher:ReacherEnvironment")
    with Client(server.host, server.port, timeout=10, world_data=True) as client:
        for seed in range(2):
            observation, info = client.reset(seed=seed)
            assert np.allclose(observation[4:6], info["world"]["target"], atol=1e-6)
            assert 0.2 <= np.hypot(*observation[4:6]) <= 0.9
            reached = 0.0
            for _ in range(100):
                observation, reward, terminated, truncated, _ = client.step(reach(observation))
                reached += reward
                assert not (terminated or truncated)
            assert np.hypot(*observation[8:10]) < 0.05  # the fingertip is on the target
            client.reset(seed=seed)
            idle = sum(client.step(np.zeros(2, np.float32))[1] for _ in range(100))
            assert reached > idle  # reaching pays, even with its control cost
        client.configure(agent={"control_cost": 0.0})
        client.reset(seed=0)
        _, reward, *_ = client.step(np.ones(2, np.float32))
        client.configure(agent={"control_cost": 10.0})
        client.reset(seed=0)
        _, costly, *_ = client.step(np.ones(2, np.float32))
        assert costly < reward  # effort is charged


@pytest.mark.parametrize(
    "name",
    [
        "cartpole",
        "classic_cartpole",
        "seeker",
        "pixels",
        "reacher",
        "pair",
        "tag",
        "hunt",
        "plinko",
        "maze",
    ],
)
def test_every_example_serves_as_a_module(name: str) -> None:
    process = subprocess.Popen(
        [sys.executable, "-m", f"examples.{name}", "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        found = re.fullmatch(r"listening on (.+):(\d+)\n", line)
        assert found, line
        with Client(found.group(1), int(found.group(2)), timeout=10) as client:
            client.reset(seed=0)
            client.step(client.action_space.sample())
    finally:
        process.terminate()
        process.wait(10)
