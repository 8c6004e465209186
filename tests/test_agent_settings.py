"""Settings per agent: ``config.agent`` for every agent, a class or one agent, and everything that
keeps settings (snapshots, restore, recordings, ``rlenv replay``, timelines, datasets, the
compliance suite, the HTTP gateway) keeping each agent's own.

The game is ``tests/per_agent_envs.py``'s: a ``Chaser`` whose class pushes with 10 N and two
runners whose class pushes with 8 N (issue 41's reproduction), served by real ``rlenv serve``
subprocesses.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from conftest import Serve
from http_gateway import Gateway, assert_problem
from per_agent_envs import NAMES

from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv_client import Client, RemoteEnv
from rlenv_client.replay import EpisodeFile, RecordEpisodes, digest
from rlenv_tools.compliance import check_server
from rlenv_tools.timeline import Timeline

TESTS = Path(__file__).parent
CHASE = "per_agent_envs:ChaseEnvironment"
CARTPOLE = "examples.cartpole:CartPoleEnvironment"
KEYS = {
    "Chaser": ("max_force",),
    "Runner1": ("max_force", "sight"),
    "Runner2": ("max_force", "sight"),
}
UNKNOWN = (
    "config.agent has no setting or agent 'speed'; its settings: max_force, sight; its "
    "agents: Chaser, Runner1, Runner2 (classes: ChaserAgent, RunnerAgent)"
)


@pytest.fixture
def serve_chase(serve: Serve) -> Any:
    """Start a server of the chase game (tests/ on its path)."""
    return lambda: serve(CHASE, env={"PYTHONPATH": _path()})


@pytest.fixture
def tests_on_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """Servers and commands this test starts find ``per_agent_envs``."""
    monkeypatch.setenv("PYTHONPATH", _path())


def _path() -> str:
    return os.pathsep.join(filter(None, [str(TESTS), os.environ.get("PYTHONPATH")]))


def settings_of(client: Client) -> dict[str, dict[str, Any]]:
    """Each agent's settings, as the server reads them now."""
    return {
        name: {key: client.get_property(name, key) for key in keys} for name, keys in KEYS.items()
    }


def joint_action(step: int) -> dict[str, np.ndarray]:
    """Every agent pushes hard, each its own way (so any agent's force shows at once)."""
    return {
        name: np.array([np.sin(step / 3 + index), np.cos(step / 4 + index)], np.float32)
        for index, name in enumerate(NAMES)
    }


def play(client: Client, seed: int, steps: int) -> list[dict[str, np.ndarray]]:
    """The observations of an episode from ``seed`` under :func:`joint_action`."""
    observations = [client.reset(seed=seed)[0]]
    observations += [client.step(joint_action(step))[0] for step in range(steps)]
    return observations


def same(first: list[dict[str, np.ndarray]], second: list[dict[str, np.ndarray]]) -> bool:
    """Bit for bit, every agent's observation at every step."""
    return [digest(o) for o in first] == [digest(o) for o in second]


# --- configuring ------------------------------------------------------------------------------


def test_every_agent_a_class_and_one_agent_the_more_precise_winning(serve_chase: Any) -> None:
    server = serve_chase()
    with Client(server.host, server.port) as client:
        assert settings_of(client) == {
            "Chaser": {"max_force": 10.0},  # each class its own
            "Runner1": {"max_force": 8.0, "sight": 10.0},
            "Runner2": {"max_force": 8.0, "sight": 10.0},
        }
        client.configure(agent={"Runner1": {"max_force": 6.0}})  # one agent
        assert settings_of(client)["Runner1"]["max_force"] == 6.0
        assert settings_of(client)["Runner2"]["max_force"] == 8.0
        assert settings_of(client)["Chaser"]["max_force"] == 10.0
        client.configure(agent={"RunnerAgent": {"sight": 3.0}})  # a class
        assert [settings_of(client)[name]["sight"] for name in ("Runner1", "Runner2")] == [3.0, 3.0]
        client.configure(agent={"max_force": 9.0})  # every agent, as before
        assert {name: values["max_force"] for name, values in settings_of(client).items()} == {
            "Chaser": 9.0,
            "Runner1": 9.0,
            "Runner2": 9.0,
        }
        # every agent < class < name, whatever the order of the keys
        client.configure(
            agent={
                "Runner2": {"max_force": 5.0},
                "RunnerAgent": {"max_force": 7.0},
                "max_force": 11.0,
            }
        )
        assert settings_of(client) == {
            "Chaser": {"max_force": 11.0},
            "Runner1": {"max_force": 7.0, "sight": 3.0},
            "Runner2": {"max_force": 5.0, "sight": 3.0},
        }
        client.inspect_configure(agent={"Chaser": {"max_force": 12.0}})  # as an inspector
        assert settings_of(client)["Chaser"]["max_force"] == 12.0


def test_a_key_neither_a_setting_nor_an_agent_is_refused_naming_both(serve_chase: Any) -> None:
    server = serve_chase()
    with Client(server.host, server.port) as client:
        refusals = [
            ({"speed": 1.0}, ErrorCode.INVALID_CONFIG, UNKNOWN),
            ({"Runner1": {"max_force": 6.0}, "speed": 1.0}, ErrorCode.INVALID_CONFIG, UNKNOWN),
            (
                {"Runner1": 6.0},
                ErrorCode.BAD_REQUEST,
                "config.agent.Runner1 must be a map of that agent's settings",
            ),
            (
                {"RunnerAgent": [1]},
                ErrorCode.BAD_REQUEST,
                "config.agent.RunnerAgent must be a map of that class's settings",
            ),
            (
                {"Chaser": {"sight": 2.0}},
                ErrorCode.INVALID_CONFIG,
                "config.agent: Chaser: ChaserAgent has no configurable 'sight'; it accepts "
                "max_force",
            ),
            (
                {"sight": 2.0},
                ErrorCode.INVALID_CONFIG,  # a setting the chaser has not
                "config.agent: Chaser: ChaserAgent has no configurable 'sight'; it accepts "
                "max_force",
            ),
            (
                {"Runner2": {"max_force": "fast"}},
                ErrorCode.INVALID_CONFIG,
                "config.agent: Runner2: RunnerAgent.max_force",
            ),
        ]
        for config, code, message in refusals:
            with pytest.raises(RemoteError) as refused:
                client.configure(agent=config)
            assert refused.value.code == code and message in str(refused.value), config
        assert settings_of(client)["Runner1"]["max_force"] == 8.0  # refused whole: nothing set
        observation, _ = client.reset(seed=0)  # still serving
        assert set(observation) == set(NAMES)


def test_one_agent_alone_keeps_its_flat_map_and_may_be_named(serve: Serve) -> None:
    server = serve(CARTPOLE)
    with Client(server.host, server.port) as client:
        assert client.hello.agents == ("Agent",)
        client.configure(agent={"max_force": 8.0})
        client.reset(seed=0)
        kept = client.snapshot()["config"]["agent"]  # flat, as before: not keyed by "Agent"
        assert set(kept) == {"max_force", "angle_limit"} and kept["max_force"] == 8.0
        client.configure(agent={"Agent": {"max_force": 7.0}})
        client.reset(seed=0)
        assert client.snapshot()["config"]["agent"] == {**kept, "max_force": 7.0}
        with pytest.raises(RemoteError) as refused:
            client.configure(agent={"max_forse": 1.0})
        assert refused.value.code == ErrorCode.INVALID_CONFIG
        assert str(refused.value).endswith(
            "config.agent has no setting or agent 'max_forse'; its settings: angle_limit, "
            "max_force; its "
            "agents: Agent (classes: CartPoleAgent)"
        )


def test_the_http_gateway_takes_both_forms_and_its_snapshots_keep_each_agents(
    tests_on_path: None,
) -> None:
    gateway = Gateway(CHASE)
    try:
        tuned = gateway.session(agent={"max_force": 9.0, "Runner1": {"max_force": 6.0}})
        plain = gateway.session()
        gateway.post(f"/v1/envs/{tuned}/reset", {"seed": 2})
        action = {name: [0.5, -1.0] for name in NAMES}
        gateway.post(f"/v1/envs/{tuned}/step", {"action": action})
        snapshot = gateway.get(f"/v1/envs/{tuned}/snapshot")["snapshot"]
        assert snapshot["config"]["agent"] == {
            "Chaser": {"max_force": 9.0},
            "Runner1": {"max_force": 6.0, "sight": 10.0},
            "Runner2": {"max_force": 9.0, "sight": 10.0},
        }
        gateway.post(f"/v1/envs/{plain}/restore", {"snapshot": snapshot})
        steps = [
            gateway.post(f"/v1/envs/{session}/step", {"action": action})
            for session in (tuned, plain)
        ]
        assert steps[0] == steps[1]  # the restored session pushes with each agent's force
        refused = gateway.request("POST", "/v1/envs", {"kwargs": {"agent": {"speed": 1.0}}})
        assert assert_problem(refused, 422, "invalid_config")["detail"].endswith(UNKNOWN)
    finally:
        gateway.close()


# --- snapshots and restore ------------------------------------------------------------------


def test_a_snapshot_keeps_each_agents_settings_and_restores_them(serve_chase: Any) -> None:
    source, fresh = serve_chase(), serve_chase()
    with Client(source.host, source.port) as original, Client(fresh.host, fresh.port) as copy:
        original.configure(agent={"Runner2": {"max_force": 5.0, "sight": 2.5}})
        before = play(original, 3, 6)
        snapshot = original.snapshot()
        assert snapshot["config"]["agent"] == {
            "Chaser": {"max_force": 10.0},
            "Runner1": {"max_force": 8.0, "sight": 10.0},
            "Runner2": {"max_force": 5.0, "sight": 2.5},
        }
        after = [original.step(joint_action(6 + step))[0] for step in range(8)]
        restored, _ = copy.restore(snapshot)
        assert digest(restored) == digest(before[-1])
        assert settings_of(copy) == settings_of(original)  # each its own, not the Chaser's
        assert same(after, [copy.step(joint_action(6 + step))[0] for step in range(8)])
        # The restored server plays later episodes with each agent's own values.
        assert same(play(original, 9, 12), play(copy, 9, 12))
        assert settings_of(copy)["Runner2"] == {"max_force": 5.0, "sight": 2.5}


def test_an_older_snapshot_with_one_agent_map_restores_it_on_every_agent(serve_chase: Any) -> None:
    server = serve_chase()
    with Client(server.host, server.port) as client:
        play(client, 4, 2)
        snapshot = client.snapshot()
        snapshot["config"]["agent"] = {"max_force": 10.0}  # as a 2.5 server kept it: the first's
        client.restore(snapshot)
        assert {name: values["max_force"] for name, values in settings_of(client).items()} == {
            "Chaser": 10.0,
            "Runner1": 10.0,
            "Runner2": 10.0,
        }


def test_a_request_that_fails_gives_each_agent_back_its_own_settings(serve_chase: Any) -> None:
    server = serve_chase()
    with Client(server.host, server.port) as client:
        client.configure(agent={"Runner1": {"max_force": 6.0}})
        play(client, 5, 2)
        snapshot = client.snapshot()
        expected = settings_of(client)
        snapshot["config"]["agent"] = {name: {"max_force": 1.0} for name in NAMES}
        snapshot["events"].append(["set", "World/Physics/Built/Later", "position", [0.0, 0.0]])
        with pytest.raises(RemoteError, match="restore: events"):
            client.restore(snapshot)  # its configuration was applied, then its replay failed
        assert settings_of(client) == expected  # not the first agent's values for every agent


# --- recordings: rlenv replay, timelines, datasets, the compliance suite ----------------------


def record(directory: Path, steps: int = 40) -> Path:
    """One episode of the chase game, its settings differing per agent, recorded."""
    env = RecordEpisodes(gym.wrappers.TimeLimit(RemoteEnv(CHASE), steps), directory)
    try:
        env.unwrapped.configure(agent={"Runner2": {"max_force": 5.0, "sight": 3.0}})
        env.reset(seed=5)
        for step in range(steps):
            _, _, terminated, truncated, _ = env.step(joint_action(step))
            if terminated or truncated:
                break
    finally:
        env.close()
    return directory / "episode-0001.rlenv"


def test_a_game_whose_classes_differ_replays_bit_for_bit(
    tmp_path: Path, tests_on_path: None
) -> None:
    path = record(tmp_path)
    episode = EpisodeFile.load(path)
    assert episode.snapshot["config"]["agent"]["Chaser"] == {"max_force": 10.0}
    assert episode.snapshot["config"]["agent"]["Runner2"] == {"max_force": 5.0, "sight": 3.0}
    replayed = subprocess.run(
        [sys.executable, "-m", "rlenv", "replay", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert replayed.returncode == 0, replayed.stdout + replayed.stderr
    assert "replayed 40 steps" in replayed.stdout
    assert "every observation identical" in replayed.stdout
    with Timeline.open(path, checkpoint_every=8) as timeline:
        for step in (len(timeline), 1, 17, 0, 33):
            assert digest(timeline.at(step).observation) == episode.observations[step], step


def test_an_older_recording_that_cannot_replay_says_why(
    tmp_path: Path, tests_on_path: None
) -> None:
    """A recording made before settings per agent kept the first agent's settings only: where
    the agents' differed it diverges, and the message says so instead of blaming the game."""
    episode = EpisodeFile.load(record(tmp_path))
    episode.snapshot["config"]["agent"] = {"max_force": 10.0}  # as a 2.5 server kept it
    older = tmp_path / "older.rlenv"
    episode.save(older)
    replayed = subprocess.run(
        [sys.executable, "-m", "rlenv", "replay", str(older)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert replayed.returncode == 1
    note = (
        "the recording predates settings per agent, protocol 2.6: it kept one agent's "
        "settings, {'max_force': 10.0}, which replay on every agent; if the agents' "
        "settings differed, it cannot replay"
    )
    # Runner2 saw the chaser within 3 m: the first observation already differs
    assert f"the first observation (after the reset) differs ({note})" in replayed.stdout
    with pytest.raises(RuntimeError, match="step 0: .*predates settings per agent"):
        Timeline.open(older).close()


def test_tags_recordings_replay_bit_for_bit_with_its_classes_own_settings(tmp_path: Path) -> None:
    """examples/tag as shipped (the chaser's class 10 N, the runners' 8 N, nothing configured),
    and once its Runner class and one runner are configured, by their names."""
    env = RecordEpisodes(gym.make("rlenv/Tag-v0", max_episode_steps=25), tmp_path)
    try:
        for episode in range(2):
            if episode == 1:
                env.unwrapped.configure(
                    agent={"Runner": {"max_force": 7.0}, "Runner2": {"max_force": 5.0}}
                )
            env.reset(seed=20 + episode)
            for step in range(25):
                _, _, terminated, truncated, _ = env.step(joint_action(step))
                if terminated or truncated:
                    break
    finally:
        env.close()
    kept = [
        EpisodeFile.load(path).snapshot["config"]["agent"]
        for path in sorted(tmp_path.glob("*.rlenv"))
    ]
    assert kept == [
        {
            "Chaser": {"max_force": 10.0},
            "Runner1": {"max_force": 8.0},
            "Runner2": {"max_force": 8.0},
        },
        {
            "Chaser": {"max_force": 10.0},
            "Runner1": {"max_force": 7.0},
            "Runner2": {"max_force": 5.0},
        },
    ]
    for path in sorted(tmp_path.glob("*.rlenv")):
        replayed = subprocess.run(
            [sys.executable, "-m", "rlenv", "replay", str(path)],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert replayed.returncode == 0, replayed.stdout + replayed.stderr
        assert "every observation identical" in replayed.stdout


def test_the_compliance_suite_passes_on_a_game_whose_classes_differ(
    serve_chase: Any, tests_on_path: None
) -> None:
    """Its set and restore probes replay bit for bit (they diverged at step 1 when a restore
    gave every agent the first agent's settings), as a library call and in ``rlenv check``."""
    server = serve_chase()
    report = check_server(server.host, server.port, random_frames=20)
    assert report.passed, "\n".join(report.failures)
    checked = subprocess.run(
        [sys.executable, "-m", "rlenv", "check", "--compliance", CHASE],
        capture_output=True,
        text=True,
        timeout=300,
    )
    line = next(line for line in checked.stdout.splitlines() if "compliance" in line)
    assert re.search(r"PASS\S*\s+compliance under hostile input .* 0 failures", line), line


@pytest.mark.minari
def test_a_dataset_of_a_game_whose_classes_differ(
    tmp_path: Path, tests_on_path: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    minari = pytest.importorskip("minari")
    pytest.importorskip("h5py")
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    path = record(tmp_path / "episodes")
    created = subprocess.run(
        [
            sys.executable,
            "-m",
            "rlenv",
            "dataset",
            "create",
            "chase/per-agent-v0",
            "--from",
            str(path.parent),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert created.returncode == 0, created.stdout + created.stderr
    (stored,) = list(minari.load_dataset("chase/per-agent-v0").iterate_episodes())
    episode = EpisodeFile.load(path)
    assert len(stored.rewards) == len(episode.observations) - 1 == 40
    for step in (0, 1, 40):  # what the recording client saw, bit for bit
        seen = {name: stored.observations[name][step] for name in NAMES}
        assert digest(seen) == episode.observations[step], step
