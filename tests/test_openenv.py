"""OpenEnv's own client against ``rlenv http``'s ``/openenv`` routes (``make test-openenv``).

The gateway runs as users run it (``python -m rlenv http TARGET --port 0``); the agent's side is
``openenv-core`` 0.3's ``GenericEnvClient(base_url=...).sync()``, unchanged. Its episodes are
compared, bit for bit, with ``gymnasium.make`` of the same id and seed.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from http_gateway import Gateway, assert_same_observation

import rlenv_client  # noqa: F401  (registers the ids)

pytest.importorskip("openenv")

from openenv.core import GenericEnvClient  # noqa: E402

pytestmark = pytest.mark.openenv

CARTPOLE = "rlenv/CartPole-v1"
PAIR = "rlenv/Pair-v0"


@pytest.fixture(scope="module")
def cartpole() -> Iterator[Gateway]:
    """``rlenv http rlenv/CartPole-v1 --port 0``."""
    started = Gateway(CARTPOLE)
    yield started
    started.close()


def _play(env: Any, expected_env: gym.Env, seed: int | None, policy: Any) -> tuple[int, bool, bool]:
    """One episode through OpenEnv's client beside gymnasium's; its length and flags."""
    result = env.reset() if seed is None else env.reset(seed=seed)
    expected, _ = expected_env.reset(seed=seed)
    assert result.reward is None and result.done is False
    assert_same_observation(result.observation["observation"], expected)
    steps = 0
    while True:
        action = policy(expected)
        result = env.step({"action": action})
        expected, reward, terminated, truncated, info = expected_env.step(action)
        steps += 1
        assert_same_observation(result.observation["observation"], expected)
        metadata = result.observation["metadata"]
        assert result.reward == reward and result.done == (terminated or truncated)
        assert (metadata["terminated"], metadata["truncated"]) == (terminated, truncated)
        if "agents" in info:
            assert metadata["info"]["agents"] == info["agents"]
        if result.done:
            return steps, terminated, truncated


def test_generic_env_client_plays_cartpole_as_gym_make_does(cartpole: Gateway) -> None:
    expected_env = gym.make(CARTPOLE)
    random = np.random.default_rng(0)
    try:
        with GenericEnvClient(base_url=f"{cartpole.url}/openenv").sync() as env:
            # a balancing policy, to gymnasium's time limit: truncated, not terminated
            balanced = _play(env, expected_env, 0, lambda o: int(o[2] + 0.5 * o[3] > 0))
            assert balanced == (500, False, True)
            assert env.state()["step_count"] == 500
            # random actions, unseeded reset: the episodes go on from the first seed
            falls = _play(env, expected_env, None, lambda o: int(random.integers(2)))
            assert falls[1] and not falls[2] and falls[0] < 500
            state = env.state()
            assert state["step_count"] == falls[0] and state["episode"] == 2
            assert state["env_id"] == CARTPOLE and state["episode_id"]
    finally:
        expected_env.close()


def test_openenv_s_client_is_told_what_was_refused_and_goes_on(cartpole: Gateway) -> None:
    with GenericEnvClient(base_url=f"{cartpole.url}/openenv").sync() as env:
        with pytest.raises(RuntimeError, match=r"reset first.*EXECUTION_ERROR"):
            env.step({"action": 1})
        env.reset(seed=1)
        with pytest.raises(RuntimeError, match=r"outside.*VALIDATION_ERROR"):
            env.step({"action": 2})
        with pytest.raises(RuntimeError, match=r"'bogus'.*VALIDATION_ERROR"):
            env.step({"action": 1, "bogus": 0})
        assert env.step({"action": 1}).reward == 1.0


def test_each_client_is_a_session_of_its_own_until_it_closes(cartpole: Gateway) -> None:
    before = {session["id"] for session in cartpole.get("/v1/envs")["envs"]}
    first = GenericEnvClient(base_url=f"{cartpole.url}/openenv").sync()
    second = GenericEnvClient(base_url=f"{cartpole.url}/openenv").sync()
    with first, second:
        one, other = first.reset(seed=4), second.reset(seed=4)
        assert one.observation == other.observation
        moved = [first.step({"action": 1}) for _ in range(3)]
        assert second.step({"action": 1}).observation == moved[0].observation  # isolated
        opened = {session["id"] for session in cartpole.get("/v1/envs")["envs"]} - before
        assert len(opened) == 2
    after = {session["id"] for session in cartpole.get("/v1/envs")["envs"]}
    assert not opened & after  # each deleted when its client closed


def test_generic_env_client_plays_several_agents_keyed_by_agent() -> None:
    """rlenv/Pair-v0: actions and observations keyed by agent, each agent's outcome in info."""
    pair = Gateway(PAIR)
    expected_env = gym.make(PAIR)
    expected_env.action_space.seed(7)

    def sample(_: Any) -> dict[str, list[float]]:
        return {name: a.tolist() for name, a in expected_env.action_space.sample().items()}

    try:
        with GenericEnvClient(base_url=f"{pair.url}/openenv").sync() as env:
            steps, terminated, truncated = _play(env, expected_env, 7, sample)
            assert terminated or truncated
            assert env.state()["step_count"] == steps
    finally:
        expected_env.close()
        pair.close()
