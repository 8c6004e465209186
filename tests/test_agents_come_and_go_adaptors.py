"""Agents that come and go (issue 42) through the client's adaptors, over real servers.

PettingZoo's ``RemoteParallelEnv`` (entries for every agent in play, ``infos[agent]["due"]``)
and gymnasium's ``RemoteEnv`` (a fixed ``Dict`` with zeros, ``info["due"]``) on
``tests/come_and_go_envs.py``'s games, whose every tick is known (A and B start, C joins at
tick 6, B is freed at 10, A terminates at 20, C is truncated at 30; four walkers at three
paces), and on ``examples.hunt``; ``AgentVectorEnv``'s fixed slots and mask
(``infos["is_active"]``) likewise. RLlib's ``RemoteMultiAgentEnv`` is tested in
``test_rllib.py`` (it needs ray), ``SB3VecEnv(agents=...)`` in ``test_sb3.py``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from api_warnings import parallel_api_complaints
from gymnasium.utils.env_checker import check_env

from rlenv_client import RemoteEnv

pettingzoo = pytest.importorskip("pettingzoo")

from rlenv_client.pettingzoo import RemoteParallelEnv  # noqa: E402

TESTS = Path(__file__).parent
COME_AND_GO = "come_and_go_envs:ComeAndGoEnvironment"
PACED = "come_and_go_envs:PacedEnvironment"
HUNT = "examples.hunt:HuntEnvironment"
NOT_SENT = object()  # cannot travel on the wire: sending it would raise TypeError


@pytest.fixture(autouse=True)
def _tests_on_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(TESTS))
    path = os.pathsep.join(filter(None, [str(TESTS), os.environ.get("PYTHONPATH")]))
    monkeypatch.setenv("PYTHONPATH", path)


@pytest.mark.parametrize("target", [COME_AND_GO, HUNT, PACED])
def test_parallel_api_test_passes(target: str) -> None:
    env = RemoteParallelEnv(target)
    try:
        assert not parallel_api_complaints(env, num_cycles=1000)
    finally:
        env.close()


def test_the_parallel_env_follows_agents_in_and_out() -> None:
    env = RemoteParallelEnv(COME_AND_GO)
    try:
        assert env.possible_agents == ["A", "B", "C", "D"]
        observations, infos = env.reset(seed=0)
        assert env.agents == ["A", "B"] and sorted(observations) == ["A", "B"]
        assert infos == {"A": {"due": True}, "B": {"due": True}}
        history = []
        while env.agents:
            played = list(env.agents)
            step = env.step(dict.fromkeys(env.agents, 2))
            history.append((played, *step, list(env.agents)))
        in_play = [before for before, *_ in history]
        assert in_play == [["A", "B"], ["A", "B"], ["A", "B", "C"], ["A", "C"], ["A", "C"],
                           ["C"], ["C"], ["C"]]  # fmt: skip
        _, observations, rewards, terminations, truncations, infos, after = history[1]
        assert after == ["A", "B", "C"]  # C joined at tick 6: in the answer at tick 8
        assert rewards["C"] == 0.0 and observations["C"].tolist() == [0.0, 8.0]
        assert infos["C"] == {"frames": 4, "due": True}
        _, observations, rewards, terminations, truncations, infos, after = history[2]
        assert terminations == {"A": False, "B": True, "C": False} and after == ["A", "C"]
        assert observations["B"].tolist() == [10.0, 10.0] and rewards["B"] == 2.0
        assert infos["B"]["due"] is False  # it left: it decides no more
        _, observations, rewards, terminations, truncations, infos, after = history[-1]
        assert set(observations) == {"C"} and truncations == {"C": True} and after == []
    finally:
        env.close()


def test_agents_not_due_keep_their_last_observation_and_their_actions_are_never_sent() -> None:
    env = RemoteParallelEnv(PACED)
    try:
        observations, _ = env.reset(seed=0)
        assert env.agents == ["Fast", "Slow", "Plain", "Jerky"]
        first = {name: value.copy() for name, value in observations.items()}
        due = dict.fromkeys(env.agents, True)
        deciders = []
        for _ in range(6):
            actions = {name: 2 if due[name] else NOT_SENT for name in env.agents}
            observations, rewards, terminations, truncations, infos = env.step(actions)
            assert set(observations) == set(env.agents) == set(rewards) == set(infos)
            due = {name: infos[name]["due"] for name in env.agents}
            deciders.append(sorted(name for name in due if due[name]))
            for name in env.agents:
                if not due[name]:
                    assert rewards[name] == 0.0
                    assert not (terminations[name] or truncations[name])
        assert deciders == [
            ["Fast", "Plain"],  # tick 2
            ["Plain", "Slow"],  # 3
            ["Fast", "Jerky", "Plain"],  # 4
            ["Fast", "Plain"],  # 6
            ["Fast", "Jerky", "Plain"],  # 8
            ["Plain", "Slow"],  # 9
        ]
        _, rewards, *_ = env.step({name: 2 for name in env.agents})  # tick 10: Fast, Plain
        assert rewards["Slow"] == 0.0  # 6 ticks of reward, kept for its decision at 15
        env.reset(seed=0)
        observations, *_ = env.step(dict.fromkeys(env.agents, 2))
        for name in ("Slow", "Jerky"):  # not due at tick 2: their reset observation
            assert observations[name].tobytes() == first[name].tobytes()
    finally:
        env.close()


def test_driven_prey_stay_out_of_the_trainers_view() -> None:
    env = RemoteParallelEnv(HUNT, server_args=["--policy", "Prey1=heuristic"])
    try:
        assert "Prey1" not in env.possible_agents and "Hunter" in env.possible_agents
        observations, _ = env.reset(seed=0)
        assert env.agents == ["Hunter", "Prey2"]
        with pytest.raises(ValueError, match="agent 'Prey1' is driven by the server"):
            env.step({"Prey1": np.zeros(2, np.float32)})
        for _ in range(40):
            entries = env.step({name: env.action_space(name).sample() for name in env.agents})
            assert all("Prey1" not in entry for entry in entries)
            assert "Prey1" not in env.agents
            assert any(infos["due"] for infos in entries[4].values())
    finally:
        env.close()


def test_a_fixed_multi_agent_example_is_as_before() -> None:
    env = RemoteParallelEnv("examples.pair:PairEnvironment")
    try:
        observations, infos = env.reset(seed=0)
        assert env.agents == env.possible_agents and infos == dict.fromkeys(env.agents, {})
        step = env.step({name: env.action_space(name).sample() for name in env.agents})
        assert all(set(entry) == set(env.possible_agents) for entry in step)
        assert all("due" not in info for info in step[4].values())
    finally:
        env.close()


def _play_gymnasium(env: RemoteEnv) -> list[tuple[Any, ...]]:
    observation, info = env.reset(seed=0)
    answers: list[tuple[Any, ...]] = [(observation, info)]
    while True:
        action = {name: 2 if name in info["due"] else NOT_SENT for name in observation}
        observation, reward, terminated, truncated, info = env.step(action)
        answers.append((observation, reward, terminated, truncated, info))
        if terminated or truncated:
            return answers


def test_remote_env_gives_every_possible_agent_a_fixed_slot_with_zeros() -> None:
    env = RemoteEnv(COME_AND_GO)
    try:
        assert list(env.observation_space.spaces) == ["A", "B", "C", "D"]
        answers = _play_gymnasium(env)
        zeros = np.zeros(2, np.float32)
        observation, info = answers[0]
        assert info["due"] == ("A", "B")
        assert observation["C"].tobytes() == observation["D"].tobytes() == zeros.tobytes()
        observation, reward, _, _, info = answers[2]  # C joined (reward None: nothing)
        assert info["due"] == ("A", "B", "C") and reward == 8.0
        assert observation["C"].tolist() == [0.0, 8.0] and info["agents"]["C"]["reward"] is None
        observation, reward, _, _, info = answers[3]  # B left: its final observation, once
        assert info["due"] == ("A", "C") and observation["B"].tolist() == [10.0, 10.0]
        assert info["agents"]["B"]["terminated"] and reward == 10.0
        observation, *_ = answers[4]
        assert observation["B"].tobytes() == zeros.tobytes()  # gone: zeros
        for answer in answers:
            assert env.observation_space.contains(answer[0])
        _, _, terminated, truncated, info = answers[-1]
        assert (terminated, truncated, info["due"]) == (False, True, ())
    finally:
        env.close()


def test_remote_env_passes_gymnasiums_checker_on_agents_that_come_and_go() -> None:
    env = RemoteEnv(PACED)
    try:
        check_env(env, skip_render_check=True)
        _, info = env.reset(seed=0)
        _, _, _, _, info = env.step(dict.fromkeys(info["due"], 2))
        assert info["due"] == ("Fast", "Plain")
        observation, *_ = env.step({"Fast": 2, "Plain": 2, "Slow": NOT_SENT, "Jerky": 0})
        assert observation["Fast"].tobytes() == np.zeros(2, np.float32).tobytes()  # not due
    finally:
        env.close()


def test_remote_env_leaves_driven_agents_out_when_agents_come_and_go() -> None:
    env = RemoteEnv(HUNT, server_args=["--policy", "Prey1=heuristic"])
    try:
        assert "Prey1" not in env.observation_space.spaces
        observation, info = env.reset(seed=0)
        assert info["due"] == ("Hunter", "Prey2")
        for _ in range(20):
            observation, reward, *_, info = env.step(env.action_space.sample())
            assert "Prey1" not in observation and "Prey1" not in info["due"]
            mine = {name: o for name, o in info["agents"].items() if name != "Prey1"}
            assert reward == pytest.approx(sum(o["reward"] or 0.0 for o in mine.values()))
    finally:
        env.close()


# --- vector envs: a fixed slot per possible agent, and a mask ---------------------------------


def test_agent_vector_keeps_a_slot_per_possible_agent_with_a_mask() -> None:
    from come_and_go_envs import Walker

    from rlenv_client.agent_vector import AgentVectorEnv

    with AgentVectorEnv(2, COME_AND_GO, agents=Walker) as env:
        assert env.learners == ["A", "B", "C", "D"] and env.num_envs == 8
        observations, infos = env.reset(seed=0)
        assert infos["is_active"].tolist() == [True, True, False, False] * 2
        assert infos["waiting"].tolist() == [False, False, True, True] * 2
        assert not observations[2:4].any()  # not in play: zeros
        moves = np.full(env.num_envs, 2)
        steps = [env.step(moves) for _ in range(8)]  # the episode: ticks 4, 8 ... 28, 30
        active = [step[4]["is_active"][:4].tolist() for step in steps]
        assert active == [
            [True, True, False, False],
            [True, True, True, False],  # C joined at tick 6
            [True, True, True, False],  # B left at tick 10: its final transition
            [True, False, True, False],
            [True, False, True, False],  # A terminated at 20
            [False, False, True, False],
            [False, False, True, False],
            [True, True, False, False],  # no one left at 30: the next episode's A and B start
        ]
        observations, rewards, terminated, truncated, infos = steps[1]
        assert observations[2].tolist() == [0.0, 8.0] and rewards[2] == 0.0  # C's first
        observations, rewards, terminated, truncated, infos = steps[2]
        assert terminated[:4].tolist() == [False, True, False, False] and rewards[1] == 2.0
        assert infos["final_obs"][1].tolist() == [10.0, 10.0]
        observations, rewards, terminated, truncated, infos = steps[3]
        assert observations[1].tolist() == [10.0, 10.0] and rewards[1] == 0.0  # B waits
        assert infos["waiting"][:4].tolist() == [False, True, False, True]
        assert not (terminated[1] or truncated[1])
        observations, rewards, terminated, truncated, infos = steps[-1]
        assert truncated[:4].all()  # C's end, and the others' waits end
        assert [infos["final_info"]["waiting"][i] for i in (0, 1, 3)] == [True, True, True]
        assert infos["final_obs"][2].tolist() == [22.0, 30.0]  # C truncated at 30
        assert not observations[2:4].any() and observations[0].tolist() == [0.0, 0.0]


def test_agent_vector_gives_an_agent_that_joins_as_its_instance_ends_its_one_row() -> None:
    from come_and_go_envs import Walker

    from rlenv_client.agent_vector import AgentVectorEnv

    # C joins at tick 6, in the answer at tick 8: the second step, which the time limit ends
    with AgentVectorEnv(2, COME_AND_GO, agents=Walker, max_episode_steps=2) as env:
        env.reset(seed=0)
        env.step(np.full(env.num_envs, 2))
        _, rewards, terminated, truncated, infos = env.step(np.full(env.num_envs, 2))
        assert truncated.all() and not terminated.any()
        final = infos["final_info"]
        for c, d in ((2, 3), (6, 7)):  # C and D of each instance
            assert infos["final_obs"][c].tolist() == [0.0, 8.0]  # its first observation
            assert rewards[c] == 0.0 and not final["_waiting"][c]  # a row, not a wait
            assert (final["agent"][c], final["frames"][c]) == ("C", 4)
            assert final["waiting"][d] and infos["final_obs"][d].tolist() == [0.0, 0.0]
        assert infos["waiting"].tolist() == [False, False, True, True] * 2  # the next episode


def test_agent_vector_slots_of_agents_not_due_carry_their_last_observation() -> None:
    from rlenv_client.agent_vector import AgentVectorEnv

    with AgentVectorEnv(1, PACED, agents=["Fast", "Slow", "Plain", "Jerky"]) as env:
        first, infos = env.reset(seed=0)
        assert infos["is_active"].all() and "waiting" not in infos
        observations, rewards, _, _, infos = env.step(np.full(4, 2))  # tick 2: Fast, Plain
        assert infos["is_active"].tolist() == [True, False, True, False]
        assert observations[[1, 3]].tobytes() == first[[1, 3]].tobytes()
        assert rewards.tolist() == [2.0, 0.0, 2.0, 0.0]
        observations, rewards, _, _, infos = env.step(np.full(4, 2))  # tick 3: Plain, Slow
        assert infos["is_active"].tolist() == [False, True, True, False]
        assert rewards[1] == 3.0  # Slow's 3 ticks, at its decision


def test_agent_vector_on_the_hunt_trains_prey_slots_that_come_and_go() -> None:
    from examples.hunt import Prey
    from rlenv_client.agent_vector import AgentVectorEnv

    with AgentVectorEnv(1, HUNT, agents=Prey) as env:  # the hunter: its heuristic, served
        assert env.learners == [f"Prey{n}" for n in range(1, 9)]
        _, infos = env.reset(seed=0)
        assert infos["waiting"].tolist() == [False, False] + [True] * 6
        joined = caught = False
        waiting = infos["waiting"]
        for _ in range(600):
            actions = env.action_space.sample()
            _, rewards, terminated, _, infos = env.step(actions)
            active = infos["is_active"]
            assert not rewards[~active].any()  # an inactive slot earns nothing
            joined |= bool((waiting & active & ~terminated).any())
            caught |= bool(terminated.any())
            waiting = infos.get("waiting", np.zeros(8, np.bool_))
            if joined and caught:
                break
        assert joined and caught
