"""Recorded episodes as Minari datasets: ``rlenv dataset create``, DataCollector, load, show."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import rlenv_client  # noqa: F401  (registers the ids)
from rlenv_client.replay import EpisodeFile, RecordEpisodes

minari = pytest.importorskip("minari")
pytest.importorskip("h5py")

pytestmark = pytest.mark.minari

Policy = Callable[[int, int, Any], Any]


@dataclass
class Seen:
    """What the recording client saw of one episode."""

    observations: list[Any] = field(default_factory=list)
    actions: list[Any] = field(default_factory=list)
    terminated: bool = False
    truncated: bool = False


@pytest.fixture(autouse=True)
def datasets_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Minari's datasets (and the subprocesses') go to a folder of this test."""
    path = tmp_path / "datasets"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(path))
    return path


def record(directory: Path, env_id: str, policies: list[Policy], **kwargs: Any) -> list[Seen]:
    """Record one episode per policy (given the episode, the step, the observation), for real."""
    env = RecordEpisodes(gym.make(env_id, **kwargs), directory)
    try:
        return [
            play(env, policy, number, 100 + number, 1000) for number, policy in enumerate(policies)
        ]
    finally:
        env.close()


def play(env: gym.Env, policy: Policy, number: int, seed: int, steps: int) -> Seen:
    """Play episode ``number`` from a reset with ``seed``, ``steps`` at most: what was seen."""
    seen = Seen()
    observation, _ = env.reset(seed=seed)
    seen.observations.append(observation)
    for t in range(steps):
        action = policy(number, t, observation)
        observation, _, terminated, truncated, _ = env.step(action)
        seen.observations.append(observation)
        seen.actions.append(action)
        if terminated or truncated:
            seen.terminated, seen.truncated = terminated, truncated
            break
    return seen


def rlenv(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "rlenv", *args], capture_output=True, text=True, timeout=300
    )


def minari_show(dataset_id: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", "from minari.cli import app; app()", "show", dataset_id],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "COLUMNS": "200"},
    )


def push(number: int, t: int, observation: Any) -> int:
    """CartPole: always right in episode 0 (falls: terminated), balancing in the others."""
    return 1 if number == 0 else int(observation[2] + 0.5 * observation[3] > 0)


def sweep(number: int, t: int, observation: Any = None) -> np.ndarray:
    """Reacher: a smooth sweep of both joints (float32, as its Box)."""
    return np.array([np.sin(t / 5 + number), np.cos(t / 7)], np.float32)


def assert_same(dataset: Any, seen: list[Seen]) -> None:
    """The dataset's episodes are the recorded ones, bit for bit."""
    episodes = list(dataset.iterate_episodes())
    assert len(episodes) == len(seen)
    for episode, expected in zip(episodes, seen, strict=True):
        observations = np.stack(expected.observations)
        assert episode.observations.dtype == observations.dtype
        assert episode.observations.tobytes() == observations.tobytes()
        actions = np.asarray(expected.actions)
        assert episode.actions.shape == actions.shape
        assert episode.actions.tobytes() == actions.astype(episode.actions.dtype).tobytes()
        assert np.array_equal(episode.actions, actions)
        steps = len(expected.actions)
        assert len(episode.rewards) == steps and len(episode.observations) == steps + 1
        ending = np.zeros(steps, bool)
        ending[-1] = True
        assert list(episode.terminations) == list(ending & expected.terminated)
        assert list(episode.truncations) == list(ending & expected.truncated)


def test_cartpole_recordings_become_a_dataset(tmp_path: Path) -> None:
    seen = record(tmp_path / "episodes", "rlenv/CartPole-v1", [push, push], max_episode_steps=30)
    assert [(s.terminated, s.truncated) for s in seen] == [(True, False), (False, True)]
    result = rlenv(
        "dataset",
        "create",
        "cartpole/recorded-v0",
        "--from",
        str(tmp_path / "episodes"),
        "--author",
        "rlenv tests",
    )
    assert result.returncode == 0, result.stderr
    steps = sum(len(s.actions) for s in seen)
    assert f"wrote dataset cartpole/recorded-v0: 2 episodes, {steps} steps" in result.stdout
    dataset = minari.load_dataset("cartpole/recorded-v0")
    assert_same(dataset, seen)
    assert dataset.spec.env_spec.id == "rlenv/CartPole-v1"
    assert dataset.spec.action_space == gym.spaces.Discrete(2)
    assert any(r.startswith("rlenv==") for r in dataset.storage.metadata["requirements"])
    assert any(r.startswith("pymunk==") for r in dataset.storage.metadata["requirements"])
    env = dataset.recover_environment()
    try:
        observation, _ = env.reset(seed=100)
        assert np.array_equal(observation, seen[0].observations[0])
        observation, *_ = env.step(1)
        assert np.array_equal(observation, seen[0].observations[1])
    finally:
        env.close()
    shown = minari_show("cartpole/recorded-v0")
    assert shown.returncode == 0, shown.stdout + shown.stderr
    for text in (
        "cartpole/recorded-v0",
        f"Total Steps               │ {steps}",
        "Total Episodes            │ 2",
        "Discrete(2)",
        "rlenv/CartPole-v1",
        "rlenv tests",
    ):
        assert text in shown.stdout, shown.stdout


def test_a_box_action_environment_and_older_recordings(tmp_path: Path) -> None:
    seen = record(tmp_path / "episodes", "rlenv/Reacher-v0", [sweep, sweep], max_episode_steps=25)
    older = tmp_path / "episodes" / "episode-0002.rlenv"
    episode = EpisodeFile.load(older)
    assert (episode.terminated, episode.truncated) == (seen[1].terminated, seen[1].truncated)
    episode.terminated = episode.truncated = None  # as recorded before they were kept
    episode.save(older)
    result = rlenv(
        "dataset", "create", "rlenv/reacher/sweep-v3", "--from", str(tmp_path / "episodes")
    )
    assert result.returncode == 0, result.stderr
    assert (
        "note: episode-0002.rlenv is an older recording, without its end: truncated, "
        "as re-simulated" in result.stdout
    )
    dataset = minari.load_dataset("rlenv/reacher/sweep-v3")
    assert_same(dataset, seen)
    assert dataset.spec.action_space == gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    env = dataset.recover_environment()
    try:
        env.reset(seed=100)
        observation, *_ = env.step(sweep(0, 0))
        assert np.array_equal(observation, seen[0].observations[1])
    finally:
        env.close()


def test_data_collector_around_an_rlenv_environment(tmp_path: Path) -> None:
    env = minari.DataCollector(gym.make("rlenv/CartPole-v1", max_episode_steps=20))
    try:
        seen = [play(env, push, number, number, 100) for number in range(2)]
        env.create_dataset(
            "cartpole/collected-v0",
            algorithm_name="push",
            author="rlenv tests",
            author_email="-",
            code_permalink="-",
            description="DataCollector test",
            eval_env="rlenv/CartPole-v1",
        )
    finally:
        env.close()
    assert_same(minari.load_dataset("cartpole/collected-v0"), seen)


@pytest.mark.parametrize(
    ("dataset_id", "form"),
    [
        ("cartpole", "ENV/NAME-vN or NAMESPACE/ENV/NAME-vN"),
        ("cartpole/expert", "ENV/NAME-vN or NAMESPACE/ENV/NAME-vN"),
        ("cart pole/expert-v0", "ENV/NAME-vN or NAMESPACE/ENV/NAME-vN"),
    ],
)
def test_a_dataset_id_of_another_form_is_refused(
    tmp_path: Path, dataset_id: str, form: str
) -> None:
    result = rlenv("dataset", "create", dataset_id, "--from", str(tmp_path))
    assert result.returncode == 2
    assert result.stderr.strip() == (
        f"rlenv dataset: dataset id {dataset_id!r} is not of the "
        f"form {form} (for example cartpole/expert-v0)"
    )


def test_an_empty_folder_is_refused(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    result = rlenv("dataset", "create", "cartpole/none-v0", "--from", str(tmp_path / "empty"))
    assert result.returncode == 2
    assert result.stderr.strip() == (
        f"rlenv dataset: {tmp_path / 'empty'} holds no recordings "
        f"(*.rlenv files written by RecordEpisodes)"
    )


def test_a_recording_that_no_longer_replays_names_its_step(
    tmp_path: Path, datasets_path: Path
) -> None:
    record(tmp_path / "episodes", "rlenv/CartPole-v1", [push])
    path = tmp_path / "episodes" / "episode-0001.rlenv"
    episode = EpisodeFile.load(path)
    actions = [event for event in episode.snapshot["events"] if event[0] == "action"]
    actions[3][1] = 0  # step 4 pushed the other way: the cart's velocity differs
    episode.save(path)
    result = rlenv("dataset", "create", "cartpole/changed-v0", "--from", str(tmp_path / "episodes"))
    assert result.returncode == 2
    assert result.stderr.strip() == (
        f"rlenv dataset: {path} no longer replays: step 4: the "
        f"observation differs from the recording"
    )
    assert not (datasets_path / "cartpole" / "changed-v0").exists()
