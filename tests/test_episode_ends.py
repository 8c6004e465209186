"""When the joint episode of several agents ends, at every layer a trainer reads it from.

The joint episode is terminated when every agent terminated, and truncated when every agent is
done and at least one was truncated: a runner caught, then the others timed out, is a time-out
(a trainer bootstraps from it), not a terminal state. Each layer is checked on the same
episodes of ``tests/episode_end_envs.py``: the protocol's answer, ``RemoteEnv``, the vector's
``steps`` columns, SB3's ``VecEnv``, PettingZoo; one agent's flags are passed on unchanged.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import pytest
from conftest import Serve
from episode_end_envs import TimedAgent

from examples.pair import chase
from rlenv_client import Client, RemoteEnv, RemoteVectorEnv
from rlenv_client.registration import ENVIRONMENTS

TESTS = Path(__file__).parent
TIMED_PAIR = "episode_end_envs:TimedPair"
TIMED_SOLO = "episode_end_envs:TimedSolo"
STILL = np.zeros(2, np.float32)
STEPS = TimedAgent.limit // 4  # the step at which an agent still playing times out
SEED = 3  # Red catches its apple at step 15, Blue (chasing too) at step 17


def _serve_timed(serve: Serve, target: str, instances: int = 1) -> str:
    """A server of ``target`` (from ``tests/``) with ``instances`` instances: its address."""
    path = os.pathsep.join(filter(None, [str(TESTS), os.environ.get("PYTHONPATH")]))
    return serve(target, env={"PYTHONPATH": path}, args=["--instances", str(instances)]).address


def _actions(observation: dict[str, np.ndarray], blue_chases: bool) -> dict[str, np.ndarray]:
    """Red chases its apple; Blue chases too, or stands still (then it times out)."""
    return {
        "Red": chase(observation["Red"]),
        "Blue": chase(observation["Blue"]) if blue_chases else STILL,
    }


def _play(
    reset: Callable[[], Any], step: Callable[[Any], tuple[Any, ...]], blue_chases: bool
) -> Iterator[tuple[bool, bool, dict[str, dict[str, Any]]]]:
    """Each step's joint flags and agents' outcomes, until the joint episode ends."""
    observation = reset()
    for _ in range(STEPS):
        observation, _, terminated, truncated, info = step(_actions(observation, blue_chases))
        yield terminated, truncated, info["agents"]
        if terminated or truncated:
            return
    raise AssertionError(f"the episode did not end in {STEPS} steps")


def _assert_ends(
    flags: list[tuple[bool, bool, dict[str, dict[str, Any]]]], blue_chases: bool
) -> None:
    """Before the last step nothing ended jointly; the last is terminated or truncated."""
    *before, (terminated, truncated, agents) = flags
    assert all(not ended and not cut for ended, cut, _ in before)
    assert agents["Red"]["terminated"] and not agents["Red"]["truncated"]
    if blue_chases:  # every agent terminated
        assert (terminated, truncated) == (True, False)
        assert agents["Blue"]["terminated"] and not agents["Blue"]["truncated"]
    else:  # Red was caught first, then Blue timed out
        assert (terminated, truncated) == (False, True)
        assert agents["Blue"] == {
            "reward": pytest.approx(-0.04),
            "terminated": False,
            "truncated": True,
        }
        assert len(flags) == STEPS
        assert any(outcome["Red"]["terminated"] for *_, outcome in before)  # caught earlier


@pytest.mark.parametrize("blue_chases", [False, True], ids=["caught-then-time-out", "all-caught"])
def test_the_protocols_answer_and_remote_env(serve: Serve, blue_chases: bool) -> None:
    address = _serve_timed(serve, TIMED_PAIR)
    host, port = address.rsplit(":", 1)
    with Client(host, int(port), timeout=10) as client:
        _assert_ends(
            list(_play(lambda: client.reset(seed=SEED)[0], client.step, blue_chases)), blue_chases
        )
    env = RemoteEnv(address=address, timeout=10)
    try:
        _assert_ends(
            list(_play(lambda: env.reset(seed=SEED)[0], env.step, blue_chases)), blue_chases
        )
    finally:
        env.close()


def test_one_agent_s_flags_are_passed_on_unchanged(serve: Serve) -> None:
    address = _serve_timed(serve, TIMED_SOLO)
    env = RemoteEnv(address=address, timeout=10)
    try:
        for chases, expected in ((True, (True, False)), (False, (False, True))):
            observation, _ = env.reset(seed=SEED)
            for _ in range(STEPS):
                observation, _, terminated, truncated, info = env.step(
                    chase(observation) if chases else STILL
                )
                if terminated or truncated:
                    break
            assert (terminated, truncated) == expected and "agents" not in info
    finally:
        env.close()


def test_the_vector_s_steps_columns(serve: Serve) -> None:
    """Sub-env 0: Red caught, then Blue timed out; sub-env 1: both caught."""
    address = _serve_timed(serve, TIMED_PAIR, instances=2)
    with RemoteVectorEnv(addresses=[address], timeout=10) as envs:
        observations, _ = envs.reset(seed=SEED)
        ended: dict[int, tuple[bool, bool, dict[str, Any]]] = {}
        for _ in range(STEPS):
            actions = {
                "Red": np.stack([chase(observations["Red"][i]) for i in range(2)]),
                "Blue": np.stack([STILL, chase(observations["Blue"][1])]),
            }
            observations, _, terminations, truncations, infos = envs.step(actions)
            for index in np.flatnonzero(terminations | truncations):
                ended.setdefault(
                    int(index),
                    (bool(terminations[index]), bool(truncations[index]), _agents_of(infos, index)),
                )
            if len(ended) == 2:
                break
        assert ended[0][:2] == (False, True) and ended[1][:2] == (True, False)
        assert ended[0][2]["Blue"]["truncated"] and ended[0][2]["Red"]["terminated"]


def _agents_of(infos: dict[str, Any], index: int) -> dict[str, dict[str, bool]]:
    """Sub-env ``index``'s agents' flags, from a vector's info of arrays."""
    agents = infos["agents"]
    return {
        name: {flag: bool(agents[name][flag][index]) for flag in ("terminated", "truncated")}
        for name in ("Red", "Blue")
    }


def test_sb3_s_vec_env(serve: Serve) -> None:
    pytest.importorskip("stable_baselines3")
    from rlenv_client.sb3 import SB3VecEnv

    address = _serve_timed(serve, TIMED_PAIR, instances=2)
    envs = SB3VecEnv(addresses=[address])
    try:
        envs.seed(SEED)
        observations = envs.reset()
        ended: dict[int, dict[str, Any]] = {}
        for _ in range(STEPS):
            actions = {
                "Red": np.stack([chase(observations["Red"][i]) for i in range(2)]),
                "Blue": np.stack([STILL, chase(observations["Blue"][1])]),
            }
            observations, _, dones, infos = envs.step(actions)
            for index in np.flatnonzero(dones):
                ended.setdefault(int(index), infos[index])
            if len(ended) == 2:
                break
        assert ended[0]["TimeLimit.truncated"] is True  # SB3 bootstraps from the time-out
        assert ended[1]["TimeLimit.truncated"] is False
    finally:
        envs.close()


def test_pettingzoo_s_agents(serve: Serve) -> None:
    pytest.importorskip("pettingzoo")
    from rlenv_client.pettingzoo import RemoteParallelEnv

    env = RemoteParallelEnv(address=_serve_timed(serve, TIMED_PAIR), timeout=10)
    try:
        observations, _ = env.reset(seed=SEED)
        ends: dict[str, tuple[bool, bool]] = {}
        while env.agents:
            actions = {
                agent: chase(observations[agent]) if agent == "Red" else STILL
                for agent in env.agents
            }
            observations, _, terminations, truncations, _ = env.step(actions)
            for agent in actions:
                if terminations[agent] or truncations[agent]:
                    ends[agent] = (terminations[agent], truncations[agent])
        assert ends == {"Red": (True, False), "Blue": (False, True)}
    finally:
        env.close()


def test_a_client_side_time_limit_truncates_every_agent_still_playing() -> None:
    """RemoteEnv's and the vector's max_episode_steps: the agents' flags agree with the joint."""
    limit = 20  # after Red's catch (step 15), before Blue's time-out
    env = RemoteEnv(TIMED_PAIR, in_process=True, max_episode_steps=limit)
    try:
        flags = list(_play(lambda: env.reset(seed=SEED)[0], env.step, blue_chases=False))
        assert len(flags) == limit
        terminated, truncated, agents = flags[-1]
        assert (terminated, truncated) == (False, True)
        assert agents["Red"]["terminated"] and not agents["Red"]["truncated"]
        assert agents["Blue"]["truncated"] and not agents["Blue"]["terminated"]
        assert not any(outcome["Blue"]["truncated"] for *_, outcome in flags[:-1])
    finally:
        env.close()
    with RemoteVectorEnv(1, TIMED_PAIR, in_process=True, max_episode_steps=limit) as envs:
        observations, _ = envs.reset(seed=SEED)
        for _ in range(limit):
            actions = {"Red": chase(observations["Red"][0])[None], "Blue": STILL[None]}
            observations, _, terminations, truncations, infos = envs.step(actions)
        assert (bool(terminations[0]), bool(truncations[0])) == (False, True)
        assert _agents_of(infos, 0) == {
            "Red": {"terminated": True, "truncated": False},
            "Blue": {"terminated": False, "truncated": True},
        }


def test_the_registered_multi_agent_id_gives_remote_env_its_time_limit() -> None:
    registration = ENVIRONMENTS["rlenv/Pair-v0"]
    spec = gymnasium.spec("rlenv/Pair-v0")
    assert spec.max_episode_steps == registration.max_episode_steps == 300
    assert spec.kwargs["max_episode_steps"] == 300  # RemoteEnv's own, agreeing per agent
    assert "max_episode_steps" not in gymnasium.spec("rlenv/CartPole-v0").kwargs


def test_a_runner_caught_then_the_time_limit_is_a_time_out_in_tag() -> None:
    """The new user's game: agents of two classes, through ``gymnasium.make`` and its limit."""
    from examples.tag import CHASER, Chaser, Runner

    chaser, runner = Chaser(), Runner("Runner")
    env = gymnasium.make("rlenv/Tag-v0")
    try:
        ends = {}
        for seed in (2, 0):  # seed 2: Runner2 alone is caught in 300 steps; seed 0: both are
            observation, _ = env.reset(seed=seed)
            terminated = truncated = False
            steps = 0
            while not (terminated or truncated):  # gym.make's TimeLimit ends it at 300 at most
                observation, _, terminated, truncated, info = env.step(
                    {
                        name: (chaser if name == CHASER else runner).heuristic(value)
                        for name, value in observation.items()
                    }
                )
                steps += 1
            ends[seed] = (
                steps,
                terminated,
                truncated,
                {
                    name: (outcome["terminated"], outcome["truncated"])
                    for name, outcome in info["agents"].items()
                },
            )
    finally:
        env.close()
    assert ends[2] == (
        300,
        False,
        True,
        {"Chaser": (False, True), "Runner1": (False, True), "Runner2": (True, False)},
    )
    steps, terminated, truncated, agents = ends[0]
    assert steps < 300 and (terminated, truncated) == (True, False)
    assert agents == dict.fromkeys(agents, (True, False))
