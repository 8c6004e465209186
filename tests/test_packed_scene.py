"""PackedScene: subtrees as plain data and back, and data that must never run code."""

from __future__ import annotations

import math
import subprocess
import sys
from typing import Any

import msgpack
import pymunk
import pytest

from rlenv import (
    CollisionShape,
    Joint,
    Marker2D,
    Node,
    Node2D,
    PackedScene,
    PackedSceneError,
    PhysicsWorld,
    ProcessMode,
    RigidBody,
    Signal,
    StaticBody,
    gradient,
)
from rlenv.tree import SceneTree


class Peg(StaticBody):
    """A user's class: its own constructor arguments and attributes."""

    hit = Signal("by")
    constructed = 0

    def __init__(self, radius: float, label: str) -> None:
        Peg.constructed += 1
        super().__init__(name="Peg")
        self.radius = radius
        self.label = label
        self.tint = (1, 2, 3)
        self.scores = {"a": [1, 2], "b": None}
        self.skin = CollisionShape.circle(radius, friction=0.25, color="gold", name="Skin")
        self.add_child(self.skin)
        self.times_hit = 0
        self.skin.collision_started.connect(self.on_touched)

    def on_touched(self, other: CollisionShape) -> None:
        self.times_hit += 1


class Tally(Node):
    def __init__(self) -> None:
        super().__init__("Tally")
        self.count = 0

    def add(self, by: Any) -> None:
        self.count += 1


def through_msgpack(data: dict[str, Any]) -> dict[str, Any]:
    return msgpack.unpackb(msgpack.packb(data))


def level() -> Node2D:
    """Pegs on a lattice, a marker with a body on it, a jointed pair, a tally listening."""
    root = Node2D("Level", position=(0.5, 0.0), rotation=0.1)
    root.add_to_group("levels")
    root.add_child(Tally())
    pegs = Node2D("Pegs", position=(-2.0, 4.0))
    root.add_child(pegs)
    first = Peg(0.1, "first")
    pegs.add_child(first)
    row = first.lattice((1.0, 0.0), 4)
    row.shapes.set("color", gradient("purple", "blue", n_steps=4))
    first.hit.connect(root.get_node("Tally").add)
    mount = Marker2D("mount", position=(1.0, 1.0), rotation=math.pi / 3)
    root.add_child(mount)
    ball = RigidBody(name="Ball", position=(0.0, 0.5))
    ball.add_child(CollisionShape.poly([(0, 0), (0.3, 0), (0.3, 0.2), (0, 0.2)], mass=0.5))
    ball.velocity = (0.5, 0.0)
    mount.attach(ball)
    anchor = StaticBody(name="Anchor", position=(3.0, 3.0))
    anchor.add_child(CollisionShape.circle(0.05, sensor=True))
    bob = RigidBody(name="Bob", position=(4.0, 3.0))
    bob.add_child(CollisionShape.circle(0.2, density=3.0, elasticity=0.7))
    root.add_child(anchor)
    root.add_child(bob)
    root.add_child(Joint.pivot("../Anchor", "../Bob", (3.0, 3.0), max_force=1e4, name="Hinge"))
    root.add_child(Node("Idle", process_mode=ProcessMode.DISABLED))
    return root


def summary(root: Node) -> list[tuple[Any, ...]]:
    rows = []
    for node in root.iter_subtree():
        row: tuple[Any, ...] = (
            type(node).__name__,
            node.name,
            tuple(node.get_groups()),
            node.process_mode,
        )
        if isinstance(node, Node2D):
            row += (tuple(node.position), node.rotation)
        if isinstance(node, CollisionShape):
            row += (
                type(node.shape).__name__,
                node.shape.mass,
                node.friction,
                node.elasticity,
                node.sensor,
                node.color,
            )
        if isinstance(node, RigidBody):
            row += (tuple(node.velocity),)
        rows.append(row)
    return rows


def test_a_level_survives_msgpack_and_instantiates_alike(tree: SceneTree) -> None:
    original = level()
    scene = PackedScene.pack(original)
    data = scene.to_data()
    assert msgpack.unpackb(msgpack.packb(data)) == data  # plain msgpack types only
    assert data["root"]["class"] == "Node2D"
    classes = {entry["class"] for entry in _entries(data["root"])}
    assert {"Peg", "Marker2D", "RigidBody", "StaticBody", "Joint", "Tally"} <= classes
    constructed = Peg.constructed
    built = PackedScene.from_data(through_msgpack(data), allowed=(Peg, Tally)).instantiate()
    assert Peg.constructed == constructed  # built from data, not by running the class's code
    assert summary(built) == summary(original)
    peg = built.get_node("Pegs/Peg3")
    assert isinstance(peg, Peg) and peg.label == "first" and peg.tint == (1, 2, 3)
    assert peg.scores == {"a": [1, 2], "b": None} and peg.skin is peg.get_node("Skin")
    assert peg.skin.collision_started.is_connected(peg.on_touched)
    first = built.get_node("Pegs/Peg")
    assert first.hit.is_connected(built.get_node("Tally").add)
    assert PackedScene.pack(built).to_data() == data  # nothing lost on the way


def test_instances_simulate_as_the_original(tree: SceneTree) -> None:
    """Packed from a fresh build, both worlds run bit for bit alike."""
    scene = PackedScene.pack(level())
    worlds = []
    for source in (level(), scene.instantiate()):
        world = PhysicsWorld(gravity=(0.0, -9.81), name=f"World{len(worlds)}")
        tree.root.add_child(world)
        world.add_child(source)
        worlds.append(world)
    tree.paused = False
    for _ in range(120):
        tree.physics_tick()
    states = [[(*b.position, *b.velocity, b.angle) for b in world.space.bodies] for world in worlds]
    assert states[0] == states[1]
    hinges = [world.get_node("Level/Hinge") for world in worlds]
    assert all(h.constraint.b is h.get_node("../Bob").body for h in hinges)


def test_a_world_keeps_its_contact_monitor_through_a_packed_scene() -> None:
    for monitor in (True, False):
        world = PhysicsWorld(gravity=(0.0, 0.0), contact_monitor=monitor, name="World")
        data = through_msgpack(PackedScene.pack(world).to_data())
        built = PackedScene.from_data(data).instantiate()
        assert isinstance(built, PhysicsWorld) and built.contact_monitor is monitor
    root = data["root"]
    refused = {**data, "root": {**root, "properties": {**root["properties"], "contact_monitor": 1}}}
    with pytest.raises(PackedSceneError, match="contact_monitor"):
        PackedScene.from_data(refused)


def test_instances_share_nothing(tree: SceneTree) -> None:
    scene = PackedScene.pack(level())
    first, second = scene.instantiate(), scene.instantiate()
    ours = [
        {
            id(getattr(n, a))
            for n in root.iter_subtree()
            for a in ("body", "shape")
            if isinstance(getattr(n, a, None), pymunk.Body | pymunk.Shape)
        }
        for root in (first, second)
    ]
    assert ours[0] and not ours[0] & ours[1]
    first.get_node("Pegs/Peg").scores["a"].append(3)
    assert second.get_node("Pegs/Peg").scores["a"] == [1, 2]


def test_pack_captures_the_subtree_as_it_is_now(tree: SceneTree) -> None:
    world = PhysicsWorld(gravity=(0.0, -9.81))
    tree.root.add_child(world)
    original = level()
    world.add_child(original)
    tree.paused = False
    for _ in range(30):
        tree.physics_tick()
    bob = original.get_node("Bob")
    scene = PackedScene.pack(original)
    then = (tuple(bob.position), tuple(bob.velocity))
    for _ in range(30):
        tree.physics_tick()
    copy = scene.instantiate().get_node("Bob")
    assert tuple(copy.position) == pytest.approx(then[0])
    assert tuple(copy.velocity) == pytest.approx(then[1])
    assert tuple(bob.position) != then[0]


def test_a_class_it_was_not_allowed_is_refused(tree: SceneTree) -> None:
    data = through_msgpack(PackedScene.pack(level()).to_data())
    with pytest.raises(PackedSceneError, match=r"Level/Tally: class 'Tally' is not allowed"):
        PackedScene.from_data(data)
    with pytest.raises(PackedSceneError, match=r"Level/Pegs/Peg: class 'Peg' is not allowed"):
        PackedScene.from_data(data, allowed=(Tally,))
    forged = {
        "format": "rlenv.PackedScene",
        "version": 1,
        "root": {"class": "os.system", "name": "Evil", "attributes": {"cmd": "true"}},
    }
    with pytest.raises(PackedSceneError, match="'os.system' is not allowed"):
        PackedScene.from_data(forged)
    with pytest.raises(TypeError, match="not a Node class"):
        PackedScene.from_data(data, allowed=(dict,))  # type: ignore[arg-type]


def test_data_never_imports_a_module() -> None:
    """In a fresh interpreter: data naming classes of modules not loaded loads none of them."""
    script = """
import sys
from rlenv import PackedScene, PackedSceneError
before = set(sys.modules)
for name in ("xml.dom.minidom:Node", "tkinter.Tk", "http.server.HTTPServer", "Popen"):
    data = {"format": "rlenv.PackedScene", "version": 1, "root": {"class": name, "name": "x"}}
    try:
        PackedScene.from_data(data)
    except PackedSceneError:
        pass
    else:
        raise SystemExit("accepted " + name)
new = {m for m in set(sys.modules) - before if m.split(".")[0] in ("xml", "tkinter", "http")}
print(sorted(new))
"""
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=True
    )
    assert result.stdout.strip() == "[]"


def _node(**entry: Any) -> dict[str, Any]:
    return {
        "format": "rlenv.PackedScene",
        "version": 1,
        "root": {"class": "Node2D", "name": "Root", **entry},
    }


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ([], "a map with exactly"),
        ({"format": "rlenv.PackedScene", "version": 2, "root": {}}, "version 1"),
        (_node(extra=1), "a node has no 'extra'"),
        (_node(name="a/b"), "contains"),
        (_node(properties={"position": [1, "x"]}), "position must be a number"),
        (_node(properties={"position": [1, math.nan]}), "position must be a number finite"),
        (_node(properties={"speed": 1}), "no property 'speed'"),
        (
            _node(children=[{"class": "Node", "name": "A"}, {"class": "Node", "name": "A"}]),
            "two children named 'A'",
        ),
        (
            _node(
                children=[
                    {
                        "class": "CollisionShape",
                        "name": "S",
                        "properties": {
                            "shape": {"kind": "poly", "vertices": [[0, 0], [1, 1], [1, 0], [0, 1]]}
                        },
                    }
                ]
            ),
            "counter-clockwise round a convex polygon",
        ),
        (
            _node(
                children=[
                    {
                        "class": "CollisionShape",
                        "name": "S",
                        "properties": {"shape": {"kind": "spline"}},
                    }
                ]
            ),
            "shape kind 'spline'",
        ),
        (
            _node(
                children=[
                    {
                        "class": "Joint",
                        "name": "J",
                        "properties": {"a": "A", "b": "B", "constraint": {"kind": "rope"}},
                    }
                ]
            ),
            "constraint kind 'rope'",
        ),
        (
            _node(children=[{"class": "RigidBody", "name": "B", "properties": {"mass": -1}}]),
            "mass must be",
        ),
        (_node(attributes={"_parent": None}), "not an attribute a scene may set"),
        (_node(attributes={"__class__": "x"}), "not an attribute a scene may set"),
        (_node(attributes={"lattice": 1}), "would hide Node2D.lattice"),
        (_node(attributes={"x": {1, 2}}), "holds a set"),
        (_node(nodes={"other": "../Elsewhere"}), "not a node of the scene"),
        (_node(connections=[["renamed", ".", "queue_freee", False]]), "has no method"),
        (_node(connections=[["no_such", ".", "queue_free", False]]), "has no signal"),
        (_node(connections=[["renamed", ".", "__init__", False]]), "not a method name"),
    ],
)
def test_malformed_data_is_refused_precisely(data: Any, match: str) -> None:
    with pytest.raises(PackedSceneError, match=match):
        PackedScene.from_data(data)


def test_deep_nesting_is_refused_without_recursing_forever() -> None:
    entry: dict[str, Any] = {"class": "Node", "name": "N"}
    for _ in range(400):
        entry = {"class": "Node", "name": "N", "children": [entry]}
    with pytest.raises(PackedSceneError, match="nested more than"):
        PackedScene.from_data({"format": "rlenv.PackedScene", "version": 1, "root": entry})


def test_what_cannot_be_data_is_refused_when_packing() -> None:
    crank = Node2D("Crank")
    crank.add_child(StaticBody(name="A"))
    crank.add_child(RigidBody(name="B"))
    crank.add_child(Joint("../A", "../B", lambda a, b: pymunk.PinJoint(a, b), name="Pin"))
    with pytest.raises(PackedSceneError, match="Joint 'Pin': .* factory function"):
        PackedScene.pack(crank)
    holder = Node("Holder")
    holder.outside = Node("Outside")  # type: ignore[attr-defined]
    with pytest.raises(PackedSceneError, match="outside the packed subtree"):
        PackedScene.pack(holder)
    holder.outside = open  # type: ignore[attr-defined]
    with pytest.raises(PackedSceneError, match="holds a builtin_function_or_method"):
        PackedScene.pack(holder)


def test_godot_spelling_and_empty_scenes() -> None:
    scene = PackedScene()
    with pytest.raises(RuntimeError, match="empty"):
        scene.instantiate()
    assert scene.pack(Node2D("Thing", position=(1.0, 2.0))) is scene
    assert tuple(scene.instantiate().position) == (1.0, 2.0)
    assert "Node2D 'Thing'" in repr(scene)


def _entries(entry: dict[str, Any]) -> list[dict[str, Any]]:
    found = [entry]
    for child in entry.get("children", []):
        found += _entries(child)
    return found
