"""Stable-Baselines3, used as its users use it (runs when the optional extra is installed)."""

from __future__ import annotations

from collections.abc import Iterator

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.env_checker import check_env  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402
from stable_baselines3.common.vec_env import VecMonitor  # noqa: E402

import rlenv_client  # noqa: E402, F401  (registers the ids)
from examples.cartpole import TARGET  # noqa: E402
from examples.tag import CHASER, RUNNERS, Chaser, Runner  # noqa: E402
from examples.tag import TARGET as TAG  # noqa: E402
from examples.train_sb3 import evaluate  # noqa: E402
from rlenv_client.sb3 import SB3VecEnv, SelfPlayCallback  # noqa: E402
from rlenv_client.selfplay import FrozenPolicy  # noqa: E402
from rlenv_client.vector import RemoteVectorEnv  # noqa: E402


@pytest.fixture(autouse=True)
def one_torch_thread() -> Iterator[None]:
    """Torch on one thread, as the training docs advise on a small machine: with its default
    threads its OpenMP worker spins and takes the servers' core (docs/training-fast.md), and
    PPO's test ran past its timeout on this 2-core VM under load."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def test_sb3_check_env_passes() -> None:
    env = gym.make("rlenv/CartPole-v0")
    try:
        check_env(env.unwrapped)
    finally:
        env.close()


def test_sb3_vec_env_follows_sb3_conventions() -> None:
    envs = VecMonitor(SB3VecEnv(3, TARGET, max_episode_steps=6))
    try:
        envs.seed(4)
        observations = envs.reset()
        assert observations.shape == (3, 5)
        finished = 0
        for _ in range(30):
            actions = np.ones((3, 1), np.float32)
            observations, rewards, dones, infos = envs.step(actions)
            assert rewards.dtype == np.float32 and dones.dtype == np.bool_
            for index in np.flatnonzero(dones):
                info = infos[index]
                assert info["terminal_observation"].shape == (5,)
                assert not np.array_equal(info["terminal_observation"], observations[index])
                assert "episode" in info  # VecMonitor saw the episode end
                assert info["TimeLimit.truncated"] == (info["episode"]["l"] == 6)
                finished += 1
        assert finished >= 5
    finally:
        envs.close()


def test_ppo_learns_cartpole_through_gymnasium_make() -> None:
    envs = make_vec_env("rlenv/CartPole-v0", n_envs=4, seed=0)
    try:
        model = PPO("MlpPolicy", envs, seed=0, n_steps=256, batch_size=64, verbose=0)
        before = evaluate(model, episodes=3)
        model.learn(total_timesteps=30_000)
        after = evaluate(model, episodes=3)
    finally:
        envs.close()
    assert after > max(4 * before, 400), (before, after)


def _episodes(envs: SB3VecEnv | VecMonitor, steps: int) -> list[tuple[dict, float, int]]:
    """Each finished episode's ``info["episode"]``, with its return and length counted here."""
    returns, lengths = np.zeros(envs.num_envs), np.zeros(envs.num_envs, int)
    finished = []
    envs.seed(1)
    envs.reset()
    for _ in range(steps):
        _, rewards, dones, infos = envs.step(np.ones((envs.num_envs, 1), np.float32))
        returns += rewards
        lengths += 1
        for index in np.flatnonzero(dones):
            finished.append((infos[index]["episode"], returns[index], lengths[index]))
            returns[index], lengths[index] = 0, 0
    return finished


def test_sb3_vec_env_fills_episode_statistics_as_monitor_does() -> None:
    envs = SB3VecEnv(2, TARGET, max_episode_steps=5, in_process=True)
    try:
        finished = _episodes(envs, 12)
        assert len(finished) >= 4
        for episode, episode_return, length in finished:
            assert set(episode) == {"r", "l", "t"} and episode["t"] >= 0
            assert episode["l"] == length and episode["r"] == pytest.approx(episode_return)
        monitored = _episodes(VecMonitor(envs), 12)  # wrapped anyway: the same figures, once
        assert [(e["l"], pytest.approx(e["r"])) for e, _, _ in monitored] == [
            (e["l"], e["r"]) for e, _, _ in finished
        ]
    finally:
        envs.close()


def test_ppo_logs_episode_returns_without_vec_monitor() -> None:
    envs = SB3VecEnv(2, TARGET, max_episode_steps=20, in_process=True)
    try:
        model = PPO("MlpPolicy", envs, seed=0, n_steps=64, batch_size=64, n_epochs=1, verbose=0)
        model.learn(total_timesteps=128)
        assert len(model.ep_info_buffer) >= 6  # what ep_rew_mean and ep_len_mean average
        assert all(info["l"] <= 20 for info in model.ep_info_buffer)
    finally:
        envs.close()


# --- one agent, or a team, of a multi-agent env ----------------------------------------------


def test_sb3_trains_the_chaser_straight_from_the_multi_agent_tag() -> None:
    envs = SB3VecEnv(2, TAG, agents=CHASER, max_episode_steps=100)
    try:
        assert envs.num_envs == 2 and envs.observation_space == Chaser.observation_space
        assert envs.venv.driven_by_server == dict.fromkeys(RUNNERS, "heuristic")
        model = PPO("MlpPolicy", envs, seed=0, n_steps=64, batch_size=64, verbose=0)
        model.learn(total_timesteps=512)
        episodes = list(model.ep_info_buffer)
    finally:
        envs.close()
    assert model.num_timesteps == 512 and len(episodes) >= 4
    assert all(1 <= episode["l"] <= 100 for episode in episodes)


def test_sb3_counts_a_team_members_wait_as_no_episode() -> None:
    """Runners share one policy; a tagged runner's episode is counted once, at its tag."""
    chaser = Chaser()
    envs = SB3VecEnv(
        1,
        TAG,
        agents=Runner,
        others={CHASER: chaser.heuristic},
        max_episode_steps=300,
        in_process=True,
    )
    try:
        envs.seed(1)
        envs.reset()
        tags, waits_ended = 0, 0
        for _ in range(300):
            envs.step_async(np.zeros((2, 2), np.float32))
            _, rewards, dones, infos = envs.step_wait()
            for index in np.flatnonzero(dones):
                info = infos[index]
                assert "terminal_observation" in info
                if "episode" in info:  # tagged: its episode, its return
                    assert info["episode"]["r"] < 0 and not info["TimeLimit.truncated"]
                    tags += 1
                else:  # a wait that ended with the instance's episode
                    assert info["TimeLimit.truncated"] and rewards[index] == 0.0
                    waits_ended += 1
            if waits_ended:
                break
    finally:
        envs.close()
    assert tags == 2 and waits_ended == 1


def test_self_play_refreshes_a_frozen_copy_of_the_learner_every_n_steps() -> None:
    frozen = FrozenPolicy(deterministic=True)
    envs = SB3VecEnv(2, TAG, agents="Runner1", others={"Runner2": frozen}, max_episode_steps=100)
    try:
        model = PPO("MlpPolicy", envs, seed=0, n_steps=64, batch_size=64, verbose=0)
        initial = [p.detach().clone() for p in model.policy.parameters()]
        model.learn(total_timesteps=512, callback=SelfPlayCallback(frozen, every=128))
        assert frozen.refreshed_at == [0, 128, 256, 384, 512]
        assert frozen.policy is not model.policy
        copied = [p.detach().clone() for p in frozen.policy.parameters()]
        assert any(not (a == b).all() for a, b in zip(copied, initial, strict=True))
        model.learn(total_timesteps=128, reset_num_timesteps=False)  # without the callback
        assert all(
            (a == b).all() for a, b in zip(copied, frozen.policy.parameters(), strict=True)
        )  # frozen: left as copied
        assert any(
            not (a == b).all() for a, b in zip(copied, model.policy.parameters(), strict=True)
        )
    finally:
        envs.close()


def test_the_frozen_copy_plays_its_agent() -> None:
    """Runner2's moves are the copy's actions on its own observations (checked by replaying
    them into the joint env)."""
    frozen, chaser = FrozenPolicy(deterministic=True), Chaser()
    envs = SB3VecEnv(
        1,
        TAG,
        agents="Runner1",
        in_process=True,
        others={"Runner2": frozen, CHASER: chaser.heuristic},
    )
    joint = RemoteVectorEnv(1, TAG, in_process=True, autoreset_mode="SameStep")
    try:
        model = PPO("MlpPolicy", envs, seed=0, n_steps=64, batch_size=64, verbose=0)
        frozen.refresh(model.policy)
        envs.seed(3)
        envs.reset()
        observations, _ = joint.reset(seed=3)
        for _ in range(30):  # Runner1 is not tagged yet
            mine = np.array([[0.5, -0.5]], np.float32)
            actions = {
                "Runner1": mine,
                "Runner2": np.array([frozen(observations["Runner2"][0])]),
                "Chaser": np.array([chaser.heuristic(observations["Chaser"][0])]),
            }
            envs.step_async(mine)
            ours, _, dones, _ = envs.step_wait()
            observations, *_ = joint.step(actions)
            assert not dones[0] and np.array_equal(ours[0], observations["Runner1"][0])
    finally:
        envs.close()
        joint.close()


# --- agents that come and go: a slot per possible prey, masked ------------------------------


def test_sb3_trains_prey_that_come_and_go_in_fixed_slots() -> None:
    from examples.hunt import HUNTER, PREY, Prey
    from examples.hunt import TARGET as HUNT

    envs = SB3VecEnv(1, HUNT, agents=Prey)  # the hunter: its heuristic, in the server
    try:
        assert envs.num_envs == len(PREY) and envs.venv.driven_by_server == {HUNTER: "heuristic"}
        envs.reset()
        assert [info["is_active"] for info in envs.reset_infos] == [True, True] + [False] * 6
        ends: list[tuple[float, dict]] = []
        for _ in range(600):
            envs.step_async(np.stack([envs.action_space.sample() for _ in range(envs.num_envs)]))
            _, rewards, dones, infos = envs.step_wait()
            for index, info in enumerate(infos):
                if not info["is_active"]:
                    assert rewards[index] == 0.0  # a row SB3 cannot skip: it earns nothing
                if dones[index] and "episode" in info:
                    ends.append((float(rewards[index]), info))
            if len(ends) >= 2:
                break
        assert len(ends) >= 2  # two prey caught: each an episode of its slot
        for reward, info in ends:
            assert info["terminal_observation"].shape == Prey.observation_space.shape
            assert not info["TimeLimit.truncated"] and reward < -0.5  # caught: -1
            assert info["episode"]["l"] >= 1
        model = PPO("MlpPolicy", envs, seed=0, n_steps=32, batch_size=64, verbose=0)
        model.learn(total_timesteps=256)
        assert model.num_timesteps == 256
    finally:
        envs.close()
