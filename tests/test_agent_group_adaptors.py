"""A group of agents (issue 46) through the trainers' adaptors, over real servers.

On ``tests/swarm_envs.py``'s discs (8 slots, 6 start, one joins at tick 10, a disc past the
edge leaves, every member is truncated at tick 120; ``repeat_action=4``: a step is 4 ticks)
and their mixed environment (the discs beside an ordinary agent, the shepherd):

- ``AgentVectorEnv`` / ``SB3VecEnv(agents=GROUP)``: a sub-environment per member per instance,
  the group's arrays reshaped, ``is_active``, final transitions once, joins, waits;
- ``RemoteVectorEnv`` / ``RemoteEnv``: the stacked spaces, outcomes as arrays, ``check_env``;
- PettingZoo's ``RemoteParallelEnv``: members as named agents, ``parallel_api_test``.

RLlib's ``RemoteMultiAgentEnv`` on a group is tested in ``test_rllib.py`` (it needs ray).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from api_warnings import parallel_api_complaints
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env

from rlenv_client import RemoteEnv
from rlenv_client.agent_vector import AgentVectorEnv
from rlenv_client.vector import RemoteVectorEnv

TESTS = Path(__file__).parent
SWARM = "swarm_envs:SwarmEnvironment"
MIXED = "swarm_envs:MixedEnvironment"
PACED = "swarm_envs:PacedSwarmEnvironment"  # the group decides every 3 ticks
DISCRETE = "swarm_envs:DiscreteSwarmEnvironment"  # Discrete(5): none, +x, -x, +y, -y
MEMBERS = 8  # Discs.instance_count
STARTING = [True] * 6 + [False] * 2  # Discs.initial_count: 6
LEFT = np.array([-1.0, 0.0], np.float32)  # a push towards -x: member 0 leaves at step 5
RIGHT = np.array([1.0, 0.0], np.float32)


@pytest.fixture(autouse=True)
def _tests_on_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(TESTS))
    path = os.pathsep.join(filter(None, [str(TESTS), os.environ.get("PYTHONPATH")]))
    monkeypatch.setenv("PYTHONPATH", path)


def _still(count: int) -> np.ndarray:
    return np.zeros((count, 2), np.float32)


# --- AgentVectorEnv and SB3VecEnv: a sub-environment per member ------------------------------


def test_every_member_of_every_instance_is_a_sub_environment() -> None:
    with AgentVectorEnv(2, SWARM, agents="Discs") as env:
        assert (env.instances, env.num_envs) == (2, 2 * MEMBERS)
        assert env.single_observation_space == spaces.Box(-50.0, 50.0, (4,), np.float32)
        assert env.single_action_space == spaces.Box(-1.0, 1.0, (2,), np.float32)
        observations, infos = env.reset(seed=0)
        assert observations.shape == (16, 4)
        assert infos["is_active"].tolist() == STARTING * 2
        assert infos["waiting"].tolist() == [not s for s in STARTING] * 2
        assert observations[:2, :2].tolist() == [[-1.5, -0.5], [-0.5, -0.5]]  # the grid
        assert not observations[6:8].any() and not observations[14:16].any()  # not in play
        actions = _still(16)
        actions[9] = RIGHT  # member 1 of instance 1 only
        observations, rewards, terminated, truncated, infos = env.step(actions)
        assert observations[9, 2] > 0 and observations[1, 2] == 0.0  # its velocity, not 1's
        assert infos["is_active"].tolist() == STARTING * 2
        assert not rewards[~infos["is_active"]].any() and rewards[infos["is_active"]].all()
        assert not (terminated.any() or truncated.any())


def test_a_member_ends_once_then_waits_for_its_instance_and_one_joins() -> None:
    with AgentVectorEnv(2, SWARM, agents="Discs") as env:
        env.reset(seed=0)
        actions = _still(16)
        actions[0] = LEFT
        steps = [env.step(actions) for _ in range(8)]
        # member 6 joins at tick 10, in the answer at tick 12 (step 3): reward 0, no boundary
        observations, rewards, terminated, truncated, infos = steps[2]
        assert infos["is_active"][[6, 14]].all() and not infos["waiting"][[6, 14]].any()
        assert rewards[6] == rewards[14] == 0.0 and not (terminated[6] or truncated[6])
        assert observations[6].any()  # its first observation (the centre, pushed about)
        ends = [int(np.flatnonzero(step[2])[0]) if step[2].any() else None for step in steps]
        assert ends == [None] * 4 + [0] + [None] * 3  # member 0 of instance 0, once
        observations, rewards, terminated, truncated, infos = steps[4]
        final = infos["final_obs"][0]
        assert final[0] < -3.0 and not observations[0].any()  # past the edge; then zeros
        assert infos["is_active"][0] and rewards[0] < 0 and not truncated[0]
        assert infos["final_info"]["member"][0] == 0 and infos["final_info"]["agent"][0] == "Discs"
        for observations, rewards, terminated, truncated, infos in steps[5:]:
            assert not observations[0].any() and rewards[0] == 0.0
            assert not infos["is_active"][0] and infos["waiting"][0]
            assert not (terminated[0] or truncated[0])


def test_the_end_of_an_instance_ends_every_slot_and_resets_them_at_once() -> None:
    # max_episode_steps=3: the episode ends at tick 12, in the very answer member 6 joins
    with AgentVectorEnv(2, SWARM, agents="Discs", max_episode_steps=3) as env:
        first, _ = env.reset(seed=0)
        for _ in range(2):
            env.step(_still(16))
        observations, rewards, terminated, truncated, infos = env.step(_still(16))
        assert truncated.all() and not terminated.any()
        waited = infos["final_info"]["_waiting"]
        assert waited.tolist() == [False] * 7 + [True] + [False] * 7 + [True]  # slot 7: a wait
        assert infos["final_obs"][6].any() and rewards[6] == 0.0  # 6 joined as it ended: a row
        assert infos["final_info"]["_frames"].tolist() == [not w for w in waited]
        assert observations.tobytes() == first.tobytes()  # the next episode, deterministic
        assert infos["is_active"].tolist() == STARTING * 2
        assert infos["waiting"].tolist() == [not s for s in STARTING] * 2


def test_sb3_gives_each_member_its_terminal_observation_and_episode_once() -> None:
    pytest.importorskip("stable_baselines3")
    from rlenv_client.sb3 import SB3VecEnv

    env = SB3VecEnv(1, SWARM, agents="Discs")
    try:
        assert env.num_envs == MEMBERS
        env.reset()
        actions = _still(MEMBERS)
        actions[0] = LEFT
        seen = []
        for _ in range(8):
            env.step_async(actions)
            _, rewards, dones, infos = env.step_wait()
            seen.append((dones.copy(), infos))
        assert [step[0].tolist().count(True) for step in seen] == [0] * 4 + [1] + [0] * 3
        dones, infos = seen[4]
        assert dones[0] and infos[0]["terminal_observation"][0] < -3.0
        assert infos[0]["episode"]["l"] == 5 and not infos[0]["TimeLimit.truncated"]
        assert all("terminal_observation" not in info for _, step in seen[5:] for info in step)
        assert seen[-1][1][0]["waiting"] and not seen[-1][1][0]["is_active"]
    finally:
        env.close()


def test_sb3_trains_ppo_on_the_group_beside_a_driven_shepherd() -> None:
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO

    from rlenv_client.sb3 import SB3VecEnv

    calls = []

    def shepherd(observation: Any) -> np.ndarray:
        calls.append(observation.shape)
        return np.zeros(2, np.float32)

    env = SB3VecEnv(2, MIXED, agents="Discs", others={"Shepherd": shepherd})
    try:
        assert env.num_envs == 2 * MEMBERS
        model = PPO("MlpPolicy", env, n_steps=8, batch_size=64, n_epochs=1, seed=0)
        model.learn(2 * 8 * env.num_envs)
        assert model.num_timesteps == 2 * 8 * env.num_envs
        assert calls and set(calls) == {(2,)}  # the shepherd's own observation, per instance
    finally:
        env.close()


def test_discrete_members_and_a_paced_group_are_sub_environments_too() -> None:
    with AgentVectorEnv(2, DISCRETE, agents="Discs") as env:
        assert env.single_action_space == spaces.Discrete(5)
        assert env.action_space == spaces.MultiDiscrete([5] * 16)
        env.reset(seed=0)
        moves = np.zeros(16, np.int64)
        moves[0], moves[9] = 2, 1  # -x for member 0 of instance 0, +x for member 1 of 1
        observations, *_ = env.step(moves)
        assert observations[0, 2] < 0 < observations[9, 2]
        assert observations[1, 2] == observations[8, 2] == 0.0
    with AgentVectorEnv(1, PACED, agents="Discs") as env:
        env.reset(seed=0)
        _, rewards, _, _, infos = env.step(_still(MEMBERS))
        assert infos["frames"].tolist() == [3] * MEMBERS  # the group's decision period
        assert infos["is_active"].tolist() == STARTING and rewards[:6].all()


def test_a_group_beside_an_ordinary_agent_picks_either_to_learn() -> None:
    still_group = np.zeros((MEMBERS, 2), np.float32)
    with AgentVectorEnv(
        2, MIXED, agents="Discs", others={"Shepherd": lambda o: np.zeros(2, np.float32)}
    ) as env:
        observations, infos = env.reset(seed=0)
        assert env.num_envs == 16 and observations.shape == (16, 4)
        observations, *_ = env.step(_still(16))
        assert observations.shape == (16, 4)
    with AgentVectorEnv(
        2, MIXED, agents="Shepherd", others={"Discs": lambda o: still_group}
    ) as env:
        observations, _ = env.reset(seed=0)
        assert env.num_envs == 2 and observations.shape == (2, 2)
        observations, rewards, *_ = env.step(_still(2))
        assert rewards.tolist() == pytest.approx([0.4, 0.4])  # 0.1 per tick
    with pytest.raises(ValueError, match="group 'Discs' learns alone"):
        AgentVectorEnv(1, MIXED, agents=["Discs", "Shepherd"], in_process=True)


def test_agent_classes_name_a_groups_members_in_its_place() -> None:
    from swarm_envs import Discs, Shepherd

    from rlenv_client.agent_vector import agent_classes

    assert agent_classes(MIXED) == {"Discs": Discs, "Shepherd": Shepherd}
    members = agent_classes(MIXED, members=True)
    assert members == {**{f"Discs_{i}": Discs for i in range(MEMBERS)}, "Shepherd": Shepherd}
    assert list(members)[-1] == "Shepherd"  # in the environment's order


# --- RemoteVectorEnv and RemoteEnv: the group's stacked arrays --------------------------------


def test_remote_vector_env_gives_the_group_as_arrays() -> None:
    with RemoteVectorEnv(2, MIXED, max_episode_steps=3, autoreset_mode="SameStep") as env:
        assert env.single_observation_space["Discs"].shape == (MEMBERS, 4)
        assert env.single_action_space["Discs"].shape == (MEMBERS, 2)
        observations, infos = env.reset(seed=0)
        assert observations["Discs"].shape == (2, MEMBERS, 4)
        assert observations["Shepherd"].shape == (2, 2)
        assert infos["agents"]["Discs"]["active"].tolist() == [STARTING] * 2
        actions = {"Discs": np.zeros((2, MEMBERS, 2), np.float32), "Shepherd": _still(2)}
        observations, rewards, *_, infos = env.step(actions)
        group = infos["agents"]["Discs"]
        assert group["reward"].shape == group["active"].shape == (2, MEMBERS)
        assert not group["reward"][~group["active"]].any()
        shepherd = infos["agents"]["Shepherd"]["reward"]
        assert rewards == pytest.approx(group["reward"].sum(axis=1) + shepherd)
        env.step(actions)
        *_, truncated, infos = env.step(actions)  # the time limit
        final = infos["final_info"]["agents"]["Discs"]
        assert truncated.all() and final["truncated"].tolist() == final["active"].tolist()
        assert final["active"][0].tolist() == [True] * 7 + [False]  # 6 joined at the end


@pytest.mark.parametrize("target", [SWARM, MIXED, PACED])
def test_remote_env_passes_gymnasiums_checker_on_a_group(target: str) -> None:
    env = RemoteEnv(target)
    try:
        check_env(env, skip_render_check=True)
        observation, info = env.reset(seed=0)
        assert observation["Discs"].shape == (MEMBERS, 4)
        assert info["agents"]["Discs"]["active"].tolist() == STARTING
        observation, reward, _, _, info = env.step(env.action_space.sample())
        outcome = info["agents"]["Discs"]
        assert set(outcome) == {"reward", "terminated", "truncated", "active", "joined"}
        others = sum(o["reward"] for name, o in info["agents"].items() if name != "Discs")
        assert reward == pytest.approx(outcome["reward"].sum() + others)
    finally:
        env.close()


# --- PettingZoo: members as named agents -----------------------------------------------------


@pytest.mark.parametrize("target", [SWARM, MIXED, PACED])
def test_parallel_api_test_passes_on_a_group(target: str) -> None:
    pytest.importorskip("pettingzoo")
    from rlenv_client.pettingzoo import RemoteParallelEnv

    env = RemoteParallelEnv(target)
    try:
        assert not parallel_api_complaints(env, num_cycles=300)
    finally:
        env.close()


def test_pettingzoo_names_members_and_follows_them_in_and_out() -> None:
    pytest.importorskip("pettingzoo")
    from rlenv_client.pettingzoo import RemoteParallelEnv

    env = RemoteParallelEnv(MIXED)
    try:
        members = [f"Discs_{i}" for i in range(MEMBERS)]
        assert env.possible_agents == [*members, "Shepherd"]
        assert env.observation_space("Discs_3") == spaces.Box(-50.0, 50.0, (4,), np.float32)
        assert env.action_space("Shepherd").shape == (2,)
        observations, infos = env.reset(seed=0)
        assert env.agents == [*members[:6], "Shepherd"] and list(observations) == env.agents
        assert observations["Discs_1"][:2].tolist() == [-0.5, -0.5]
        history = []
        for _ in range(6):
            actions = {name: np.zeros(2, np.float32) for name in env.agents}
            actions["Discs_0"] = LEFT
            history.append((list(env.agents), env.step(actions)))
        played, (observations, rewards, terminations, truncations, infos) = history[2]
        assert "Discs_6" not in played and "Discs_6" in observations
        assert rewards["Discs_6"] == 0.0 and observations["Discs_6"].any()  # joined at 12
        ended = [name for _, step in history for name, done in step[2].items() if done]
        assert ended == ["Discs_0"]  # once, at tick 20
        played, (observations, rewards, terminations, *_) = history[4]
        assert terminations["Discs_0"] and observations["Discs_0"][0] < -3.0
        assert "Discs_0" not in env.agents and "Discs_0" not in history[5][1][0]
    finally:
        env.close()


def test_pettingzoo_marks_every_member_of_a_group_a_person_claimed(serve: Any) -> None:
    pytest.importorskip("pettingzoo")
    from rlenv_client import Client
    from rlenv_client.pettingzoo import RemoteParallelEnv

    server = serve(MIXED)
    env = RemoteParallelEnv(address=f"{server.host}:{server.port}")
    try:
        env.reset(seed=0)
        with Client(server.host, server.port) as person:
            assert person.claim("Discs", np.zeros((MEMBERS, 2), np.float32)) == ["Discs"]
            infos = env.step({agent: np.zeros(2, np.float32) for agent in env.agents})[4]
            assert [name for name, info in infos.items() if info.get("claimed")] == [
                f"Discs_{i}" for i in range(6)
            ]
            person.release_claim()
            infos = env.step({agent: np.zeros(2, np.float32) for agent in env.agents})[4]
            assert all("claimed" not in info for info in infos.values())
    finally:
        env.close()
