"""examples.tag: two roles whose spaces, settings and rewards differ, played over a real server."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from conftest import Serve

from examples.tag import CHASER, RUNNERS, TARGET, Chaser, Runner
from rlenv_client import Client

Policy = Callable[[str, np.ndarray], np.ndarray]


def _connect(serve: Serve) -> Client:
    server = serve(TARGET)
    return Client(server.host, server.port, timeout=10)


def _play(client: Client, seed: int, policy: Policy, steps: int = 300) -> dict[str, Any]:
    """One episode; each agent's return and how it ended."""
    observation, _ = client.reset(seed=seed)
    returns = dict.fromkeys((CHASER, *RUNNERS), 0.0)
    ended: dict[str, str] = {}
    for _ in range(steps):
        action = {
            name: policy(name, value) for name, value in observation.items() if name not in ended
        }
        observation, _, terminated, truncated, info = client.step(action)
        for name, outcome in info["agents"].items():
            returns[name] += outcome["reward"]
            if outcome["terminated"]:
                ended.setdefault(name, "terminated")
        if terminated or truncated:
            break
    return {"returns": returns, "ended": ended}


def test_the_roles_differ_in_spaces_and_settings(serve: Serve) -> None:
    with _connect(serve) as client:
        assert tuple(client.hello.agents) == (CHASER, *RUNNERS)
        assert client.observation_space[CHASER].shape == (10,)
        assert client.observation_space["Runner1"].shape == (8,)
    assert Chaser.max_force == 10.0 and Runner.max_force == 8.0


def test_the_chasers_heuristic_tags_runners_that_a_random_chaser_never_does(serve: Serve) -> None:
    chaser, runner = Chaser(), Runner("Runner")
    rng = np.random.default_rng(0)

    def heuristics(name: str, observation: np.ndarray) -> np.ndarray:
        return (chaser if name == CHASER else runner).heuristic(observation)

    def random_chaser(name: str, observation: np.ndarray) -> np.ndarray:
        if name == CHASER:
            return rng.uniform(-1.0, 1.0, 2).astype(np.float32)
        return runner.heuristic(observation)

    with _connect(serve) as client:
        tagged = [len(_play(client, seed, heuristics)["ended"]) for seed in range(4)]
        missed = [len(_play(client, seed, random_chaser)["ended"]) for seed in range(4)]
    assert sum(tagged) >= 4  # the heuristic tags: a runner, or both and then the chaser is done
    assert sum(missed) < sum(tagged)


def test_a_tag_ends_the_runner_and_both_end_the_chaser(serve: Serve) -> None:
    chaser, runner = Chaser(), Runner("Runner")

    def heuristics(name: str, observation: np.ndarray) -> np.ndarray:
        return (chaser if name == CHASER else runner).heuristic(observation)

    with _connect(serve) as client:
        for seed in range(8):
            episode = _play(client, seed, heuristics)
            if len(episode["ended"]) == 3:
                break
        else:
            raise AssertionError("the heuristic chaser never tagged both runners in 8 seeds")
    returns = episode["returns"]
    assert returns[CHASER] > 10.0  # two tags, minus the time it took
    assert all(returns[name] < 0.0 for name in RUNNERS)
