"""Node.duplicate: Godot's deep copy of a subtree, with its own pymunk objects."""

from __future__ import annotations

import copy

import pymunk
import pytest

from rlenv import (
    Camera,
    CollisionShape,
    Joint,
    Node,
    Node2D,
    PhysicsWorld,
    ProcessMode,
    RigidBody,
    Signal,
    StaticBody,
)
from rlenv.tree import SceneTree


class Lamp(Node):
    """A node with plain attributes, references and a signal."""

    switched = Signal("on")

    def __init__(self, name: str = "Lamp") -> None:
        super().__init__(name)
        self.settings = {"colors": [[1, 2, 3]], "power": 40.0}
        self.history: list[bool] = []
        self.partner: Node | None = None
        self.outside: Node | None = None

    def record(self, on: bool) -> None:
        self.history.append(on)


def pymunk_objects(node: Node) -> set[int]:
    found = set()
    for member in node.iter_subtree():
        for attribute in ("body", "shape", "constraint", "space"):
            value = getattr(member, attribute, None)
            if isinstance(value, pymunk.Body | pymunk.Shape | pymunk.Constraint | pymunk.Space):
                found.add(id(value))
    return found


def pendulum(origin: tuple[float, float] = (0.0, 3.0)) -> Node2D:
    rig = Node2D("Rig", position=origin)
    rig.add_to_group("rigs")
    anchor = StaticBody(name="Anchor")
    anchor.add_child(CollisionShape.circle(0.05, sensor=True))
    bob = RigidBody(name="Bob", position=(1.0, 0.0))
    bob.add_child(
        CollisionShape.circle(
            0.1, mass=1.0, friction=0.9, elasticity=0.4, color="teal", name="Skin"
        )
    )
    rig.add_child(anchor)
    rig.add_child(bob)
    rig.add_child(Joint.pivot("../Anchor", "../Bob", (0.0, 0.0), name="Hinge"))
    return rig


def test_same_classes_names_groups_and_modes() -> None:
    root = pendulum()
    root.process_mode = ProcessMode.ALWAYS
    root.get_node("Bob").add_to_group("swinging")
    twin = root.duplicate()
    originals, copies = list(root.iter_subtree()), list(twin.iter_subtree())
    assert [type(n) for n in copies] == [type(n) for n in originals]
    assert [n.name for n in copies] == [n.name for n in originals]
    assert [n.get_groups() for n in copies] == [n.get_groups() for n in originals]
    assert twin.process_mode is ProcessMode.ALWAYS
    assert not set(map(id, copies)) & set(map(id, originals))
    assert twin.parent is None and not twin.is_inside_tree()
    assert twin.get_node("Bob/Skin").color == (0, 128, 128)


def test_plain_attributes_are_copied_deeply_never_shared() -> None:
    lamp = Lamp()
    twin = lamp.duplicate()
    assert twin.settings == lamp.settings and twin.settings is not lamp.settings
    assert twin.settings["colors"][0] is not lamp.settings["colors"][0]
    twin.settings["colors"][0].append(4)
    assert lamp.settings["colors"] == [[1, 2, 3]]


def test_references_and_connections_inside_point_to_the_copies() -> None:
    room = Node("Room")
    first, second = Lamp("First"), Lamp("Second")
    room.add_child(first)
    room.add_child(second)
    stranger = Lamp("Stranger")
    first.partner = second
    first.outside = stranger
    heard: list[bool] = []
    first.switched.connect(second.record)
    first.switched.connect(stranger.record)
    first.switched.connect(heard.append)  # a function (a bound list method) stays as it is
    second.switched.connect(first.record, one_shot=True)
    twin = room.duplicate()
    twin_first, twin_second = twin.get_node("First"), twin.get_node("Second")
    assert isinstance(twin_first, Lamp) and isinstance(twin_second, Lamp)
    assert twin_first.partner is twin_second
    assert twin_first.outside is stranger  # outside the subtree: kept, not copied
    twin_first.switched.emit(True)
    assert twin_second.history == [True] and second.history == []
    assert stranger.history == [True]  # Godot keeps connections to nodes outside
    assert heard == [True]
    twin_second.switched.emit(False)
    twin_second.switched.emit(False)
    assert twin_first.history == [False] and first.history == []  # one-shot stays one-shot


def test_physics_nodes_get_their_own_pymunk_objects(tree: SceneTree) -> None:
    world = PhysicsWorld(gravity=(0.0, -9.8), name="World")
    tree.root.add_child(world)
    rig = pendulum()
    world.add_child(rig)
    twin = rig.duplicate()
    assert not pymunk_objects(rig) & pymunk_objects(twin)
    world_twin = world.duplicate()
    assert world_twin.space is not world.space and list(world_twin.space.bodies) == []
    assert world_twin.gravity == world.gravity
    assert not pymunk_objects(world) & pymunk_objects(world_twin)
    skin, twin_skin = rig.get_node("Bob/Skin"), twin.get_node("Bob/Skin")
    assert isinstance(skin, CollisionShape) and isinstance(twin_skin, CollisionShape)
    for attribute in ("mass", "friction", "elasticity", "radius"):
        assert getattr(twin_skin.shape, attribute) == getattr(skin.shape, attribute)
    assert twin_skin.shape.body is None  # not attached until it enters a space


def test_a_copied_body_reads_and_pushes_its_own_body(tree: SceneTree) -> None:
    """The accessors' handle (taken once per body) is the copy's, in a space and out of one."""
    world = PhysicsWorld(gravity=(0.0, 0.0), name="World")
    tree.root.add_child(world)
    bob = RigidBody(name="Bob", position=(1.0, 0.0))
    bob.add_child(CollisionShape.circle(0.1, mass=1.0))
    world.add_child(bob)
    twin = bob.duplicate()
    twin.velocity = (3.0, 4.0)
    twin.angular_velocity = 2.0
    assert bob.body.velocity == (0.0, 0.0) and bob.body.angular_velocity == 0.0
    assert twin.body.velocity == (3.0, 4.0) and twin.velocity == (3.0, 4.0)
    twin.name = "Twin"
    world.add_child(twin)
    twin.apply_central_force((10.0, 0.0))
    assert twin.body.force == (10.0, 0.0) and bob.body.force == (0.0, 0.0)
    tree.physics_tick()
    assert bob.position == (1.0, 0.0) and bob.rotation == 0.0
    assert twin.position == twin.body.position != (1.0, 0.0)
    assert twin.rotation == twin.body.angle != 0.0


def test_a_joint_between_copied_bodies_joins_the_copies(tree: SceneTree) -> None:
    world = PhysicsWorld(gravity=(0.0, -9.8), name="World")
    tree.root.add_child(world)
    rig = pendulum(origin=(0.0, 3.0))
    world.add_child(rig)
    twin = rig.duplicate()
    twin.position = (5.0, 3.0)
    world.add_child(twin)
    hinge = twin.get_node("Hinge")
    assert isinstance(hinge, Joint) and hinge.constraint is not None
    assert hinge.constraint.a is twin.get_node("Anchor").body
    assert hinge.constraint.b is twin.get_node("Bob").body
    assert rig.get_node("Hinge").constraint.a is rig.get_node("Anchor").body
    # both swing about their own hinge, the same way
    tree.paused = False
    for _ in range(25):  # a quarter swing or so: near the bottom
        tree.physics_tick()
    bob, twin_bob = rig.get_node("Bob"), twin.get_node("Bob")
    assert twin_bob.body.position.x - 5.0 == pytest.approx(bob.body.position.x, abs=1e-9)
    assert twin_bob.body.position.y == pytest.approx(bob.body.position.y, abs=1e-9)
    assert bob.body.position.y < 2.5  # it swung


def test_a_copy_simulates_as_a_freshly_built_node(tree: SceneTree) -> None:
    """A body copied mid-flight starts where the original is now; with the same velocity
    both then move identically, bit for bit, in two separate worlds."""
    worlds = []
    for name in ("A", "B"):
        world = PhysicsWorld(gravity=(0.0, -9.8), name=name)
        tree.root.add_child(world)
        worlds.append(world)
    crate = RigidBody(name="Crate", position=(0.0, 5.0), angle=0.4)
    crate.add_child(CollisionShape.box(1.0, 0.5, density=2.0))
    worlds[0].add_child(crate)
    tree.paused = False
    for _ in range(10):
        tree.physics_tick()
    twin = crate.duplicate()
    assert tuple(twin.position) == tuple(crate.position) and twin.angle == crate.angle
    assert twin.velocity == crate.velocity
    worlds[0].remove_child(crate)  # both now alone in a fresh world of their own
    fresh = PhysicsWorld(gravity=(0.0, -9.8), name="C")
    tree.root.add_child(fresh)
    fresh.add_child(crate)
    worlds[1].add_child(twin)
    for _ in range(50):
        tree.physics_tick()
    assert (*crate.body.position, crate.body.angle) == (*twin.body.position, twin.body.angle)


def test_copies_become_ready_when_they_enter(tree: SceneTree, log: list) -> None:
    class Noted(Node):
        def _ready(self) -> None:
            log.append(self.name)

    tree.root.add_child(Noted("Original"))
    twin = tree.root.get_node("Original").duplicate()
    assert not twin.is_node_ready() and log == ["Original"]
    twin.name = "Twin"
    tree.root.add_child(twin)
    assert log == ["Original", "Twin"]


def test_deepcopy_is_duplicate_and_freed_nodes_refuse() -> None:
    rig = pendulum()
    twin = copy.deepcopy(rig)
    assert isinstance(twin, Node2D) and twin is not rig
    assert not pymunk_objects(rig) & pymunk_objects(twin)
    rig.queue_free()
    with pytest.raises(ValueError, match="freed"):
        rig.duplicate()


def test_a_recording_camera_copy_does_not_film() -> None:
    camera = Camera(size=(8, 8))
    camera._recorder = object()  # type: ignore[assignment] # as if recording
    camera.set_physics_process(True)
    twin = camera.duplicate()
    assert not twin.recording and not twin.is_physics_processing()
