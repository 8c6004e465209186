"""Snapshots as data: taken mid-episode, restored anywhere, stepping on bit for bit."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from conftest import Serve

from examples.cartpole import TARGET
from examples.pair import NAMES, chase
from rlenv.serving import _snapshots as snapshots
from rlenv_client import Client, ErrorCode, LocalClient, RemoteError

CARTPOLE_ACTIONS = [np.array([0.4 * np.sin(t / 2.0)], np.float32) for t in range(60)]


def steps(client: Client, actions: list[Any], repeat: int | None = None) -> list[tuple]:
    seen = []
    for action in actions:
        observation, reward, terminated, truncated, info = client.step(action, repeat)
        seen.append((observation.tobytes(), reward, terminated, truncated, info["frames"]))
        if terminated or truncated:
            break
    return seen


def test_a_snapshot_restored_in_another_server_steps_on_identically(serve: Serve) -> None:
    first, second = serve(), serve()
    with Client(first.host, first.port) as original, Client(second.host, second.port) as copy:
        original.configure(agent={"max_force": 12.0}, repeat_action=3)
        original.reset(seed=21)
        steps(original, CARTPOLE_ACTIONS[:7])
        snapshot = original.snapshot()
        copy.configure(agent={"max_force": 1.0})  # other settings, overridden by the snapshot
        copy.reset(seed=99)
        steps(copy, CARTPOLE_ACTIONS[:3])
        restored, _ = copy.restore(snapshot)
        assert restored.tobytes() == original.observe()["agent"].tobytes()
        assert copy.snapshot() == snapshot  # the restored state is the same state
        assert steps(copy, CARTPOLE_ACTIONS[7:]) == steps(original, CARTPOLE_ACTIONS[7:])


def test_a_snapshot_restored_in_the_same_server_rewinds(client: Client) -> None:
    client.reset(seed=5)
    steps(client, CARTPOLE_ACTIONS[:4])
    snapshot = client.snapshot()
    later = steps(client, CARTPOLE_ACTIONS[4:20], repeat=2)
    client.restore(snapshot)
    assert steps(client, CARTPOLE_ACTIONS[4:20], repeat=2) == later


def test_snapshots_survive_mid_episode_configuration(client: Client) -> None:
    client.reset(seed=8)
    steps(client, CARTPOLE_ACTIONS[:3], repeat=1)
    client.configure(agent={"max_force": 5.0})
    steps(client, CARTPOLE_ACTIONS[3:6], repeat=1)
    snapshot = client.snapshot()
    assert [event[0] for event in snapshot["events"]] == ["action"] * 3 + ["config"] + [
        "action"
    ] * 3
    after = steps(client, CARTPOLE_ACTIONS[6:15], repeat=1)
    assert len(after) == 9
    client.configure(agent={"max_force": 10.0})
    client.restore(snapshot)
    assert steps(client, CARTPOLE_ACTIONS[6:15], repeat=1) == after


def test_multi_agent_snapshots(serve: Serve) -> None:
    first, second = serve("examples.pair:PairEnvironment"), serve("examples.pair:PairEnvironment")
    with Client(first.host, first.port) as a, Client(second.host, second.port) as b:
        observation, _ = a.reset(seed=2)
        for _ in range(5):
            observation, *_ = a.step({n: chase(observation[n]) for n in NAMES})
        b.restore(a.snapshot())
        for _ in range(5):
            x, y = a.observe()["agent"], b.observe()["agent"]
            assert all(x[n].tobytes() == y[n].tobytes() for n in NAMES)
            actions = {n: chase(x[n]) for n in NAMES}
            assert a.step(actions)[1] == b.step(actions)[1]


def _tampered(snapshot: dict[str, Any], **changes: Any) -> dict[str, Any]:
    return {**snapshot, **changes}


def test_bad_snapshots_are_refused_and_change_nothing(client: Client) -> None:
    client.reset(seed=1)
    steps(client, CARTPOLE_ACTIONS[:3])
    good = client.snapshot()
    steps(client, CARTPOLE_ACTIONS[3:5])
    before = client.observe()["agent"].tobytes()
    evil_rng = json.dumps({"bit_generator": "os.system", "state": {}})
    cases = [
        ([1, 2, 3], ErrorCode.BAD_REQUEST, "must be a map"),
        (_tampered(good, version=2), ErrorCode.BAD_REQUEST, "version 2"),
        ({**good, "code": "import os"}, ErrorCode.BAD_REQUEST, "exactly the keys"),
        (_tampered(good, rng="__import__('os')"), ErrorCode.BAD_REQUEST, "invalid rng state"),
        (_tampered(good, rng=evil_rng), ErrorCode.BAD_REQUEST, "invalid rng state"),
        (_tampered(good, events=[["exec", "print(1)"]]), ErrorCode.BAD_REQUEST, "events[0]"),
        (
            _tampered(good, events=[["action", np.zeros(3, np.float32), 1]]),
            ErrorCode.INVALID_ACTION,
            "events[0]: action has shape (3,)",
        ),
        (_tampered(good, events=[["action", [0.1], 0]]), ErrorCode.BAD_REQUEST, "events[0]"),
        (_tampered(good, config={"agent": {"gravity": 1}}), ErrorCode.INVALID_CONFIG, "'gravity'"),
    ]
    for snapshot, code, words in cases:
        with pytest.raises(RemoteError) as error:
            client.restore(snapshot)  # type: ignore[arg-type]
        assert error.value.code == code, (words, error.value.message)
        assert words in error.value.message
        assert client.observe()["agent"].tobytes() == before  # nothing changed
    client.restore(good)


def test_snapshots_need_an_episode_and_go_alone(serve: Serve) -> None:
    server = serve()
    with Client(server.host, server.port) as client:
        with pytest.raises(RemoteError) as error:
            client.snapshot()
        assert error.value.code == ErrorCode.RESET_REQUIRED
        client.reset(seed=0)
        from rlenv.protocol import Request

        client.send_request(Request(0, {"snapshot": {}, "action": np.zeros(1, np.float32)}))
        with pytest.raises(RemoteError, match="snapshot goes alone"):
            client.step_result(client.receive_reply())


def test_a_snapshot_that_outlives_its_episode_needs_a_reset(client: Client) -> None:
    client.reset(seed=3)
    push = np.ones(1, np.float32)
    while not client.step(push)[2]:
        pass
    snapshot = client.snapshot()
    snapshot["events"].append(["action", [0.0], 1])  # an action after the pole fell
    with pytest.raises(RemoteError) as error:
        client.restore(snapshot)
    assert error.value.code == ErrorCode.ENVIRONMENT_ERROR
    assert "after its episode ended" in error.value.message
    client.reset(seed=3)


def test_the_log_of_an_endless_episode_stays_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    """Past MAX_EVENTS (lowered here to 5) the log forgets its events and snapshots are
    refused, so an episode that never ends does not grow the server's memory forever."""
    monkeypatch.setattr(snapshots, "MAX_EVENTS", 5)
    with LocalClient(TARGET) as local:
        local.configure(agent={"angle_limit": 1e9}, world={"track_limit": 1e9})  # endless
        local.reset(seed=1)
        for _ in range(5):
            local.step(np.zeros(1, np.float32))
        assert len(local.snapshot()["events"]) == 5
        local.step(np.zeros(1, np.float32))
        log = local.host.instances[0].log
        assert log.overflowed and log.events == []
        with pytest.raises(RemoteError, match="too long to snapshot: more than 5 actions") as error:
            local.snapshot()
        assert error.value.code == ErrorCode.BAD_REQUEST
        local.step(np.zeros(1, np.float32))  # the episode itself goes on
        assert log.events == []  # and its log stays empty
        local.reset(seed=1)
        local.step(np.zeros(1, np.float32))
        assert len(local.snapshot()["events"]) == 1


def test_a_snapshot_taken_after_one_agent_ended_restores() -> None:
    """The log holds the actions of the agents still in the episode; the replay takes them."""
    still = np.zeros(2, np.float32)
    with (
        LocalClient("examples.pair:PairEnvironment") as local,
        LocalClient("examples.pair:PairEnvironment") as other,
    ):
        observation, _ = local.reset(seed=2)
        info: dict[str, Any] = {"agents": {"Blue": {"terminated": False}}}
        for _ in range(300):  # Blue chases its apple, Red stands still
            if info["agents"]["Blue"]["terminated"]:
                break
            observation, _, _, _, info = local.step(
                {"Blue": chase(observation["Blue"]), "Red": still}
            )
        assert info["agents"]["Blue"]["terminated"] and not info["agents"]["Red"]["terminated"]
        red_only = {"Red": still}
        local.step(red_only)
        snapshot = local.snapshot()
        assert "Blue" not in snapshot["events"][-1][1]
        other.restore(snapshot)
        for _ in range(3):
            mine, theirs = local.step(red_only), other.step(red_only)
            assert all(mine[0][n].tobytes() == theirs[0][n].tobytes() for n in NAMES)
            assert mine[1:4] == theirs[1:4]


def test_a_snapshot_asking_for_real_time_is_refused(client: Client) -> None:
    client.reset(seed=2)
    snapshot = client.snapshot()
    snapshot["config"]["environment"]["real_time"] = True
    with pytest.raises(RemoteError, match="replay in lockstep") as error:
        client.restore(snapshot)
    assert error.value.code == ErrorCode.BAD_REQUEST
    assert client.get_property(".", "real_time") is False


def test_a_restore_answers_no_ticks_of_its_replay(client: Client) -> None:
    """The answer to a restore reports the request's own ticks, none: not the replay's."""
    client.reset(seed=0)
    client.step(np.zeros(1, np.float32), 2)
    client.step(np.zeros(1, np.float32), 4)
    snapshot = client.snapshot()
    answer = client._call(restore=snapshot)
    assert (answer.frames, answer.reward) == (0, 0.0)
    assert client.step(np.zeros(1, np.float32), 3)[4]["frames"] == 3


def test_a_snapshot_holds_the_configuration_of_the_reset_read_as_the_nodes_are_now() -> None:
    """Every reset captures the configuration cheaply (its map is made when a snapshot asks):
    a change of a node's configurable keys, or another world, is read at the next reset, and
    a value user code changes after the reset is not the snapshot's."""
    with LocalClient(TARGET) as local:
        instance = local.host.instances[0]
        world = instance.environment.world
        local.reset(seed=1)
        config = local.snapshot()["config"]
        assert (
            config
            == instance.settings.state()
            == {
                part: {key: getattr(nodes[0], key) for key in nodes[0].configurable}
                for part, nodes in (
                    ("environment", [instance.environment]),
                    ("agent", instance.agents),
                    ("world", [world]),
                )
            }
        )
        world.track_limit = 9.0  # user code, mid-episode: the episode began with 2.4
        assert local.snapshot()["config"]["world"]["track_limit"] == 2.4
        world.configurable = ("track_limit",)  # this node's own, from now on
        local.reset(seed=2)
        assert local.snapshot()["config"]["world"] == {"track_limit": 9.0}
        instance.environment.world = None  # no world: no part of the configuration
        assert set(instance.settings.state()) == {"environment", "agent"}
