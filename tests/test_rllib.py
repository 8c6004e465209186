"""RLlib (new API stack) on rlenv vectors: the env creator, PPO, lost servers, no leftovers.

Every server these tests cause is found by an environment variable that the Ray cluster, its
EnvRunner actors and so their servers inherit; none may be left when a test ends.
"""

from __future__ import annotations

import os
import select
import signal
import time
import uuid
from collections.abc import Iterator
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("ray.rllib")
pytest.importorskip("torch")

import ray  # noqa: E402
from ray.rllib.algorithms.ppo import PPOConfig  # noqa: E402
from ray.rllib.env.env_context import EnvContext  # noqa: E402
from ray.tune.registry import ENV_CREATOR, _global_registry, register_env  # noqa: E402

from examples.cartpole import TARGET  # noqa: E402
from examples.tag import TARGET as TAG_TARGET  # noqa: E402
from rlenv_client import ConnectionLost, RemoteVectorEnv  # noqa: E402
from rlenv_client.registration import ENVIRONMENTS  # noqa: E402
from rlenv_client.rllib import RLlibEnvCreator, config_for, register  # noqa: E402
from rlenv_client.rllib_agents import (  # noqa: E402
    RemoteMultiAgentEnv,
    multi_agent_config_for,
    policy_per_agent,
)

pytestmark = pytest.mark.ray

TAG = "RLENV_RLLIB_TEST"


def tagged_servers(tag: str, command: bytes = b"rlenv\0serve") -> set[int]:
    """Pids of running processes whose command line holds ``command`` (by default: rlenv
    servers) and whose environment holds ``TAG=tag``."""
    wanted = f"{TAG}={tag}".encode()
    found = set()
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            with open(f"/proc/{entry}/cmdline", "rb") as file:
                if command not in file.read():
                    continue  # zombies have no command line
            with open(f"/proc/{entry}/environ", "rb") as file:
                if wanted in file.read().split(b"\0"):
                    found.add(int(entry))
        except OSError:
            continue
    return found


def wait_gone(pids: set[int], timeout: float = 30.0) -> None:
    """Wait (on pidfds, no sleeping) until every process in ``pids`` has exited."""
    deadline = time.monotonic() + timeout
    for pid in pids:
        try:
            descriptor = os.pidfd_open(pid)
        except ProcessLookupError:
            continue
        try:
            ready, _, _ = select.select([descriptor], [], [], max(0.0, deadline - time.monotonic()))
        finally:
            os.close(descriptor)
        assert ready, f"process {pid} still runs"


@pytest.fixture(scope="module")
def cluster() -> Iterator[str]:
    """A local Ray instance of 2 CPUs for this module; yields the tag of its processes."""
    tag = uuid.uuid4().hex
    os.environ[TAG] = tag  # inherited by Ray's processes and the servers they start
    ray.init(
        address="local",
        num_cpus=2,
        include_dashboard=False,
        log_to_driver=False,
        configure_logging=False,
    )
    try:
        yield tag
    finally:
        ray.shutdown()
        del os.environ[TAG]
        wait_gone(tagged_servers(tag, command=b""))  # Ray's processes too


@pytest.fixture
def no_leftovers(cluster: str) -> Iterator[str]:
    """Fails the test if it leaves a server running."""
    yield cluster
    wait_gone(tagged_servers(cluster))


def small_ppo(name: str, *, num_env_runners: int, num_envs: int, **env_config: Any) -> PPOConfig:
    """PPO with small batches (a training iteration takes about a second)."""
    return (
        PPOConfig()
        .environment(name, env_config=env_config)
        .env_runners(
            num_env_runners=num_env_runners,
            num_envs_per_env_runner=num_envs,
            gym_env_vectorize_mode=gym.VectorizeMode.VECTOR_ENTRY_POINT,
            rollout_fragment_length=50,
        )
        .training(train_batch_size_per_learner=50 * num_envs, minibatch_size=50, num_epochs=1)
        .fault_tolerance(restart_failed_sub_environments=True)
        .debugging(seed=0)
    )


def runner_servers(algo: Any) -> list[list[int]]:
    """Per remote EnvRunner: the pids of its vector's servers."""
    return algo.env_runner_group.foreach_env_runner(
        lambda runner: [server.pid for server in runner.env.unwrapped.servers],
        local_env_runner=False,
    )


# --- the creator ----------------------------------------------------------------------------


def test_creator_builds_from_what_rllib_passes(no_leftovers: str) -> None:
    name = register("rlenv/CartPole-v0")
    assert name == "rllib/rlenv/CartPole-v0"
    creator = _global_registry.get(ENV_CREATOR, name)  # as EnvRunners get it: unpickled
    assert isinstance(creator, RLlibEnvCreator)
    assert creator.target == ENVIRONMENTS["rlenv/CartPole-v0"].target
    context = EnvContext({"instances_per_server": 2}, worker_index=1, num_workers=1)
    config = context | {"num_envs": 4}  # what SingleAgentEnvRunner.make_env passes
    assert type(config) is dict and not hasattr(config, "worker_index")
    vector = creator(config)
    try:
        assert isinstance(vector, RemoteVectorEnv)
        assert vector.num_envs == 4 and len(vector.servers) == 2
        assert vector.max_episode_steps == 500  # the id's TimeLimit, which RLlib drops
        assert vector.metadata["autoreset_mode"] is gym.vector.AutoresetMode.NEXT_STEP
        observations, _ = vector.reset(seed=3)
        assert observations.shape == (4, 5)
        observations, rewards, *_ = vector.step(np.zeros((4, 1), np.float32))
        assert observations.shape == (4, 5) and rewards.tolist() == [4.0] * 4
        pids = {server.pid for server in vector.servers}
    finally:
        vector.close()
    assert not pids & tagged_servers(no_leftovers)  # closing the vector ended its servers

    plain = creator({"num_envs": 2, "in_process": True, "repeat_action": 2})  # no worker_index
    try:
        assert plain.num_envs == 2 and plain.servers == []
        plain.reset(seed=0)
        assert plain.step(np.zeros((2, 1), np.float32))[1].tolist() == [2.0, 2.0]
    finally:
        plain.close()


def test_creator_refuses_what_rllib_cannot_use(serve: Any) -> None:
    creator = RLlibEnvCreator(TARGET)
    with pytest.raises(ValueError, match=r"unknown key in the env config: bogus; valid keys"):
        creator({"num_envs": 2, "bogus": 1})
    with pytest.raises(ValueError, match="unknown keys in register"):
        register("rlenv/CartPole-v0", bogus=1, nope=2)
    with pytest.raises(ValueError, match="fixed by register"):
        creator({"num_envs": 2, "target": TARGET})
    with pytest.raises(ValueError, match="VECTOR_ENTRY_POINT"):  # SYNC mode: one env a call
        creator(EnvContext({}, worker_index=1))
    with pytest.raises(ValueError, match="NEXT_STEP"):
        creator({"num_envs": 2, "autoreset_mode": "SameStep"})
    with pytest.raises(ValueError, match="not an rlenv id"):
        register("CartPole-v1")
    server = serve(args=["--instances", "2"])
    with pytest.raises(
        ValueError, match="2 sub-environments and RLlib expects num_envs_per_env_runner=3"
    ):
        creator({"num_envs": 3, "addresses": [server.address]})
    with pytest.raises(ValueError, match="pool_servers is only for pool"):
        creator({"num_envs": 2, "pool_servers": 2})


# --- PPO on it --------------------------------------------------------------------------------


def test_ppo_trains_one_iteration_in_the_driver(no_leftovers: str) -> None:
    creator = RLlibEnvCreator(TARGET, max_episode_steps=500)

    def recording(config: dict) -> RemoteVectorEnv:  # runs on a copy: RLlib pickles creators
        vector = creator(config)
        vector.given = config  # type: ignore[attr-defined]
        return vector

    register_env("rlenv-recording", recording)
    algo = small_ppo(
        "rlenv-recording", num_env_runners=0, num_envs=4, instances_per_server=2
    ).build_algo()
    try:
        vector = algo.env_runner.env.unwrapped
        assert isinstance(vector, RemoteVectorEnv) and vector.num_envs == 4
        assert type(vector.given) is dict  # env_ctx | {"num_envs": 4}: no worker_index
        assert vector.given == {"instances_per_server": 2, "num_envs": 4}
        result = algo.train()
        assert result["env_runners"]["num_env_steps_sampled"] >= 200
        pids = {server.pid for server in vector.servers}
        assert pids <= tagged_servers(no_leftovers)
    finally:
        algo.stop()
    assert not pids & tagged_servers(no_leftovers)


def test_config_for_sets_what_the_creator_needs() -> None:
    config = config_for(
        PPOConfig(),
        "rlenv/CartPole-v0",
        num_envs_per_env_runner=3,
        num_env_runners=1,
        repeat_action=2,
    )
    assert config.env == "rllib/rlenv/CartPole-v0"
    assert config.gym_env_vectorize_mode is gym.VectorizeMode.VECTOR_ENTRY_POINT
    assert config.num_envs_per_env_runner == 3 and config.num_env_runners == 1
    assert config.restart_failed_sub_environments


# --- lost servers ------------------------------------------------------------------------------


def test_lost_server_makes_rllib_recreate_the_vector(no_leftovers: str) -> None:
    """max_restarts=0: ConnectionLost from step; RLlib closes the vector and builds another."""
    name = register(TARGET, name="rlenv-no-restarts", max_episode_steps=500)
    algo = small_ppo(
        name, num_env_runners=1, num_envs=2, instances_per_server=1, max_restarts=0
    ).build_algo()
    try:
        algo.train()
        [before] = runner_servers(algo)
        os.killpg(before[0], signal.SIGKILL)
        wait_gone({before[0]})
        result = algo.train()
        assert result["env_runners"]["num_env_step_failures"] == 1
        [after] = runner_servers(algo)
        assert len(after) == 2 and not set(after) & set(before)
        wait_gone(set(before))  # the other server of the old vector was closed too
        assert tagged_servers(no_leftovers) == set(after)
    finally:
        algo.stop()


def test_lost_server_is_restarted_by_the_vector(no_leftovers: str) -> None:
    """The default: the vector replaces its lost server; RLlib sees truncated episodes."""
    name = register(TARGET, name="rlenv-restarts", max_episode_steps=500)
    algo = small_ppo(name, num_env_runners=1, num_envs=2, instances_per_server=1).build_algo()
    try:
        algo.train()
        [before] = runner_servers(algo)
        os.killpg(before[0], signal.SIGKILL)
        wait_gone({before[0]})
        result = algo.train()
        assert result["env_runners"].get("num_env_step_failures", 0) == 0
        [after] = runner_servers(algo)
        assert after[1] == before[1] and after[0] != before[0]
        [restarts] = algo.env_runner_group.foreach_env_runner(
            lambda runner: [s.restarts for s in runner.env.unwrapped.sessions],
            local_env_runner=False,
        )
        assert restarts == [1, 0]
    finally:
        algo.stop()


def test_connection_lost_is_an_exception_rllib_catches(
    no_leftovers: str, caplog: pytest.LogCaptureFixture
) -> None:
    """A server lost more often than max_restarts: step raises ConnectionLost, which RLlib's
    EnvRunner._try_env_step catches (``except Exception``), then it builds the vector anew."""
    from ray.rllib.env.env_runner import ENV_STEP_FAILURE
    from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

    name = register(TARGET, name="rlenv-one-restart", max_episode_steps=500)
    runner = SingleAgentEnvRunner(
        config=small_ppo(name, num_env_runners=0, num_envs=1, max_restarts=1)
    )
    try:
        runner.sample(num_timesteps=20, random_actions=True)
        actions = np.zeros((1, 1), np.float32)
        vector = runner.env.unwrapped
        lost = vector.servers[0].pid
        os.killpg(lost, signal.SIGKILL)  # within the budget: the vector restarts it
        wait_gone({lost})
        *_, truncated, infos = runner._try_env_step(actions)
        assert truncated.tolist() == [True] and "server_restarted" in infos[0]
        assert runner.env.unwrapped is vector
        lost = vector.servers[0].pid
        os.killpg(lost, signal.SIGKILL)  # past it: ConnectionLost, and RLlib catches it
        wait_gone({lost})
        with caplog.at_level("ERROR"):
            assert runner._try_env_step(actions) == ENV_STEP_FAILURE
        [failure] = [record for record in caplog.records if record.exc_info]
        assert failure.exc_info is not None and failure.exc_info[0] is ConnectionLost
        assert f"(pid {lost}) exited with code -9" in str(failure.exc_info[1])  # which, how
        fresh = runner.env.unwrapped
        assert fresh is not vector and vector.closed
        assert tagged_servers(no_leftovers) == {server.pid for server in fresh.servers}
        runner.sample(num_timesteps=20, random_actions=True)  # and sampling goes on
    finally:
        runner.stop()


# --- servers leased from a pool ------------------------------------------------------------


@pytest.fixture
def pool(no_leftovers: str) -> Iterator[Any]:
    """A named pool of one server of two CartPoles."""
    from rlenv_client.ray import RayServerPool

    with RayServerPool(
        TARGET,
        servers=1,
        instances_per_server=2,
        cpus_per_server=0.5,
        name="rllib-test-pool",
        progress=lambda _: None,
    ) as servers:
        yield servers


def lease_is_free() -> bool:
    """Whether the test pool's server can be leased (then gives it back)."""
    from rlenv_client.ray import RayServerPool

    try:
        RayServerPool.lease("rllib-test-pool", servers=1).release()
    except ValueError:
        return False
    return True


def test_pool_creator_refuses_and_gives_back(pool: Any) -> None:
    creator = RLlibEnvCreator(TARGET, pool="rllib-test-pool")
    with pytest.raises(ValueError, match="instances_per_server cannot be used with pool"):
        creator({"num_envs": 2, "instances_per_server": 2})
    with pytest.raises(
        ValueError, match="pool_servers=1 gives 2, and RLlib expects num_envs_per_env_runner=4"
    ):
        creator({"num_envs": 4})
    assert lease_is_free()
    vector = creator({"num_envs": 2})
    try:
        assert not lease_is_free()
        vector.reset(seed=0)
        assert vector.step(np.zeros((2, 1), np.float32))[0].shape == (2, 5)
    finally:
        vector.close()
    assert lease_is_free()


def test_ppo_on_leased_servers_recovers_a_lost_one(pool: Any) -> None:
    """max_restarts=0: ServerLost; RLlib closes the vector (its lease goes back) and the
    creator leases the pool's only server again, which its actor has restarted."""
    name = register(
        "rlenv/CartPole-v0", name="rlenv-pooled", pool="rllib-test-pool", max_restarts=0
    )
    algo = small_ppo(name, num_env_runners=1, num_envs=2).build_algo()
    try:
        algo.train()
        assert not lease_is_free()
        pid = ray.get(pool.actor(0).server_pid.remote())
        os.kill(pid, signal.SIGKILL)
        wait_gone({pid})
        result = algo.train()
        assert result["env_runners"]["num_env_step_failures"] == 1
        assert ray.get(pool.actor(0).server_pid.remote()) != pid
    finally:
        algo.stop()
    assert lease_is_free()


# --- several agents: a MultiAgentEnv, a policy per class ---------------------------------------


def test_two_policies_train_the_chaser_and_the_runners_of_tag(no_leftovers: str) -> None:
    config = multi_agent_config_for(
        PPOConfig(), TAG_TARGET, per="class", num_env_runners=1, max_episode_steps=100
    )
    config = (
        config.env_runners(rollout_fragment_length=100)
        .training(train_batch_size_per_learner=200, minibatch_size=50, num_epochs=1)
        .debugging(seed=0)
    )
    assert config.policies.keys() == {"Chaser", "Runner"}
    mapping = config.policy_mapping_fn
    assert [mapping(name, None) for name in ("Chaser", "Runner1", "Runner2")] == [
        "Chaser",
        "Runner",
        "Runner",
    ]
    algo = config.build_algo()
    try:
        before = algo.learner_group.get_weights()
        for _ in range(2):
            result = algo.train()
        after = algo.learner_group.get_weights()
        runners = result["env_runners"]
        assert set(runners["module_episode_returns_mean"]) == {"Chaser", "Runner"}
        assert set(runners["agent_episode_returns_mean"]) == {"Chaser", "Runner1", "Runner2"}
        assert {"Chaser", "Runner"} <= set(result["learners"])
        for module in ("Chaser", "Runner"):  # each policy learned from its own agents
            assert any(
                not np.array_equal(np.asarray(after[module][key]), np.asarray(before[module][key]))
                for key in before[module]
            ), module
        servers = algo.env_runner_group.foreach_env_runner(
            lambda runner: [env.unwrapped.session.server.pid for env in runner.env.envs],
            local_env_runner=False,
        )
        assert servers and all(servers)
    finally:
        algo.stop()


def test_the_server_drives_what_rllib_does_not_train(no_leftovers: str) -> None:
    env = RemoteMultiAgentEnv(
        TAG_TARGET, others={"Runner1": "heuristic", "Runner2": "heuristic"}, max_episode_steps=5
    )
    try:
        assert env.possible_agents == ["Chaser"] and env.driven == ("Runner1", "Runner2")
        observations, _ = env.reset(seed=0)
        assert list(observations) == ["Chaser"]
        for _ in range(5):
            observations, rewards, terminateds, truncateds, _ = env.step(
                {"Chaser": np.zeros(2, np.float32)}
            )
        assert truncateds == {"Chaser": True, "__all__": True}
        assert terminateds == {"Chaser": False, "__all__": False}
    finally:
        env.close()


# --- agents that come and go: RLlib's own convention -----------------------------------------


COME_AND_GO = "come_and_go_envs:ComeAndGoEnvironment"
PACED = "come_and_go_envs:PacedEnvironment"
HUNT = "examples.hunt:HuntEnvironment"


@pytest.fixture
def come_and_go_tests(monkeypatch: pytest.MonkeyPatch) -> None:
    """``tests/come_and_go_envs.py`` importable here and in the servers started."""
    tests = os.path.dirname(__file__)
    monkeypatch.syspath_prepend(tests)
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join(filter(None, [tests, os.environ.get("PYTHONPATH")]))
    )


def test_agents_come_and_go_in_rllibs_dicts(come_and_go_tests: None) -> None:
    env = RemoteMultiAgentEnv(COME_AND_GO)
    try:
        assert env.possible_agents == ["A", "B", "C", "D"]
        observations, infos = env.reset(seed=0)
        assert sorted(observations) == sorted(infos) == env.agents == ["A", "B"]
        steps = []
        while True:
            step = env.step(dict.fromkeys(observations, 2))
            observations = step[0]
            steps.append(step)
            if step[2]["__all__"] or step[3]["__all__"]:
                break
        assert [sorted(step[0]) for step in steps] == [
            ["A", "B"],
            ["A", "B", "C"],  # C joined at tick 6
            ["A", "B", "C"],  # B freed at 10: its final observation
            ["A", "C"],
            ["A", "C"],  # A terminated at 20
            ["C"],
            ["C"],
            ["C"],  # truncated at 30
        ]
        observations, rewards, terminateds, truncateds, _ = steps[1]  # C joins: reward 0.0
        assert rewards == {"A": 4.0, "B": 4.0, "C": 0.0}
        assert observations["C"].tolist() == [0.0, 8.0]
        observations, rewards, terminateds, truncateds, _ = steps[2]  # B leaves, once
        assert terminateds == {"A": False, "B": True, "C": False, "__all__": False}
        assert observations["B"].tolist() == [10.0, 10.0] and rewards["B"] == 2.0
        _, _, terminateds, truncateds, _ = steps[-1]
        assert terminateds == {"C": False, "__all__": False}
        assert truncateds == {"C": True, "__all__": True} and env.agents == []
    finally:
        env.close()


def test_only_agents_that_act_now_are_in_rllibs_dicts(come_and_go_tests: None) -> None:
    env = RemoteMultiAgentEnv(PACED, max_episode_steps=4)
    try:
        observations, _ = env.reset(seed=0)
        observations, rewards, terminateds, truncateds, _ = env.step(dict.fromkeys(observations, 2))
        assert sorted(observations) == sorted(rewards) == ["Fast", "Plain"]
        with pytest.raises(ValueError, match="no action for agent 'Plain', which acts now"):
            env.step({"Fast": 2})
        cannot_travel = object()  # sent, it would raise TypeError
        observations, *_ = env.step({"Fast": 2, "Plain": 2, "Slow": cannot_travel})
        assert sorted(observations) == ["Plain", "Slow"]
        observations, *_ = env.step(dict.fromkeys(observations, 2))
        assert sorted(observations) == ["Fast", "Jerky", "Plain"]
        observations, rewards, terminateds, truncateds, _ = env.step(dict.fromkeys(observations, 2))
        # cut by max_episode_steps: every agent in play gets its last observation, truncated
        assert sorted(observations) == ["Fast", "Jerky", "Plain", "Slow"]
        assert truncateds == {**dict.fromkeys(observations, True), "__all__": True}
        assert terminateds["__all__"] is False and env.agents == []
        assert rewards["Slow"] == 0.0  # not due at tick 6: its reward waits for its decision
    finally:
        env.close()


def test_ppo_trains_a_policy_per_class_on_the_hunt(no_leftovers: str) -> None:
    config = multi_agent_config_for(
        PPOConfig(), HUNT, per="class", num_env_runners=0, max_episode_steps=60
    )
    config = (
        config.env_runners(rollout_fragment_length=100)
        .training(train_batch_size_per_learner=200, minibatch_size=50, num_epochs=1)
        .debugging(seed=0)
    )
    assert config.policies.keys() == {"Hunter", "Prey"}
    algo = config.build_algo()
    try:
        result = algo.train()
        agents = set(result["env_runners"]["agent_episode_returns_mean"])
        assert "Hunter" in agents and {"Prey1", "Prey2"} <= agents
        assert {"Hunter", "Prey"} <= set(result["learners"])
    finally:
        algo.stop()


# --- a group of agents: its members are RLlib's agents, with one policy ------------------------


SWARM_MIXED = "swarm_envs:MixedEnvironment"
DISCS = [f"Discs_{i}" for i in range(8)]


def test_a_groups_members_are_agents_in_rllibs_dicts(come_and_go_tests: None) -> None:
    env = RemoteMultiAgentEnv(SWARM_MIXED, max_episode_steps=4)
    try:
        assert env.possible_agents == [*DISCS, "Shepherd"]
        assert env.observation_spaces["Discs_7"] == gym.spaces.Box(-50.0, 50.0, (4,), np.float32)
        observations, _ = env.reset(seed=0)
        assert list(observations) == env.agents == [*DISCS[:6], "Shepherd"]  # 6 start
        steps = []
        for _ in range(4):
            actions = {name: np.zeros(2, np.float32) for name in observations}
            steps.append(env.step(actions))
            observations = steps[-1][0]
        observations, rewards, terminateds, truncateds, _ = steps[2]  # tick 12: Discs_6 joined
        assert list(observations) == [*DISCS[:7], "Shepherd"] and rewards["Discs_6"] == 0.0
        assert rewards["Shepherd"] == pytest.approx(0.4)
        observations, rewards, terminateds, truncateds, _ = steps[3]  # cut by the time limit
        assert truncateds == {**dict.fromkeys([*DISCS[:7], "Shepherd"], True), "__all__": True}
        assert env.agents == []
    finally:
        env.close()


def test_ppo_trains_one_policy_for_a_group_beside_the_shepherds(
    no_leftovers: str, come_and_go_tests: None
) -> None:
    config = multi_agent_config_for(
        PPOConfig(), SWARM_MIXED, per="class", num_env_runners=0, max_episode_steps=30
    )
    config = (
        config.env_runners(rollout_fragment_length=60)
        .training(train_batch_size_per_learner=240, minibatch_size=60, num_epochs=1)
        .debugging(seed=0)
    )
    assert config.policies.keys() == {"Discs", "Shepherd"}
    mapping = config.policy_mapping_fn
    assert {mapping(name, None) for name in DISCS} == {"Discs"}
    assert policy_per_agent(SWARM_MIXED).policies == {**dict.fromkeys(DISCS, "Discs"),
                                                      "Shepherd": "Shepherd"}  # fmt: skip
    algo = config.build_algo()
    try:
        result = algo.train()
        assert set(result["env_runners"]["module_episode_returns_mean"]) == {"Discs", "Shepherd"}
        assert {"Discs_0", "Discs_6", "Shepherd"} <= set(
            result["env_runners"]["agent_episode_returns_mean"]
        )
        assert {"Discs", "Shepherd"} <= set(result["learners"])
    finally:
        algo.stop()
