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
    pole = nodes["/root/CartPole/World/Physics/Pole"]
    assert pole["type"] == "RigidBody"
    assert set(pole["exported"]) == {"position", "velocity", "angle", "angular_velocity"}
    assert nodes["/root/CartPole/World/Physics"]["exported"]["gravity"] == [0.0, -9.81]
    assert nodes["/root/CartPole/Agent"]["exported"]["max_force"] == 10.0


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
        (lambda: client.set_property(POLE, "position", [1.0, 2.0, 3.0]),
         "must be a list of 2 numbers like"),
        (lambda: client.set_property(POLE, "angle", True), "must be a float like"),
        (lambda: client.set_property("World/Physics/Pole/Stick", "sensor", 1),
         "must be a bool like"),
        (lambda: client._call(inspect={"delete": {}}), "inspect must be one of"),
        (lambda: client._call(inspect={"get": {"path": POLE}}), "takes exactly"),
    ]:
        with pytest.raises(RemoteError) as error:
            call()
        assert error.value.code == ErrorCode.BAD_REQUEST
        assert words in error.value.message
    assert client.observe()["agent"].tobytes() == before


def test_only_the_controller_sets(server: object, client: Client) -> None:
    client.reset(seed=0)
    with Client(server.host, server.port) as other:  # type: ignore[attr-defined]
        assert isinstance(other.get_property(POLE, "angle"), float)  # reading is open
        assert len(other.tree()) > 5
        with pytest.raises(RemoteError) as error:
            other.set_property(POLE, "angle", 0.5)
        assert error.value.code == ErrorCode.BUSY


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
