"""Timelines: recorded episodes re-simulated step by step, tick by tick, branched and compared."""

from __future__ import annotations

import random
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conftest import Serve, alive

import rlenv_client  # noqa: F401  (registers the ids)
from examples.cartpole import TARGET as CARTPOLE
from examples.cartpole import controller
from examples.plinko import TARGET as PLINKO
from examples.plinko import follow
from rlenv.protocol.errors import RemoteError
from rlenv_client import Client
from rlenv_client.launcher import ServerStartError
from rlenv_client.replay import EpisodeFile, RecordEpisodes, digest, replay
from rlenv_tools.timeline import Timeline

IDS = {CARTPOLE: "rlenv/CartPole-v0", PLINKO: "rlenv/Plinko-v0"}


def record(directory: Path, target: str) -> Path:
    """One episode of ``target`` under a noisy controller, recorded in ``directory``."""
    env = RecordEpisodes(gym.make(IDS[target], repeat_action=2, share_server=False), directory)
    policy = controller if target == CARTPOLE else follow
    try:
        observation, _ = env.reset(seed=11)
        for t in range(1000):
            noise = 0.3 * np.sin(t / 3.0)
            action = np.clip(policy(observation) + noise, -1, 1).astype(np.float32)
            observation, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
    finally:
        env.close()
    return directory / "episode-0001.rlenv"


def actions(episode: EpisodeFile) -> list[np.ndarray]:
    return [event[1] for event in episode.snapshot["events"] if event[0] == "action"]


@pytest.mark.parametrize("target", [CARTPOLE, PLINKO])
def test_every_step_is_the_recorded_one_in_any_order(tmp_path: Path, target: str) -> None:
    path = record(tmp_path, target)
    episode = EpisodeFile.load(path)
    with Timeline.open(path, checkpoint_every=10) as timeline:
        last = len(timeline)
        assert last == len(episode.observations) - 1 > 25
        steps = [0, last, 1, 9, 10, 11, 20, 19, last // 2, last - 1, 3, 25, 0, last]
        random.Random(5).shuffle(steps)
        for step in steps:  # backwards (misses), forwards (hits and stepping on), repeats
            state = timeline.at(step)
            assert state.step == step
            assert digest(state.observation) == episode.observations[step], step
        start = timeline.at(0)
        assert start.reward == 0.0 and start.info["frames"] == 0
        assert len(timeline.rewards) == last + 1
        for step in (0, 1, last // 2, last):
            assert timeline.rewards[step] == timeline.at(step).reward
        assert not (start.terminated or start.truncated)
        end = timeline.at(last)
        assert (end.terminated, end.truncated) == (episode.terminated, episode.truncated)
        assert end.draw["shapes"]
        agent = next(path for path in end.properties if path.endswith("/Agent"))
        assert end.properties[agent] == timeline.at(1).properties[agent]


@pytest.mark.parametrize("target", [CARTPOLE, PLINKO])
def test_the_ticks_of_a_step_add_up_to_the_step(tmp_path: Path, target: str) -> None:
    path = record(tmp_path, target)
    with Timeline.open(path) as timeline:
        for step in (1, 7, len(timeline)):
            state = timeline.at(step)
            ticks = timeline.ticks(step)
            assert [tick.tick for tick in ticks] == list(range(1, state.info["frames"] + 1))
            assert digest(ticks[-1].observation) == digest(state.observation)
            assert sum(tick.reward for tick in ticks) == pytest.approx(state.reward)
            assert ticks[-1].properties == state.properties
            assert ticks[-1].draw == state.draw and ticks[0].draw["shapes"]
            assert (ticks[-1].terminated, ticks[-1].truncated) == (
                state.terminated,
                state.truncated,
            )
            assert not any(tick.terminated or tick.truncated for tick in ticks[:-1])
        assert digest(timeline.at(8).observation) == timeline.episode.observations[8]
        with pytest.raises(IndexError):
            timeline.ticks(0)


def test_branches_share_their_start_and_end_with_the_episode(tmp_path: Path) -> None:
    path = record(tmp_path, CARTPOLE)
    episode = EpisodeFile.load(path)
    recorded = actions(episode)
    with Timeline.open(path, checkpoint_every=4) as timeline:
        same = timeline.branch(5, recorded[5:])
        assert len(same) == len(timeline)
        assert timeline.diff(same).first_difference is None

        changed = [recorded[5] * -1 + np.float32(0.5), *recorded[6:]]
        other = timeline.branch(5, changed)
        difference = timeline.diff(other)
        assert difference.first_difference is not None and difference.first_difference >= 6
        assert not any(np.any(d) for d in difference.observations[:6])
        assert difference.rewards[:6] == [0.0] * 6
        assert np.any(difference.observations[difference.first_difference])
        for step in (0, 5, 3):
            assert digest(other.at(step).observation) == episode.observations[step]

        short = timeline.branch(5, recorded[5:8])
        assert len(short) == 8 and not short.ended
        assert timeline.diff(short).first_difference == 9  # only one of them reaches it

        push = [np.ones(1, np.float32)] * 1000
        falls = timeline.branch(2, push)
        assert len(falls) < 2 + 1000 and falls.episode.terminated
        steered = timeline.branch(
            2, policy=lambda observation: np.ones(1, np.float32), max_steps=1000
        )
        assert timeline.diff(steered).first_difference is not None
        assert falls.diff(steered).first_difference is None  # the same actions, by policy

        deeper = falls.branch(len(falls) - 1, policy=lambda o: -np.ones(1, np.float32), max_steps=3)
        assert len(deeper) <= len(falls) + 2
        assert falls.diff(deeper).first_difference == len(falls)
        assert len(timeline.branch(len(timeline), push)) == len(timeline)  # it had ended


def test_a_policy_branch_stops_at_max_steps(tmp_path: Path) -> None:
    path = record(tmp_path, PLINKO)
    with Timeline.open(path) as timeline:
        branch = timeline.branch(4, policy=follow, max_steps=3)
        assert len(branch) == 7
        chosen = actions(branch.episode)
        for step in range(4, 7):  # the action from each state is the policy's of it
            assert np.array_equal(chosen[step], follow(branch.at(step).observation))
        with pytest.raises(ValueError):
            timeline.branch(4, policy=follow)
        with pytest.raises(ValueError):
            timeline.branch(4)


def test_a_saved_branch_replays_bit_for_bit(tmp_path: Path, serve: Serve) -> None:
    path = record(tmp_path, CARTPOLE)
    with Timeline.open(path) as timeline:
        branch = timeline.branch(3, policy=controller, max_steps=40)
        branch.save(tmp_path / "branch.rlenv")
        length = len(branch)
    saved = EpisodeFile.load(tmp_path / "branch.rlenv")
    server = serve(CARTPOLE)
    with Client(server.host, server.port, timeout=30) as client:
        result = replay(saved, client)
    assert result.divergence is None and result.steps == length


def test_closing_ends_every_process(tmp_path: Path) -> None:
    path = record(tmp_path, CARTPOLE)
    timeline = Timeline.open(path, checkpoint_every=5)
    branch = timeline.branch(2, policy=controller, max_steps=12)
    branch.close()  # a branch leaves the processes to its root
    processes = timeline.processes
    assert len(processes) >= 2 + len(timeline) // 5 and branch.processes == processes
    assert all(alive(pid) for pid in processes)
    assert len(timeline.at(3).observation) > 0
    timeline.close()
    assert not any(alive(pid) for pid in processes)
    with pytest.raises(RuntimeError, match="closed"):
        timeline.at(1)
    timeline.close()  # twice is fine


def recorded(serve: Serve, target: str, actions: list[int], path: Path) -> Path:
    """An episode of ``target`` taking ``actions`` over a real server, written to ``path``."""
    server = serve(target)
    with Client(server.host, server.port, timeout=30) as client:
        observation, _ = client.reset(seed=3)
        digests = [digest(observation)]
        for action in actions:
            digests.append(digest(client.step(action)[0]))
        EpisodeFile(target, client.snapshot(), digests, False, False).save(path)
    return path


def test_an_episode_without_digests_gets_them_on_the_first_pass(tmp_path: Path) -> None:
    path = record(tmp_path, PLINKO)
    episode = EpisodeFile.load(path)
    bare = EpisodeFile(episode.target, episode.snapshot, [], episode.terminated, episode.truncated)
    with Timeline(bare) as timeline:
        assert timeline.episode.observations == episode.observations
        assert bare.observations == []  # the caller's recording is left as it was
        timeline.save(tmp_path / "with-digests.rlenv")
    assert EpisodeFile.load(tmp_path / "with-digests.rlenv").observations == episode.observations


def test_a_step_can_read_a_few_nodes_only(tmp_path: Path) -> None:
    path = record(tmp_path, PLINKO)
    with Timeline.open(path) as timeline:
        everything = timeline.at(6)
        agent = next(path for path in everything.properties if path.endswith("/Agent"))
        few = timeline.at(6, nodes=[agent])
        assert few.properties == {agent: everything.properties[agent]}
        assert digest(few.observation) == digest(everything.observation)
        assert few.draw == everything.draw


@pytest.mark.parametrize(
    ("target", "timeout"),
    [("examples.faulty:DyingEnvironment", 60.0), ("examples.faulty:SlowEnvironment", 10.0)],
)
def test_a_crash_or_a_hang_fails_one_call_and_the_timeline_goes_on(
    tmp_path: Path, serve: Serve, target: str, timeout: float
) -> None:
    # The timeout also bounds each process's start: a crash is seen at once (no need to wait),
    # a hang costs the whole timeout, which must still leave a loaded machine time to start one
    path = recorded(serve, target, [0] * 8, tmp_path / "episode.rlenv")
    recording = EpisodeFile.load(path)
    with Timeline.open(path, timeout=timeout, checkpoint_every=4) as timeline:
        with pytest.raises(RuntimeError, match="environment process .* (is gone|did not answer)"):
            timeline.branch(5, [1])
        for step in (6, 2, 8):
            assert digest(timeline.at(step).observation) == recording.observations[step]
        assert len(timeline.branch(5, [0, 0])) == 7


def test_an_action_the_environment_raises_on_is_refused_and_the_timeline_goes_on(
    tmp_path: Path, serve: Serve
) -> None:
    path = recorded(serve, "examples.faulty:FaultyEnvironment", [0] * 4, tmp_path / "episode.rlenv")
    with Timeline.open(path) as timeline:
        with pytest.raises(RemoteError, match="environment_error"):
            timeline.branch(2, [1])
        with pytest.raises(RemoteError, match="invalid_action"):
            timeline.branch(2, [7])
        again = timeline.branch(2, [0, 0])
        assert again.episode.observations == timeline.episode.observations[:5]
        with pytest.raises(RemoteError, match="cannot draw"):  # its _draw always raises
            timeline.at(3)


def test_a_target_that_does_not_load_is_said(tmp_path: Path) -> None:
    path = record(tmp_path, CARTPOLE)
    with pytest.raises(ServerStartError, match="examples.nothing"):
        Timeline.open(path, target="examples.nothing:Nothing")


def test_a_timeline_says_its_environment_and_lists_its_nodes(tmp_path: Path) -> None:
    path = record(tmp_path, PLINKO)
    with Timeline.open(path) as timeline:
        assert timeline.hello.environment == "Plinko" and timeline.hello.agents == ("Agent",)
        assert timeline.hello.action_space.shape == (1,)
        nodes = timeline.tree(5)
        agent = next(node for node in nodes if node.get("config") == "agent")
        assert agent["demonstration_keys"]
        assert {node["path"]: node["exported"] for node in nodes} == timeline.at(5).properties
        branch = timeline.branch(2, policy=follow, max_steps=2)
        assert branch.hello is timeline.hello
