"""AgentVectorEnv: one agent, or a team, of a multi-agent env as a gymnasium vector."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import Serve
from gymnasium.vector import AutoresetMode

from examples.cartpole import TARGET as CARTPOLE
from examples.cartpole import CartPoleAgent
from examples.pair import TARGET as PAIR
from examples.pair import PairAgent, chase
from examples.tag import CHASER, RUNNERS, Chaser, Runner
from examples.tag import TARGET as TAG
from examples.tag.scripted import TARGET as SCRIPTED
from rlenv_client.agent_vector import AgentVectorEnv, agent_classes
from rlenv_client.vector import RemoteVectorEnv

_runner, _chaser = Runner("Runner"), Chaser()


def run_away(observation: np.ndarray) -> np.ndarray:
    """The runners' heuristic, as a callable the client calls."""
    return _runner.heuristic(observation)


def stand_still(observation: np.ndarray) -> np.ndarray:
    return np.zeros(2, np.float32)


def test_the_chaser_alone_plays_the_scripted_rewrite_bit_for_bit() -> None:
    """Training the chaser from Tag sees exactly what the single-agent rewrite gives."""
    alone = AgentVectorEnv(
        2,
        TAG,
        agents=CHASER,
        others=dict.fromkeys(RUNNERS, run_away),
        max_episode_steps=120,
        instances_per_server=2,
    )
    rewrite = RemoteVectorEnv(
        2,
        SCRIPTED,
        autoreset_mode=AutoresetMode.SAME_STEP,
        max_episode_steps=120,
        instances_per_server=2,
    )
    try:
        assert alone.num_envs == 2 and alone.learners == [CHASER]
        assert alone.single_observation_space == rewrite.single_observation_space
        assert alone.single_action_space == rewrite.single_action_space
        assert alone.driven_here == dict.fromkeys(RUNNERS, run_away)
        seen, expected = alone.reset(seed=7)[0], rewrite.reset(seed=7)[0]
        assert np.array_equal(seen, expected)
        rng = np.random.default_rng(0)
        ends = 0
        for step in range(300):
            actions = (
                np.array([_chaser.heuristic(row) for row in seen])
                if step % 4
                else rng.uniform(-1, 1, (2, 2)).astype(np.float32)
            )
            seen, *ours, info = alone.step(actions)
            expected, *theirs, their_info = rewrite.step(actions)
            assert np.array_equal(seen, expected), step
            for mine, other in zip(ours, theirs, strict=True):
                assert np.array_equal(mine, other), step
            for index in np.flatnonzero(ours[1] | ours[2]):
                ends += 1
                assert np.array_equal(info["final_obs"][index], their_info["final_obs"][index])
                assert info["final_info"]["agent"][index] == CHASER
        assert ends >= 4  # tags (terminated) and time limits (truncated) both happened
    finally:
        alone.close()
        rewrite.close()


def test_by_default_the_servers_drive_the_others_by_their_heuristics() -> None:
    """``agents="Chaser"`` alone: each runner's heuristic runs in the server, beside the
    physics (``--policy Runner1=heuristic``), and the chaser sees the rewrite's game."""
    alone = AgentVectorEnv(2, TAG, agents=CHASER, max_episode_steps=60)
    rewrite = RemoteVectorEnv(
        2,
        SCRIPTED,
        autoreset_mode=AutoresetMode.SAME_STEP,
        max_episode_steps=60,
        instances_per_server=2,
    )
    try:
        assert alone.driven_by_server == dict.fromkeys(RUNNERS, "heuristic")
        assert alone.driven_here == {}
        assert [client.hello.driven for client in alone.vector.clients] == [RUNNERS] * 2
        seen, expected = alone.reset(seed=11)[0], rewrite.reset(seed=11)[0]
        assert np.array_equal(seen, expected)
        for _ in range(150):
            actions = np.array([_chaser.heuristic(row) for row in seen])
            seen, *ours, _ = alone.step(actions)
            expected, *theirs, _ = rewrite.step(actions)
            assert np.array_equal(seen, expected)
            for mine, other in zip(ours, theirs, strict=True):
                assert np.array_equal(mine, other)
    finally:
        alone.close()
        rewrite.close()


def test_a_class_makes_each_of_its_agents_a_sub_environment_sharing_one_policy() -> None:
    team = AgentVectorEnv(2, TAG, agents=Runner, others={CHASER: stand_still}, in_process=True)
    joint = RemoteVectorEnv(2, TAG, in_process=True)
    try:
        assert team.learners == list(RUNNERS) and team.num_envs == 4
        assert team.single_observation_space == Runner.observation_space
        observations, _ = team.reset(seed=3)
        expected, _ = joint.reset(seed=3)
        for instance in range(2):
            for j, name in enumerate(RUNNERS):
                assert np.array_equal(observations[instance * 2 + j], expected[name][instance])
    finally:
        team.close()
        joint.close()


def test_a_learner_that_ends_first_waits_for_its_instance_to_reset() -> None:
    """A tagged runner's episode ends; it waits (reward 0, its last observation) until the
    chaser ends the instance's episode, and that wait ends as truncated, marked waiting."""
    team = AgentVectorEnv(
        1,
        TAG,
        agents=Runner,
        in_process=True,
        max_episode_steps=300,
        others={CHASER: lambda observation: _chaser.heuristic(observation)},
    )
    try:
        observations, _ = team.reset(seed=1)
        waits: list[int] = []
        for _ in range(300):
            previous = observations
            observations, rewards, terminated, truncated, info = team.step(
                np.zeros((2, 2), np.float32)
            )
            waiting = info.get("waiting", np.zeros(2, np.bool_))
            last = bool(truncated.any() or terminated.all())  # the instance's episode ended
            for index in np.flatnonzero(terminated):  # tagged: -10 this step, then it waits
                assert rewards[index] < -9 and waiting[index] != last
                if not last:
                    assert np.array_equal(observations[index], info["final_obs"][index])
                    waits.append(index)
            for index in np.flatnonzero(waiting & ~terminated):
                assert rewards[index] == 0.0 and not truncated[index]
                assert np.array_equal(observations[index], previous[index])
            if last:  # the chaser tagged both: a wait ends here, as truncated
                for index in np.flatnonzero(truncated):
                    assert index in waits and info["final_info"]["waiting"][index]
                    assert rewards[index] == 0.0
                if truncated.any():
                    break
        else:
            pytest.fail("the chaser's heuristic tagged no standing runner in 300 steps")
        assert waits and "waiting" not in info
    finally:
        team.close()


def test_a_single_agent_environment_has_its_one_agent_as_learner() -> None:
    alone = AgentVectorEnv(2, CARTPOLE, agents=CartPoleAgent, in_process=True)
    plain = RemoteVectorEnv(2, CARTPOLE, in_process=True, autoreset_mode=AutoresetMode.SAME_STEP)
    try:
        assert alone.single_observation_space == plain.single_observation_space
        assert np.array_equal(alone.reset(seed=2)[0], plain.reset(seed=2)[0])
        actions = np.ones((2, 1), np.float32)
        for _ in range(40):
            ours, theirs = alone.step(actions), plain.step(actions)
            for mine, other in zip(ours[:4], theirs[:4], strict=True):
                assert np.array_equal(mine, other)
    finally:
        alone.close()
        plain.close()


def test_agent_classes_reads_each_agents_class_from_the_target() -> None:
    assert agent_classes(TAG) == {CHASER: Chaser, "Runner1": Runner, "Runner2": Runner}


@pytest.mark.parametrize(
    ("agents", "others", "message"),
    [
        (
            "Red",
            None,
            "agent 'Blue' neither learns nor has a policy in others, and its class has no "
            "heuristic: give others={'Blue': 'policy.onnx'} or a callable, or define "
            "PairAgent.heuristic",
        ),
        ("Green", None, "agents: the environment has no agent 'Green'; its agents: Red, Blue"),
        (
            Chaser,
            None,
            "agents: no agent is a Chaser; its agents: Red (PairAgent), Blue (PairAgent)",
        ),
        (
            "Red",
            {"Green": chase},
            "others: the environment has no agent 'Green'; its agents: "
            "Red (PairAgent), Blue (PairAgent)",
        ),
        (PairAgent, {"Red": chase}, "others: agent 'Red' is a learner (agents selects it)"),
        ("Red", {"Blue": "nowhere.onnx"}, "others['Blue']: no such policy file: nowhere.onnx"),
    ],
)
def test_refusals_name_the_agent(agents: object, others: object, message: str) -> None:
    with pytest.raises(ValueError) as refused:
        AgentVectorEnv(1, PAIR, agents=agents, others=others)  # type: ignore[arg-type]
    assert str(refused.value) == message


def test_others_that_is_not_a_map_is_refused_saying_what_it_takes() -> None:
    with pytest.raises(TypeError) as refused:
        AgentVectorEnv(1, PAIR, agents="Red", others="heuristic")  # type: ignore[arg-type]
    assert str(refused.value) == (
        "others must map agent names (or RLAgent classes) to what drives them, e.g. "
        '{"Runner1": "heuristic"}; got \'heuristic\''
    )


def test_learners_sharing_a_policy_must_share_spaces() -> None:
    with pytest.raises(
        ValueError, match="agents 'Chaser' and 'Runner1' learn one policy but have different spaces"
    ):
        AgentVectorEnv(
            1, TAG, agents=[CHASER, "Runner1"], in_process=True, others={"Runner2": run_away}
        )


def test_running_servers_cannot_be_given_server_side_policies(serve: Serve) -> None:
    server = serve(TAG)
    with pytest.raises(ValueError) as refused:
        AgentVectorEnv(None, TAG, agents=CHASER, addresses=[server.address])
    assert str(refused.value) == (
        "agent 'Runner1' is to be driven by 'heuristic' in its server, and servers given by "
        "address start no server here: give others={'Runner1': callable}, or serve it with "
        "rlenv serve --policy Runner1=heuristic"
    )
    with AgentVectorEnv(
        None,
        TAG,
        agents=CHASER,
        addresses=[server.address],
        others=dict.fromkeys(RUNNERS, run_away),
    ) as alone:
        assert alone.num_envs == 1
        observations, _ = alone.reset(seed=0)
        assert alone.step(np.zeros((1, 2), np.float32))[0].shape == (1, 10)


def test_others_may_name_a_class_for_all_its_agents() -> None:
    with AgentVectorEnv(1, TAG, agents=CHASER, others={Runner: run_away}, in_process=True) as alone:
        assert alone.driven_here == dict.fromkeys(RUNNERS, run_away)
        assert alone.driven_by_server == {}
        alone.reset(seed=0)
        assert alone.step(np.zeros((1, 2), np.float32))[0].shape == (1, 10)


def _batched_by_gymnasium(vector: RemoteVectorEnv, infos: dict) -> dict:
    """``infos`` batched again, one sub-environment at a time, by gymnasium's ``_add_info``."""
    batched: dict = {}
    for index in range(vector.num_envs):
        agents = {
            name: {
                key: column[index].item()
                for key, column in outcome.items()
                if not key.startswith("_")
            }
            for name, outcome in infos["agents"].items()
            if not name.startswith("_")
        }
        batched = vector._add_info(
            batched, {"agents": agents, "frames": int(infos["frames"][index])}, index
        )
    return batched


def _assert_same(ours: dict, theirs: dict) -> None:
    assert ours.keys() == theirs.keys()
    for key, value in ours.items():
        if isinstance(value, dict):
            _assert_same(value, theirs[key])
        else:
            assert value.dtype == theirs[key].dtype and np.array_equal(value, theirs[key]), key


def test_several_agents_outcomes_are_batched_in_columns_as_gymnasium_batches_them() -> None:
    with RemoteVectorEnv(3, TAG, in_process=True) as vector:
        vector.reset(seed=0)
        vector.action_space.seed(0)
        for _ in range(5):
            *_, infos = vector.step(vector.action_space.sample())
            _assert_same(infos, _batched_by_gymnasium(vector, infos))
