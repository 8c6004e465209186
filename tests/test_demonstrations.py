"""Demonstrations: a scripted controller's and a person's episodes, recorded and replayed.

A person plays through the inspector's control routes, over real HTTP beside a real server
(the page itself is driven in ``test_inspector_browser.py``).
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from conftest import wait_until
from gymnasium import spaces
from inspector_http import fetch

from examples.cartpole import TARGET, controller
from rlenv.demonstration_keys import default_keys
from rlenv_client import Client
from rlenv_client.launcher import ServerProcess
from rlenv_client.replay import EpisodeFile
from rlenv_tools.demonstrations import record
from rlenv_tools.inspector import Demonstrator, InspectorServer, Watcher


def replays_identically(path: Path) -> bool:
    result = subprocess.run(
        [sys.executable, "-m", "rlenv", "replay", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return "every observation identical" in result.stdout


def actions(path: Path) -> list[float]:
    return [
        float(event[1][0])
        for event in EpisodeFile.load(path).snapshot["events"]
        if event[0] == "action"
    ]


def test_a_scripted_controller_records_episodes_that_replay_bit_for_bit(tmp_path: Path) -> None:
    def wobbly(observation: np.ndarray) -> np.ndarray:
        return np.clip(controller(observation) + 0.9, -1, 1).astype(np.float32)

    files = record(TARGET, wobbly, 2, tmp_path, seed=5)
    assert [path.name for path in files] == ["episode-0001.rlenv", "episode-0002.rlenv"]
    for path in files:
        episode = EpisodeFile.load(path)
        assert episode.target == TARGET
        assert len(episode.observations) == 1 + len(actions(path))
        assert replays_identically(path)
    again = record(TARGET, wobbly, 1, tmp_path, seed=5)  # numbered after, never overwriting
    assert [path.name for path in again] == ["episode-0003.rlenv"]
    assert EpisodeFile.load(again[0]).snapshot == EpisodeFile.load(files[0]).snapshot


def test_default_keys_follow_the_action_space() -> None:
    assert default_keys(spaces.Discrete(2)) == {"1": 0, "2": 1, "ArrowLeft": 0, "ArrowRight": 1}
    three = default_keys(spaces.Discrete(3, start=-1))
    assert three == {"1": -1, "2": 0, "3": 1, "ArrowLeft": -1, "ArrowDown": 0, "ArrowRight": 1}
    assert sorted(default_keys(spaces.Discrete(12)).values()) == list(range(9))
    box = default_keys(spaces.Box(np.array([-2, -1], np.float32), np.array([2, 3], np.float32)))
    assert {key: value.tolist() for key, value in box.items()} == {
        "ArrowLeft": [-2.0, 0.0],
        "ArrowRight": [2.0, 0.0],
        "ArrowDown": [0.0, -1.0],
        "ArrowUp": [0.0, 3.0],
    }
    assert box["ArrowUp"].dtype == np.float32
    assert default_keys(spaces.Box(-1, 1, (3,))) == {}
    assert default_keys(spaces.MultiBinary(4)) == {}


@pytest.fixture
def demonstrations(server: ServerProcess, tmp_path: Path) -> Iterator[tuple[str, Demonstrator]]:
    """An inspector (in this process) on ``server`` whose person's episodes go to tmp_path."""
    watcher = Watcher([f"{server.host}:{server.port}"])
    demonstrator = Demonstrator(watcher, tmp_path, target=TARGET, rate=200.0)
    inspector = InspectorServer(watcher, demonstrator=demonstrator)
    inspector.start()
    try:
        yield inspector.url, demonstrator
    finally:
        inspector.close()


def test_a_person_takes_control_plays_with_keys_and_releases(
    server: ServerProcess, demonstrations: tuple[str, Demonstrator], tmp_path: Path
) -> None:
    page, demonstrator = demonstrations
    status, _, state = fetch(page, "api/control")
    assert status == 200 and state["enabled"] and not state["controlling"]
    status, _, state = fetch(page, "api/control", method="POST", body={"server": 0, "instance": 0})
    assert status == 200 and state["controlling"], state
    assert state["keys"] == ["ArrowLeft", "ArrowRight"]  # CartPole's Box(1,): the defaults
    fetch(page, "api/keys", method="POST", body={"held": ["ArrowLeft", "Escape"]})
    wait_until(lambda: demonstrator.episodes >= 1, "no episode was recorded")
    status, _, state = fetch(page, "api/keys", method="POST", body={"held": ["ArrowRight"]})
    assert status == 200 and state["held"] == ["ArrowRight"]  # a key outside the map is dropped
    pressed = state["episodes"]
    wait_until(lambda: demonstrator.episodes >= pressed + 2, "no episode with ArrowRight")
    status, _, state = fetch(page, "api/release", method="POST", body={})
    assert status == 200 and not state["controlling"] and state["error"] == ""
    first, *_, last = sorted(tmp_path.glob("episode-*.rlenv"))
    assert actions(first)[-1] == -1.0 and set(actions(first)) <= {0.0, -1.0}
    assert set(actions(last)) == {1.0}  # held all along
    assert EpisodeFile.load(last).target == TARGET
    assert replays_identically(first) and replays_identically(last)
    with Client(server.host, server.port) as trainer:  # control was given back
        trainer.reset()
        trainer.step(np.zeros(1, np.float32))


def test_control_is_refused_while_another_client_controls(
    server: ServerProcess, demonstrations: tuple[str, Demonstrator]
) -> None:
    page, demonstrator = demonstrations
    with Client(server.host, server.port) as trainer:
        trainer.reset()
        status, _, answer = fetch(
            page, "api/control", method="POST", body={"server": 0, "instance": 0}
        )
        assert status == 409 and "busy" in answer["error"]
        trainer.step(np.zeros(1, np.float32))  # still the trainer's
    status, _, answer = fetch(page, "api/keys", method="POST", body={"held": ["ArrowLeft"]})
    assert status == 409 and "take control first" in answer["error"]
    assert not demonstrator.status()["controlling"]


def test_control_routes_keep_the_inspectors_rules(
    server: ServerProcess, demonstrations: tuple[str, Demonstrator]
) -> None:
    page, demonstrator = demonstrations
    take = {"server": 0, "instance": 0}
    for headers in ({"Origin": "http://attacker.example"}, {"Host": "attacker.example"}):
        status, _, answer = fetch(page, "api/control", method="POST", body=take, headers=headers)
        assert status == 403 and "refused" in answer["error"]
    status, _, _ = fetch(
        page, "api/control", method="POST", body=take, headers={"Content-Type": "text/plain"}
    )  # a cross-site form's kind
    assert status == 415
    wrong_key = page.rstrip("/").rsplit("/", 1)[0] + "/wrong/"
    assert fetch(wrong_key, "api/control", method="POST", body=take)[0] == 403
    assert fetch(page, "api/control", method="POST", body={"server": -1, "instance": 0})[0] == 400
    assert fetch(page, "api/keys", method="POST", body={"held": "ArrowLeft"})[0] == 400
    assert not demonstrator.status()["controlling"]
    with Client(server.host, server.port) as trainer:  # nobody took control
        trainer.reset()


def test_without_a_directory_the_inspector_only_watches(server: ServerProcess) -> None:
    inspector = InspectorServer(Watcher([f"{server.host}:{server.port}"]))
    inspector.start()
    try:
        assert fetch(inspector.url, "api/control")[2] == {"enabled": False}
        status, _, answer = fetch(
            inspector.url, "api/control", method="POST", body={"server": 0, "instance": 0}
        )
        assert status == 404 and "--record-demonstrations" in answer["error"]
    finally:
        inspector.close()


# --- several agents: a person plays one, the others keep what drives them ---------------------

TIMED_PAIR = "heuristic_envs:TimedChasingPair"
FINDS_TEST_ENVS = {
    "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")])
}


@pytest.fixture
def pair_demonstrations(
    serve, tmp_path: Path, request: pytest.FixtureRequest
) -> Iterator[tuple[str, Demonstrator, ServerProcess]]:
    """An inspector on a TimedChasingPair server (its arguments: the test's parameter)."""
    server = serve(TIMED_PAIR, args=getattr(request, "param", []), env=FINDS_TEST_ENVS)
    watcher = Watcher([f"{server.host}:{server.port}"])
    demonstrator = Demonstrator(watcher, tmp_path, target=TIMED_PAIR, rate=200.0)
    inspector = InspectorServer(watcher, demonstrator=demonstrator)
    inspector.start()
    try:
        yield inspector.url, demonstrator, server
    finally:
        inspector.close()


def _actions_of(path: Path, agent: str) -> list[list[float]]:
    return [
        list(map(float, event[1][agent]))
        for event in EpisodeFile.load(path).snapshot["events"]
        if event[0] == "action" and agent in event[1]
    ]


def test_a_person_chooses_the_agent_to_play_and_the_other_plays_its_heuristic(
    pair_demonstrations: tuple[str, Demonstrator, ServerProcess], tmp_path: Path
) -> None:
    page, demonstrator, server = pair_demonstrations
    take = {"server": 0, "instance": 0}
    status, _, answer = fetch(page, "api/control", method="POST", body=take)
    assert (
        status == 422
        and answer["error"] == "this environment has 2 agents: choose the one to play (Red, Blue)"
    )
    status, _, answer = fetch(page, "api/control", method="POST", body={**take, "agent": "Green"})
    assert status == 404 and answer["error"] == "no agent 'Green'; the agents: Red, Blue"
    assert fetch(page, "api/control", method="POST", body={**take, "agent": 3})[0] == 400
    status, _, state = fetch(page, "api/control", method="POST", body={**take, "agent": "Red"})
    assert status == 200 and state["controlling"] and state["agent"] == "Red", state
    assert state["heuristic"] == ["Blue"]  # Blue's class has one: it plays it
    assert state["keys"] == ["ArrowDown", "ArrowLeft", "ArrowRight", "ArrowUp"]
    fetch(page, "api/keys", method="POST", body={"held": ["ArrowRight"]})
    wait_until(lambda: demonstrator.episodes >= 2, "no episode was recorded", seconds=60)
    status, _, state = fetch(page, "api/release", method="POST", body={})
    assert status == 200 and not state["controlling"] and state["error"] == ""
    recorded = sorted(tmp_path.glob("episode-*.rlenv"))[1]  # held ArrowRight all along
    episode = EpisodeFile.load(recorded)
    assert episode.agent == "Red" and episode.target == TIMED_PAIR
    assert episode.terminated or episode.truncated
    assert {tuple(action) for action in _actions_of(recorded, "Red")} == {(1.0, 0.0)}
    blue = _actions_of(recorded, "Blue")
    assert len({tuple(action) for action in blue}) > 1  # the heuristic's pushes, not one idle
    result = subprocess.run(
        [sys.executable, "-m", "rlenv", "replay", str(recorded)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, **FINDS_TEST_ENVS},
    )
    assert result.returncode == 0 and "every observation identical" in result.stdout, (
        result.stdout + result.stderr
    )
    with Client(server.host, server.port) as trainer:  # control was given back
        trainer.reset()


@pytest.mark.parametrize("pair_demonstrations", [["--policy", "Blue=heuristic"]], indirect=True)
def test_with_the_other_agent_driven_by_the_server_the_person_plays_the_one_left(
    pair_demonstrations: tuple[str, Demonstrator, ServerProcess], tmp_path: Path
) -> None:
    page, demonstrator, _ = pair_demonstrations
    take = {"server": 0, "instance": 0}
    status, _, answer = fetch(page, "api/control", method="POST", body={**take, "agent": "Blue"})
    assert status == 422 and answer["error"] == (
        "agent 'Blue' is driven by the server (rlenv serve --policy); choose another: Red"
    )
    status, _, state = fetch(page, "api/control", method="POST", body=take)  # the only one
    assert status == 200 and state["agent"] == "Red" and state["heuristic"] == []
    wait_until(lambda: demonstrator.episodes >= 1, "no episode was recorded", seconds=60)
    fetch(page, "api/release", method="POST", body={})
    (first, *_) = sorted(tmp_path.glob("episode-*.rlenv"))
    assert EpisodeFile.load(first).agent == "Red"
    assert {tuple(action) for action in _actions_of(first, "Red")} == {(0.0, 0.0)}  # idle
    assert len({tuple(action) for action in _actions_of(first, "Blue")}) > 1  # the server's


def test_a_person_plays_the_chaser_of_tag_while_both_runners_play_their_heuristic(
    serve, tmp_path: Path
) -> None:
    server = serve("examples.tag:TagEnvironment")
    watcher = Watcher([f"{server.host}:{server.port}"])
    demonstrator = Demonstrator(watcher, tmp_path, target="examples.tag:TagEnvironment", rate=200.0)
    inspector = InspectorServer(watcher, demonstrator=demonstrator)
    inspector.start()
    try:
        page = inspector.url
        status, _, answer = fetch(
            page, "api/control", method="POST", body={"server": 0, "instance": 0}
        )
        assert status == 422 and answer["error"] == (
            "this environment has 3 agents: choose the one to play (Chaser, Runner1, Runner2)"
        )
        assert fetch(page, "api/servers")[2][0]["driven"] == []
        status, _, state = fetch(
            page, "api/control", method="POST", body={"server": 0, "instance": 0, "agent": "Chaser"}
        )
        assert status == 200 and state["agent"] == "Chaser", state
        assert state["heuristic"] == ["Runner1", "Runner2"]
        with Client(server.host, server.port) as observer:
            start = observer.observe()["agent"]["Runner1"][:2].copy()
            wait_until(
                lambda: not np.array_equal(observer.observe()["agent"]["Runner1"][:2], start),
                "Runner1 never ran",
            )
        fetch(page, "api/release", method="POST", body={})
    finally:
        inspector.close()
