"""Exact replays: an episode recorded as seed, configuration and actions re-runs identically."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import rlenv_client  # registers the ids
from examples.cartpole import controller
from rlenv.protocol import unpack
from rlenv_client.replay import EpisodeFile, RecordEpisodes


def record(directory: Path, episodes: int = 2) -> list[Path]:
    env = RecordEpisodes(gym.make("rlenv/CartPole-v0", repeat_action=2), directory)
    try:
        env.unwrapped.configure(agent={"max_force": 8.0})
        for episode in range(episodes):
            observation, _ = env.reset(seed=40 + episode)
            for t in range(400):
                noise = 0.8 * np.sin(t / 3.0 + episode)
                action = np.clip(controller(observation) + noise, -1, 1).astype(np.float32)
                observation, _, terminated, truncated, _ = env.step(action)
                if terminated or truncated:
                    break
    finally:
        env.close()
    return sorted(directory.glob("*.rlenv"))


def run_replay(path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "rlenv", "replay", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_recorded_episodes_replay_bit_for_bit(tmp_path: Path) -> None:
    files = record(tmp_path)
    assert [f.name for f in files] == ["episode-0001.rlenv", "episode-0002.rlenv"]
    episode = EpisodeFile.load(files[0])
    assert episode.target == "rlenv.examples.cartpole:CartPoleEnvironment"  # the id's target
    assert episode.snapshot["config"]["agent"]["max_force"] == 8.0
    assert len(episode.observations) == 1 + sum(
        e[0] == "action" for e in episode.snapshot["events"]
    )
    for path in files:
        result = run_replay(path)
        assert result.returncode == 0, result.stdout + result.stderr
        assert "every observation identical" in result.stdout
    # A recording naming the checkout's examples.cartpole (an installed rlenv loads
    # rlenv.examples.cartpole for it: make test-package) replays the same.
    episode.target = "examples.cartpole:CartPoleEnvironment"
    episode.save(tmp_path / "checkout.rlenv")
    result = run_replay(tmp_path / "checkout.rlenv")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "every observation identical" in result.stdout


def test_a_divergence_is_found_and_located(tmp_path: Path) -> None:
    path = record(tmp_path, episodes=1)[0]
    episode = EpisodeFile.load(path)
    episode.observations[5] = "0" * 32  # pretend step 5 looked different
    episode.save(tmp_path / "tampered.rlenv")
    result = run_replay(tmp_path / "tampered.rlenv")
    assert result.returncode == 1 and "step 5:" in result.stdout
    episode = EpisodeFile.load(path)
    episode.snapshot["events"][2][1] = np.array([-1.0], np.float32)  # another action at step 3
    episode.save(tmp_path / "changed.rlenv")
    result = run_replay(tmp_path / "changed.rlenv")
    assert result.returncode == 1 and "step 3:" in result.stdout


def test_replay_refuses_what_is_not_an_episode(tmp_path: Path) -> None:
    junk = tmp_path / "junk.rlenv"
    junk.write_bytes(b"\x00\x01not msgpack")
    result = run_replay(junk)
    assert result.returncode == 2 and "not an rlenv episode" in result.stderr
    assert "Traceback" not in result.stderr


def test_an_inspectors_edits_are_replayed(tmp_path: Path) -> None:
    env = RecordEpisodes(
        gym.make("rlenv/CartPole-v0", repeat_action=2, share_server=False), tmp_path
    )
    try:
        address = env.unwrapped.client.address
        host, _, port = address.rpartition(":")
        observation, _ = env.reset(seed=7)
        with rlenv_client.Client(host, int(port)) as inspector:  # an observer, beside
            for t in range(600):  # until the episode ends (the time limit at the latest)
                if t == 5:
                    inspector.set_property("World/Physics/Pole", "angular_velocity", 1.5)
                if t == 10:
                    inspector.inspect_configure(world={"gravity": [0.0, -4.0]})
                action = np.clip(controller(observation), -1, 1).astype(np.float32)
                observation, _, terminated, truncated, _ = env.step(action)
                if terminated or truncated:
                    break
    finally:
        env.close()
    path = sorted(tmp_path.glob("*.rlenv"))[0]
    kinds = [event[0] for event in EpisodeFile.load(path).snapshot["events"]]
    assert "set" in kinds and "config" in kinds
    result = run_replay(path)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "every observation identical" in result.stdout


def test_recordings_keep_how_episodes_ended_and_older_ones_still_replay(tmp_path: Path) -> None:
    path = record(tmp_path, episodes=1)[0]
    episode = EpisodeFile.load(path)
    assert (episode.terminated, episode.truncated) in ((True, False), (False, True))
    older = tmp_path / "older.rlenv"  # as written before the end was kept: no such keys
    EpisodeFile(episode.target, episode.snapshot, episode.observations).save(older)
    assert "terminated" not in unpack(older.read_bytes())
    assert (EpisodeFile.load(older).terminated, EpisodeFile.load(older).truncated) == (None, None)
    result = run_replay(older)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "every observation identical" in result.stdout
