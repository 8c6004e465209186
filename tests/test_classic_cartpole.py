"""rlenv/CartPole-v1: gymnasium's CartPole-v1 interface on rlenv's physics, through gymnasium."""

from __future__ import annotations

import math
import subprocess
import sys
from collections.abc import Callable, Iterator

import gymnasium as gym
import numpy as np
import pytest

import rlenv_client  # noqa: F401  (registers the ids)
from examples.classic_cartpole import heuristic
from rlenv_client import RemoteError

ENV_ID = "rlenv/CartPole-v1"
ANGLE_LIMIT = 12 * 2 * math.pi / 360  # gymnasium's theta_threshold_radians
Policy = Callable[[np.ndarray, np.random.Generator], int]


@pytest.fixture
def env() -> Iterator[gym.Env]:
    made = gym.make(ENV_ID)
    yield made
    made.close()


def _random(observation: np.ndarray, rng: np.random.Generator) -> int:
    return int(rng.integers(2))


def _episode(
    env: gym.Env, policy: Policy, seed: int, rng: np.random.Generator
) -> tuple[list[float], bool, bool, list[np.ndarray]]:
    observation, _ = env.reset(seed=seed)
    observations, rewards = [observation], []
    while True:
        observation, reward, terminated, truncated, _ = env.step(policy(observation, rng))
        observations.append(observation)
        rewards.append(reward)
        if terminated or truncated:
            return rewards, terminated, truncated, observations


def test_the_spaces_and_limit_are_gymnasium_cartpole_v1s(env: gym.Env) -> None:
    native = gym.make("CartPole-v1")
    try:
        assert env.action_space == native.action_space == gym.spaces.Discrete(2)
        assert env.observation_space == native.observation_space
        assert env.observation_space.dtype == np.float32
        assert env.spec is not None and env.spec.max_episode_steps == 500
        observation, _ = env.reset(seed=0)
        assert observation.dtype == np.float32 and observation.shape == (4,)
        assert np.all(np.abs(observation) <= 0.05)  # gymnasium's starting state
    finally:
        native.close()


def test_every_step_pays_one_and_the_pole_falls_past_twelve_degrees(env: gym.Env) -> None:
    rewards, terminated, truncated, observations = _episode(
        env, lambda *_: 1, 3, np.random.default_rng(0)
    )
    assert terminated and not truncated
    assert rewards == [1.0] * len(rewards)  # the step on which the pole falls pays too
    assert 5 < len(rewards) < 60  # always pushing right drops the pole quickly
    *before, last = observations
    for x, _, angle, _ in before:
        assert abs(x) <= 2.4 and abs(angle) <= ANGLE_LIMIT
    assert last[2] < -ANGLE_LIMIT  # pushed right, the pole falls to the left
    assert abs(last[0]) <= 2.4


def test_the_cart_leaving_the_track_ends_the_episode(env: gym.Env) -> None:
    def drift(observation: np.ndarray, rng: np.random.Generator) -> int:
        """Keep the pole up, leaning it a little: the cart runs off the track's end."""
        return int(observation[2] + 0.5 * observation[3] + 0.05 > 0)

    rewards, terminated, truncated, observations = _episode(env, drift, 0, np.random.default_rng(0))
    assert terminated and not truncated and len(rewards) < 500
    *before, last = observations
    assert last[0] < -2.4 and abs(last[2]) <= ANGLE_LIMIT, last
    assert all(abs(x) <= 2.4 for x, *_ in before)


def test_a_balanced_pole_is_truncated_at_500_steps(env: gym.Env) -> None:
    rewards, terminated, truncated, _ = _episode(
        env, lambda o, _: heuristic(o), 0, np.random.default_rng(0)
    )
    assert truncated and not terminated
    assert len(rewards) == 500 and sum(rewards) == 500.0


def test_episodes_are_reproducible_per_seed() -> None:
    runs = []
    for _ in range(2):
        env = gym.make(ENV_ID)
        try:
            rng = np.random.default_rng(7)
            runs.append([_episode(env, _random, seed, rng)[3] for seed in (11, 12)])
        finally:
            env.close()
    for first, second in zip(runs[0], runs[1], strict=True):
        assert len(first) == len(second)
        assert all(a.tobytes() == b.tobytes() for a, b in zip(first, second, strict=True))
    assert runs[0][0][0].tobytes() != runs[0][1][0].tobytes()  # another seed, another start


def test_a_heuristic_survives_far_longer_than_random_as_on_gymnasium(env: gym.Env) -> None:
    native = gym.make("CartPole-v1")
    try:
        lengths = {}
        for name, made in (("rlenv", env), ("native", native)):
            for policy_name, policy in (
                ("heuristic", lambda o, _: heuristic(o)),
                ("random", _random),
            ):
                rng = np.random.default_rng(1)
                episodes = 5 if policy_name == "heuristic" else 30
                lengths[name, policy_name] = np.mean(
                    [len(_episode(made, policy, seed, rng)[0]) for seed in range(episodes)]
                )
    finally:
        native.close()
    for name in ("rlenv", "native"):
        assert lengths[name, "heuristic"] >= 400, lengths
        assert lengths[name, "random"] < 50, lengths
        assert lengths[name, "heuristic"] > 8 * lengths[name, "random"], lengths
    # the same random actions last about as long on both physics
    assert 0.7 < lengths["rlenv", "random"] / lengths["native", "random"] < 1.4, lengths


def test_reset_options_set_the_bounds_as_gymnasiums_do(env: gym.Env) -> None:
    observation, _ = env.reset(seed=0, options={"low": -0.001, "high": 0.001})
    assert np.all(np.abs(observation) <= 0.001 + 1e-6), observation
    with pytest.raises(RemoteError, match="low and high"):
        env.reset(seed=0, options={"low": 0.1, "high": -0.1})
    observation, _ = env.reset(seed=0)  # the server goes on serving
    assert np.all(np.abs(observation) <= 0.05)


def test_a_script_that_cannot_import_rlenv_client_names_the_module() -> None:
    script = (
        "import sys, gymnasium as gym\n"
        "assert 'rlenv_client' not in sys.modules\n"
        "env = gym.make('rlenv_client:rlenv/CartPole-v1')\n"
        "observation, _ = env.reset(seed=0)\n"
        "print(env.spec.id, env.action_space, observation.shape, env.step(1)[1])\n"
        "env.close()\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["rlenv/CartPole-v1", "Discrete(2)", "(4,)", "1.0"]
