"""Remote introspection: the node tree and exported properties over the protocol."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import Serve

from rlenv_client import Client, ErrorCode, RemoteError

POLE = "World/Physics/Pole"


def test_the_tree_lists_nodes_types_and_exported_values(client: Client) -> None:
    client.reset(seed=0)
    nodes = {node["path"]: node for node in client.tree()}
    assert nodes["/root/CartPole"]["type"] == "CartPoleEnvironment"
    assert nodes["/root/CartPole"]["exported"] == {"repeat_action": 4, "real_time": False}
    assert nodes["/root/CartPole"]["read_only"] == ["real_time"]  # set by config only
    pole = nodes["/root/CartPole/World/Physics/Pole"]
    assert pole["type"] == "RigidBody"
    assert set(pole["exported"]) == {"position", "velocity", "angle", "angular_velocity"}
    assert nodes["/root/CartPole/World/Physics"]["exported"]["gravity"] == [0.0, -9.81]
    assert nodes["/root/CartPole/Agent"]["exported"]["max_force"] == 10.0
    assert pole["read_only"] == []


def test_get_and_set_reach_the_simulation(client: Client) -> None:
    observation, _ = client.reset(seed=0)
    assert client.get_property(POLE, "angle") == pytest.approx(-float(observation[2]))
    client.set_property(POLE, "angular_velocity", 3)  # an int may set a float
    assert client.get_property("/root/CartPole/" + POLE, "angular_velocity") == 3.0
    assert client.observe()["agent"][4] == pytest.approx(-3.0)
    client.set_property("World/Physics", "gravity", [0, 0])
    client.set_property(POLE, "angular_velocity", 0.0)
    client.set_property("World/Physics/Cart", "velocity", [0.0, 0.0])
    client.set_property(POLE, "velocity", [0.0, 0.0])
    before = client.observe()["agent"]
    after, *_ = client.step(np.zeros(1, np.float32))
    assert after[2] == pytest.approx(before[2], abs=1e-6)  # no gravity: the pole stays put


def test_bad_inspection_gets_precise_errors_and_changes_nothing(client: Client) -> None:
    client.reset(seed=0)
    before = client.observe()["agent"].tobytes()
    for call, words in [
        (lambda: client.get_property("World/Nowhere", "angle"), "no node at path 'World/Nowhere'"),
        (lambda: client.get_property(POLE, "mass"), "exports no 'mass'; it exports position"),
        (lambda: client.set_property(POLE, "angle", "steep"), "RigidBody.angle must be a float"),
        (
            lambda: client.set_property(POLE, "position", [1.0, 2.0, 3.0]),
            "must be a list of 2 numbers like",
        ),
        (lambda: client.set_property(POLE, "angle", True), "must be a float like"),
        (
            lambda: client.set_property("World/Physics/Pole/Stick", "sensor", 1),
            "must be a bool like",
        ),
        (lambda: client._call(inspect={"delete": {}}), "inspect must be one of"),
        (lambda: client._call(inspect={"get": {"path": POLE}}), "takes exactly"),
        (lambda: client._call(inspect={"stats": {"since": -1}}), "since must be an integer"),
        (lambda: client._call(inspect={"stats": {"from": 1}}), "takes exactly"),
        (lambda: client._call(inspect={"node": {}}), "takes exactly"),
        (lambda: client._call(inspect={"configure": {"robot": {}}}), "takes exactly"),
        (lambda: client._call(observation={"draw": {"width": 3}}), "draw takes an empty map"),
    ]:
        with pytest.raises(RemoteError) as error:
            call()
        assert error.value.code == ErrorCode.BAD_REQUEST
        assert words in error.value.message
    with pytest.raises(RemoteError, match="max_force must be a float") as error:
        client.inspect_configure(agent={"max_force": "x"})
    assert error.value.code == ErrorCode.INVALID_CONFIG
    assert client.observe()["agent"].tobytes() == before


def test_an_observer_edits_while_the_controller_steps(server: object, client: Client) -> None:
    client.reset(seed=0)
    with Client(server.host, server.port) as other:  # type: ignore[attr-defined]
        assert isinstance(other.get_property(POLE, "angle"), float)
        assert len(other.tree()) > 5
        other.set_property(POLE, "angular_velocity", 2.5)  # an inspector's edit
        other.inspect_configure(world={"gravity": [0.0, -20.0]})
        with pytest.raises(RemoteError) as error:  # stepping stays the controller's
            other.reset(seed=1)
        assert error.value.code == ErrorCode.BUSY
    assert client.observe()["agent"][4] == pytest.approx(-2.5)
    events = client.snapshot()["events"]
    assert events[-2:] == [
        ["set", POLE, "angular_velocity", 2.5],
        ["config", {"world": {"gravity": [0.0, -20.0]}}],
    ]
    observation, _ = client.reset(seed=0)  # the set lasted its episode; the setting stays
    assert abs(observation[4]) < 0.05  # a fresh start, not the set
    assert client.get_property("World/Physics", "gravity") == [0.0, -20.0]
    assert client.snapshot()["config"]["world"]["gravity"] == [0.0, -20.0]


def test_a_setting_changed_by_an_inspector_changes_the_physics_at_once(client: Client) -> None:
    client.reset(seed=0)
    client.inspect_configure(world={"gravity": [0.0, 0.0]})
    for name in ("Cart", "Pole"):
        client.set_property(f"World/Physics/{name}", "velocity", [0.0, 0.0])
    client.set_property(POLE, "angular_velocity", 0.0)
    before = client.observe()["agent"]
    after, *_ = client.step(np.zeros(1, np.float32))
    assert after[2] == pytest.approx(before[2], abs=1e-6)  # no gravity: the pole stays put


def test_node_gives_one_entry_of_the_tree(client: Client) -> None:
    client.reset(seed=0)
    tree = {node["path"]: node for node in client.tree()}
    for path in ("World", "Agent", "", "World/Physics/Pole"):
        entry = client.node(path or "/root/CartPole")
        assert entry == tree[entry["path"]]
    assert client.node("World")["config"] == "world"
    assert "gravity" in client.node("World")["configurable"]
    assert client.node("Agent")["config"] == "agent"
    assert "config" not in client.node("World/Physics")  # a set lasts one episode there
    with pytest.raises(RemoteError, match="no node at path 'Nowhere'"):
        client.node("Nowhere")


def test_snapshots_reproduce_properties_set_during_the_episode(serve: Serve) -> None:
    first, second = serve(), serve()
    with Client(first.host, first.port) as a, Client(second.host, second.port) as b:
        a.reset(seed=4)
        a.step(np.zeros(1, np.float32), 1)
        a.set_property(POLE, "angular_velocity", -1.5)
        a.step(np.zeros(1, np.float32), 1)
        snapshot = a.snapshot()
        assert snapshot["events"][1][0] == "set"
        b.restore(snapshot)
        for _ in range(5):
            x, y = a.step(np.zeros(1, np.float32), 1), b.step(np.zeros(1, np.float32), 1)
            assert x[0].tobytes() == y[0].tobytes()


def _trajectory(client: Client, steps: int = 6) -> list[bytes]:
    pushes = np.linspace(-1.0, 1.0, steps, dtype=np.float32).reshape(steps, 1)
    return [client.step(push, 2)[0].tobytes() for push in pushes]


def test_a_reset_undoes_every_set_so_a_seed_gives_one_episode(serve: Serve) -> None:
    """Sets last for their episode: the same seed gives the same episode on any server,
    whatever was set before, and a snapshot taken after the reset restores that episode."""
    first, second = serve(), serve()
    with Client(first.host, first.port) as a, Client(second.host, second.port) as b:
        b.reset(seed=9)
        expected = _trajectory(b)
        a.reset(seed=0)
        a.set_property("World/Physics", "gravity", [0, -1])  # in an earlier episode
        a.reset(seed=9)
        assert a.get_property("World/Physics", "gravity") == [0.0, -9.81]
        a.set_property("World/Physics", "gravity", [0, -1])  # during one
        a.set_property("World/Physics", "gravity", [0, -2])
        a.set_property("Agent", "max_force", 3.0)
        a.reset(seed=9)
        assert a.get_property("World/Physics", "gravity") == [0.0, -9.81]
        assert a.get_property("Agent", "max_force") == 10.0
        snapshot = a.snapshot()
        assert _trajectory(a) == expected
        b.restore(snapshot)
        assert _trajectory(b) == expected


def test_a_configured_property_outlives_a_set_of_it(client: Client) -> None:
    """``config`` persists across resets; a set of a configured property lasts one episode."""
    client.configure(agent={"max_force": 5.0})
    client.reset(seed=0)
    client.set_property("Agent", "max_force", 2.0)
    client.reset(seed=0)
    assert client.get_property("Agent", "max_force") == 5.0
    client.set_property("Agent", "max_force", 2.0)
    client.configure(agent={"max_force": 7.0})  # the configuration's from now on
    client.reset(seed=0)
    assert client.get_property("Agent", "max_force") == 7.0


def test_restoring_a_snapshot_with_sets_twice_gives_one_trajectory(client: Client) -> None:
    client.reset(seed=2)
    client.step(np.full(1, 0.3, np.float32), 2)
    client.set_property("World/Physics", "gravity", [0, -1])
    client.step(np.full(1, -0.3, np.float32), 2)
    snapshot = client.snapshot()
    original = _trajectory(client)
    client.restore(snapshot)
    first = _trajectory(client)
    client.set_property("World/Physics", "gravity", [0, -30])  # what the next restore must undo
    client.restore(snapshot)
    assert _trajectory(client) == first == original


def test_a_restore_whose_set_is_refused_changes_nothing(client: Client) -> None:
    client.reset(seed=1)
    client.step(np.zeros(1, np.float32), 2)
    snapshot = client.snapshot()
    before = client.observe()["agent"].tobytes()
    bad = {**snapshot, "events": [*snapshot["events"], ["set", "World/Physics", "gravity", "down"]]}
    with pytest.raises(RemoteError) as error:
        client.restore(bad)
    assert error.value.code == ErrorCode.BAD_REQUEST
    assert "restore: events[1]: inspect: PhysicsWorld.gravity must be a list" in error.value.message
    assert client.observe()["agent"].tobytes() == before
    client.step(np.zeros(1, np.float32), 2)  # the episode goes on


def test_a_set_refused_during_the_replay_needs_a_reset(client: Client) -> None:
    """A node the episode builds is checked when the replay sets it: too late to change
    nothing, so the answer says the episode needs a reset."""
    client.reset(seed=1)
    snapshot = client.snapshot()
    client._call(inspect={"set": {"path": "World/Physics", "property": "gravity", "value": [0, 0]}})
    bad = {**snapshot, "events": [["set", "World/Physics/Spawned", "angle", 1.0]]}
    with pytest.raises(RemoteError) as error:
        client.restore(bad)
    assert error.value.code == ErrorCode.BAD_REQUEST
    assert error.value.message.startswith(
        "restore: events[0]: inspect: no node at path 'World/Physics/Spawned'"
    )
    assert error.value.message.endswith("reset required")
    with pytest.raises(RemoteError) as refused:
        client.step(np.zeros(1, np.float32))
    assert refused.value.code == ErrorCode.RESET_REQUIRED
    assert refused.value.message == "a restore failed part way; reset first"
    client.reset(seed=1)
    assert client.get_property("World/Physics", "gravity") == [0.0, -9.81]
