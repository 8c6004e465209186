"""RLAgent.heuristic and the agents a server drives (``rlenv serve --policy NAME=heuristic``)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from examples.pair import PairAgent, chase
from rlenv import RLAgent
from rlenv.protocol.errors import RemoteError
from rlenv_client import Client, LocalClient

CHASING_PAIR = "heuristic_envs:ChasingPair"
SEEKER = "heuristic_envs:HeuristicSeeker"
PAIR = "examples.pair:PairEnvironment"
HERE_TOO = {
    "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")])
}
"""A server's environment that finds heuristic_envs."""


def test_an_agent_class_has_a_heuristic_only_if_it_defines_one() -> None:
    from heuristic_envs import ChasingPairAgent, HeuristicSeekerAgent

    assert not RLAgent.has_heuristic() and not PairAgent.has_heuristic()
    assert ChasingPairAgent.has_heuristic() and HeuristicSeekerAgent.has_heuristic()
    assert ChasingPairAgent("Blue").has_heuristic()  # on an agent too
    with pytest.raises(NotImplementedError, match="PairAgent has no heuristic"):
        PairAgent("Red").heuristic(np.zeros(8, np.float32))


def test_a_heuristic_plays_one_agent_as_if_its_actions_were_sent(serve) -> None:
    """The learner sends Red's actions; Blue's are its heuristic's, on Blue's observation."""
    rng = np.random.default_rng(0)
    reds = [rng.uniform(-1, 1, 2).astype(np.float32) for _ in range(40)]
    driven = serve(CHASING_PAIR, args=["--policy", "Blue=heuristic"], env=HERE_TOO)
    plain = serve(PAIR)
    with (
        Client(driven.host, driven.port, timeout=10) as learner,
        Client(plain.host, plain.port, timeout=10) as both,
    ):
        assert learner.hello.driven == ("Blue",) and both.hello.driven == ()
        observation, _ = learner.reset(seed=5)
        mirrored, _ = both.reset(seed=5)
        for red in reds:
            observation, reward, *_ = learner.step({"Red": red})
            mirrored, mirrored_reward, *_ = both.step({"Red": red, "Blue": chase(mirrored["Blue"])})
            for name in ("Red", "Blue"):
                np.testing.assert_array_equal(observation[name], mirrored[name])
            assert reward == mirrored_reward
        assert np.abs(observation["Blue"][:2] - mirrored["Blue"][:2]).sum() == 0.0


def _serve_refused(*args: str) -> str:
    """The one line ``rlenv serve ARGS`` exits 2 with (it finds heuristic_envs)."""
    result = subprocess.run(
        [sys.executable, "-m", "rlenv", "serve", *args],
        timeout=120,
        capture_output=True,
        text=True,
        stdin=subprocess.DEVNULL,
        env={**os.environ, **HERE_TOO},
    )
    assert result.returncode == 2, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    return lines[0]


def test_a_heuristic_for_an_agent_without_one_is_refused_at_start_naming_its_class() -> None:
    line = _serve_refused(PAIR, "--policy", "Red=heuristic")
    assert line == (
        "rlenv serve: --policy Red=heuristic: agent 'Red' (class PairAgent) has "
        "no heuristic; define PairAgent.heuristic(observation)"
    )
    with pytest.raises(ValueError, match=r"agent 'Red' \(class PairAgent\) has no heuristic"):
        LocalClient(CHASING_PAIR, policies={"Blue": "heuristic", "Red": "heuristic"})
    with pytest.raises(
        ValueError, match="the environment has no agent 'Green'; its agents: Red, Blue"
    ):
        LocalClient(CHASING_PAIR, policies={"Green": "heuristic"})


def test_a_heuristic_plays_a_single_agent_environment_by_itself(serve) -> None:
    server = serve(
        SEEKER, args=["--policy", "Agent=heuristic", "--max-episode-steps", "200"], env=HERE_TOO
    )
    with Client(server.host, server.port, timeout=10) as observer:
        assert observer.hello.driven == ("Agent",)
        deadline = time.monotonic() + 60
        while (stats := observer.stats())["next"] < 3:
            assert time.monotonic() < deadline, f"only {stats['next']} episodes in 60 s"
        caught = [e for e in stats["episodes"] if e["end"] == "terminated"]
        assert caught and all(e["return"] > 0 for e in caught)  # the greedy push gets apples
        with pytest.raises(RemoteError, match="driven by policies"):
            observer.reset(seed=1)


def test_in_process_a_heuristic_drives_its_agent_and_replays_exactly() -> None:
    with LocalClient(CHASING_PAIR, policies={"Blue": "heuristic"}) as learner:
        assert learner.hello.driven == ("Blue",)
        observation, _ = learner.reset(seed=3)
        before = observation["Blue"]
        for _ in range(5):
            observation, *_ = learner.step({"Red": np.zeros(2, np.float32)})
        assert not np.array_equal(observation["Blue"], before)  # Blue moved by itself
        snapshot = learner.snapshot()
        with LocalClient(PAIR) as replayer:  # no heuristic there: the log holds Blue's actions
            replayed, _ = replayer.restore(snapshot)
        np.testing.assert_array_equal(replayed["Blue"], observation["Blue"])
        np.testing.assert_array_equal(replayed["Red"], observation["Red"])


def test_a_heuristic_answering_outside_its_space_is_an_environment_error_naming_it() -> None:
    with LocalClient("heuristic_envs:WrongHeuristicPair", policies={"Blue": "heuristic"}) as env:
        env.reset(seed=0)
        with pytest.raises(
            RemoteError,
            match=r"WrongPairAgent.heuristic of agent 'Blue' gave "
            r"array\(\[0., 0., 0.\]",
        ):
            env.step({"Red": np.zeros(2, np.float32)})
        env.reset(seed=0)  # the server goes on


def test_every_agent_driven_is_refused_in_process() -> None:
    with pytest.raises(ValueError, match="policies drive every agent"):
        LocalClient(SEEKER, policies={"Agent": "heuristic"})


# --- the trainer's view: driven agents left out -----------------------------------------------


def test_remote_env_leaves_the_driven_agent_out_of_its_spaces_actions_and_rewards(serve) -> None:
    from gymnasium.utils.env_checker import check_env

    from rlenv_client import RemoteEnv

    server = serve(CHASING_PAIR, args=["--policy", "Blue=heuristic"], env=HERE_TOO)
    env = RemoteEnv(address=f"{server.host}:{server.port}")
    try:
        assert list(env.action_space.keys()) == ["Red"]
        assert list(env.observation_space.keys()) == ["Red"]
        observation, _ = env.reset(seed=2)
        assert list(observation) == ["Red"] and observation in env.observation_space
        with pytest.raises(
            ValueError, match="agent 'Blue' is driven by the server .* act for Red only"
        ):
            env.step({"Red": np.zeros(2, np.float32), "Blue": np.zeros(2, np.float32)})
        terminated = truncated = False
        steps = 0
        while not (terminated or truncated):
            observation, reward, terminated, truncated, info = env.step(
                {"Red": chase(observation["Red"])}
            )
            assert list(observation) == ["Red"]
            assert reward == pytest.approx(info["agents"]["Red"]["reward"])
            assert set(info["agents"]) == {"Red", "Blue"}  # the server's report, whole
            steps += 1
            assert steps < 500, "greedy Red never caught its apple"
        assert terminated and not truncated and info["agents"]["Red"]["terminated"]
        check_env(env.unwrapped, skip_render_check=True)
    finally:
        env.close()


def test_a_parallel_env_lists_only_the_agents_it_acts_for(serve) -> None:
    from pettingzoo.test import parallel_api_test

    from rlenv_client.pettingzoo import RemoteParallelEnv

    server = serve(CHASING_PAIR, args=["--policy", "Blue=heuristic"], env=HERE_TOO)
    env = RemoteParallelEnv(address=f"{server.host}:{server.port}", max_cycles=30)
    try:
        assert env.possible_agents == ["Red"]
        observations, infos = env.reset(seed=1)
        assert env.agents == ["Red"] and list(observations) == ["Red"] and list(infos) == ["Red"]
        assert list(env.action_spaces) == list(env.observation_spaces) == ["Red"]
        with pytest.raises(ValueError, match="agent 'Blue' is driven by the server"):
            env.step({"Red": np.zeros(2, np.float32), "Blue": np.zeros(2, np.float32)})
        observations, rewards, terminations, truncations, _ = env.step(
            {"Red": np.zeros(2, np.float32)}
        )  # no action for Blue is needed
        assert list(observations) == list(rewards) == list(terminations) == ["Red"]
        parallel_api_test(env, num_cycles=30)
    finally:
        env.close()


def test_a_server_driving_every_agent_leaves_a_trainer_nothing_and_says_so(serve) -> None:
    from rlenv_client import RemoteEnv

    server = serve(SEEKER, args=["--policy", "Agent=heuristic"], env=HERE_TOO)
    with pytest.raises(
        ValueError,
        match=r"the server drives every agent of Seeker \(Agent; "
        r"rlenv serve --policy\): there is nothing to act for",
    ):
        RemoteEnv(address=f"{server.host}:{server.port}")


def test_a_vector_env_steps_only_the_trainers_agents_of_several_instances(serve) -> None:
    """Two instances, Blue driven: Red's view matches a plain vector whose Blue we push."""
    from rlenv_client import RemoteVectorEnv

    driven = serve(
        CHASING_PAIR, args=["--instances", "2", "--policy", "Blue=heuristic"], env=HERE_TOO
    )
    plain = serve(PAIR, args=["--instances", "2"])
    vector = RemoteVectorEnv(addresses=[f"{driven.host}:{driven.port}"])
    mirror = RemoteVectorEnv(addresses=[f"{plain.host}:{plain.port}"])
    try:
        assert list(vector.single_action_space) == list(vector.single_observation_space) == ["Red"]
        observations, _ = vector.reset(seed=[4, 9])
        mirrored, _ = mirror.reset(seed=[4, 9])
        with pytest.raises(ValueError, match="agent 'Blue' is driven by the server"):
            vector.step({"Red": np.zeros((2, 2), np.float32), "Blue": np.zeros((2, 2), np.float32)})
        for _ in range(300):  # until Red catches its apple somewhere (then autoresets differ)
            reds = np.stack([chase(row) for row in observations["Red"]])
            blues = np.stack([chase(row) for row in mirrored["Blue"]])
            observations, rewards, terminations, truncations, _ = vector.step({"Red": reds})
            mirrored, _, _, _, infos = mirror.step({"Red": reds, "Blue": blues})
            assert list(observations) == ["Red"]
            np.testing.assert_array_equal(observations["Red"], mirrored["Red"])
            red = infos["agents"]["Red"]  # the mirror's Red alone, not both agents' sum
            np.testing.assert_allclose(rewards, red["reward"])
            np.testing.assert_array_equal(terminations, red["terminated"])
            assert not truncations.any()
            if terminations.any():
                break
        else:
            raise AssertionError("greedy Red never caught its apple")
    finally:
        vector.close()
        mirror.close()


# --- gym.make(..., server_args=["--policy", ...]): the shared per-client server ---------------


def test_environments_sharing_a_server_each_drive_their_own_agent(monkeypatch) -> None:
    from rlenv_client import RemoteEnv

    monkeypatch.setenv("PYTHONPATH", HERE_TOO["PYTHONPATH"])
    args = ["--policy", "Blue=heuristic"]
    first, second = (
        RemoteEnv(CHASING_PAIR, server_args=args),
        RemoteEnv(CHASING_PAIR, server_args=args),
    )
    try:
        assert first.server is second.server  # one --per-client server, two environments
        assert list(first.action_space) == list(second.action_space) == ["Red"]
        one, _ = first.reset(seed=7)
        other, _ = second.reset(seed=7)
        for _ in range(10):  # the same seed and actions: the same episode in each
            one, *_ = first.step({"Red": chase(one["Red"])})
            other, *_ = second.step({"Red": chase(other["Red"])})
            np.testing.assert_array_equal(one["Red"], other["Red"])
        with Client(first.server.host, first.server.port, timeout=10) as third:
            assert third.hello.driven == ("Blue",)
            observation, _ = third.reset(seed=7)
            third.step({"Red": chase(observation["Red"])})
            blue_moved = third.step({"Red": np.zeros(2, np.float32)})[0]["Blue"]
            assert np.abs(blue_moved[2:4]).sum() > 0  # its own Blue, pushed by the heuristic
    finally:
        first.close()
        second.close()


def test_gym_make_passes_policy_to_the_shared_server_which_checks_it() -> None:
    import gymnasium

    from rlenv_client.launcher import ServerStartError

    with pytest.raises(
        ServerStartError,
        match=r"agent 'Red' \(class PairAgent\) has no "
        r"heuristic",
    ):
        gymnasium.make("rlenv/Pair-v0", server_args=["--policy", "Red=heuristic"])


def test_a_per_client_server_driving_every_agent_is_refused_at_start() -> None:
    line = _serve_refused(
        "examples.seeker:SeekerEnvironment", "--per-client", "--policy", "Agent=heuristic"
    )
    assert "has no heuristic" in line  # the seeker's agent has none: checked first
    line = _serve_refused(SEEKER, "--per-client", "--policy", "Agent=heuristic")
    assert line == (
        "rlenv serve: --policy drives every agent, so the server plays its "
        "episodes itself and no client controls them: leave out --per-client, or "
        "drive fewer agents"
    )


# --- examples.tag: one chaser, two runners, each class with a heuristic -----------------------

RUNNERS_DRIVEN = ["--policy", "Runner1=heuristic", "--policy", "Runner2=heuristic"]


def test_gym_make_trains_the_chaser_against_the_runners_heuristics() -> None:
    import gymnasium

    from examples.tag import Chaser

    chaser = Chaser()  # its heuristic is a function of the observation: here the learner's
    env = gymnasium.make("rlenv/Tag-v0", server_args=RUNNERS_DRIVEN)
    try:
        assert list(env.action_space) == list(env.observation_space) == ["Chaser"]
        assert env.unwrapped.client.hello.driven == ("Runner1", "Runner2")
        observation, _ = env.reset(seed=0)
        runners, terminated, truncated = 0.0, False, False
        while not (terminated or truncated):
            observation, reward, terminated, truncated, info = env.step(
                {"Chaser": chaser.heuristic(observation["Chaser"])}
            )
            assert list(observation) == ["Chaser"]
            assert reward == pytest.approx(info["agents"]["Chaser"]["reward"])
            runners += info["agents"]["Runner1"]["reward"] + info["agents"]["Runner2"]["reward"]
        assert terminated == info["agents"]["Chaser"]["terminated"]  # both runners tagged
        assert runners != 0.0  # the runners played, on the server
    finally:
        env.close()


def test_a_parallel_env_of_tag_lists_the_runners_when_the_chaser_is_driven(serve) -> None:
    from pettingzoo.test import parallel_api_test

    from rlenv_client.pettingzoo import RemoteParallelEnv

    server = serve("examples.tag:TagEnvironment", args=["--policy", "Chaser=heuristic"])
    env = RemoteParallelEnv(address=f"{server.host}:{server.port}", max_cycles=50)
    try:
        assert env.possible_agents == ["Runner1", "Runner2"]
        parallel_api_test(env, num_cycles=50)
    finally:
        env.close()


def test_make_vec_starts_servers_that_drive_the_runners() -> None:
    import gymnasium

    from examples.tag import Chaser

    chaser = Chaser()
    vector = gymnasium.make_vec(
        "rlenv/Tag-v0",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        server_args=RUNNERS_DRIVEN,
        instances_per_server=1,
    )
    try:
        assert list(vector.single_action_space) == ["Chaser"]
        observations, _ = vector.reset(seed=3)
        for _ in range(5):
            actions = np.stack([chaser.heuristic(row) for row in observations["Chaser"]])
            observations, rewards, *_, infos = vector.step({"Chaser": actions})
            np.testing.assert_allclose(rewards, infos["agents"]["Chaser"]["reward"])
        assert list(observations) == ["Chaser"]
    finally:
        vector.close()
