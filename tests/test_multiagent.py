"""Several agents in one environment: keyed spaces and outcomes, PettingZoo's parallel API."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import Serve
from gymnasium import spaces

from examples.pair import NAMES, PairAgent, PairEnvironment, PairWorld, chase
from rlenv.environment import RLEnvironment
from rlenv_client import Client, ErrorCode, LocalClient, RemoteError

PAIR = "examples.pair:PairEnvironment"


def test_spaces_and_outcomes_are_keyed_by_agent(serve: Serve) -> None:
    server = serve(PAIR)
    with Client(server.host, server.port, timeout=10) as client:
        assert client.hello.agents == NAMES
        assert client.action_space == spaces.Dict({n: PairAgent.action_space for n in NAMES})
        observation, _ = client.reset(seed=4)
        assert set(observation) == set(NAMES)
        assert observation["Red"][6:8] == pytest.approx(-observation["Blue"][6:8], abs=1e-5)
        done: dict[str, int] = {}
        for step in range(300):
            live = [n for n in NAMES if n not in done]
            observation, reward, terminated, truncated, info = client.step(
                {n: chase(observation[n]) for n in live}
            )
            outcomes = info["agents"]
            assert reward == pytest.approx(sum(o["reward"] for o in outcomes.values()))
            for name in live:
                if outcomes[name]["terminated"]:
                    assert outcomes[name]["reward"] > 9.0
                    done[name] = step
            if terminated:
                break
        assert set(done) == set(NAMES) and terminated and not truncated
        with pytest.raises(RemoteError) as error:
            client.step({n: np.zeros(2, np.float32) for n in NAMES})
        assert error.value.code == ErrorCode.RESET_REQUIRED


def test_joint_actions_are_checked_per_agent(serve: Serve) -> None:
    server = serve(PAIR)
    with Client(server.host, server.port, timeout=10) as client:
        client.reset(seed=0)
        still = np.zeros(2, np.float32)
        for action, words in [
            (still, "action must be a map from agent name to action"),
            ({"Red": still}, "no action for agent 'Blue'"),
            ({"Red": still, "Blue": still, "Green": still}, "unknown agent 'Green'"),
            ({"Red": still, "Blue": np.ones(3, np.float32)}, "action['Blue'] has shape (3,)"),
        ]:
            with pytest.raises(RemoteError) as error:
                client.step(action)
            assert error.value.code == ErrorCode.INVALID_ACTION
            assert words in error.value.message
        client.step({"Red": still, "Blue": still})


def test_pettingzoo_parallel_api() -> None:
    pytest.importorskip("pettingzoo")
    from pettingzoo.test import parallel_api_test

    from rlenv_client.pettingzoo import RemoteParallelEnv

    for target, cycles in ((PAIR, 60), ("examples.cartpole:CartPoleEnvironment", 20)):
        env = RemoteParallelEnv(target, max_cycles=cycles)
        try:
            parallel_api_test(env, num_cycles=150)
        finally:
            env.close()


def test_pettingzoo_agents_leave_when_done() -> None:
    pytest.importorskip("pettingzoo")
    from rlenv_client.pettingzoo import RemoteParallelEnv

    env = RemoteParallelEnv(PAIR, in_process=True)
    try:
        observations, infos = env.reset(seed=4)
        assert env.agents == list(NAMES) and set(infos) == set(NAMES)
        finished = []
        while env.agents:
            observations, rewards, terminations, _, _ = env.step(
                {agent: chase(observations[agent]) for agent in env.agents}
            )
            finished += [agent for agent, done in terminations.items() if done]
            assert set(env.agents).isdisjoint(finished)
        assert sorted(finished) == sorted(NAMES)
    finally:
        env.close()


class _TunableAgent(PairAgent):
    configurable = ("force",)


class _MixedPair(PairEnvironment):
    """Red may be configured with a force, Blue may not."""

    def __init__(self) -> None:
        RLEnvironment.__init__(self, "Pair", repeat_action=4)
        self.add_child(_TunableAgent("Red"))  # the first agent: the one a single check looked at
        self.add_child(PairAgent("Blue"))
        self.add_child(PairWorld())


def test_an_agent_config_is_checked_for_every_agent_before_any_applies() -> None:
    with LocalClient(_MixedPair) as client:
        red = client.environment.get_node("Red")
        with pytest.raises(RemoteError, match="PairAgent has no configurable 'force'") as error:
            client.configure(agent={"force": (1.0, 1.0)})
        assert error.value.code == ErrorCode.INVALID_CONFIG
        assert red.force == (0.0, 0.0)  # refused as a whole: Red was not changed either
