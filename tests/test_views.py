"""Tree views: queries over the tree, bulk reads and writes."""

from __future__ import annotations

import pytest

from rlenv.node import Node
from rlenv.scene2d.physics import CollisionShape, Joint, PhysicsWorld, RigidBody, StaticBody
from rlenv.tree import SceneTree
from rlenv.views import View, view


@pytest.fixture
def arm(tree: SceneTree) -> Node:
    """Base (static) -> Upper -> Lower, two hinges, shapes on each body, a sensor group."""
    world = PhysicsWorld(gravity=(0, 0), name="World")
    base = StaticBody(name="Base")
    base.add_child(CollisionShape.circle(0.1, name="Mount"))
    upper = RigidBody(name="Upper", position=(0.5, 0))
    upper.add_child(CollisionShape.box(1.0, 0.1, mass=1.0, name="UpperShape"))
    lower = RigidBody(name="Lower", position=(1.5, 0))
    lower.add_child(CollisionShape.box(1.0, 0.1, mass=1.0, name="LowerShape"))
    tip = CollisionShape.circle(0.05, (0.5, 0), sensor=True, name="Tip")
    tip.add_to_group("sensors")
    lower.add_child(tip)
    upper.add_child(lower)
    base.add_child(upper)
    world.add_child(base)
    world.add_child(Joint.pivot("../Base", "../Base/Upper", (0, 0), name="Shoulder"))
    world.add_child(Joint.pivot("../Base/Upper", "../Base/Upper/Lower", (1, 0), name="Elbow"))
    tree.root.add_child(world)
    return world


def test_steps_chain_in_tree_order(arm: Node) -> None:
    root = view(arm)
    assert root.all.bodies.name == ["Base", "Upper", "Lower"]
    assert root.bodies.name == ["Base"]
    assert root.bodies.bodies.name == ["Upper"]
    assert root.bodies.bodies.bodies.name == ["Lower"]
    assert root.all.joints.name == ["Shoulder", "Elbow"]
    assert root.all.bodies.shapes.name == ["Mount", "UpperShape", "LowerShape", "Tip"]
    assert root.all.bodies["*er"].name == ["Upper", "Lower"]
    assert root.all.in_group("sensors").name == ["Tip"]
    assert root.all.bodies.where(lambda b: b.position.x > 1).name == ["Lower"]
    assert root.all.bodies.bodies.parent.name == ["Base", "Upper"]
    assert len(root.all) == 10 and arm in root.all
    assert repr(root.all.bodies) == "View[3|World.all.bodies]"
    assert root.all.bodies[0].name == "Base"


def test_bulk_reads_and_writes(arm: Node, tree: SceneTree) -> None:
    shapes = view(arm).all.shapes
    shapes.friction = 0.25
    assert [s.shape.friction for s in shapes] == [0.25] * 4
    bodies = view(arm).all.bodies.of_type(RigidBody)
    bodies.set("angular_velocity", [1.0, -2.0])
    assert bodies.angular_velocity == [1.0, -2.0]
    tree.paused = False
    tree.physics_tick()
    assert all(abs(w) > 0 for w in bodies.angular_velocity)  # the space saw the new values


def test_bad_bulk_operations_change_nothing(arm: Node) -> None:
    everything = view(arm).all
    with pytest.raises(AttributeError, match="no attribute 'position'"):
        everything.position  # noqa: B018 - the world node has no position
    before = view(arm).all.bodies.angle
    with pytest.raises(AttributeError, match="nothing was set"):
        everything.angle = 1.0  # shapes and joints have no angle
    assert view(arm).all.bodies.angle == before
    with pytest.raises(ValueError, match="2 values for the 3 nodes"):
        view(arm).all.bodies.set("angle", [0.0, 1.0])
    with pytest.raises(AttributeError, match="read-only"):
        everything._nodes = ()


def test_an_empty_view_is_harmless() -> None:
    empty = View([])
    assert len(empty) == 0 and empty.all.bodies.name == []
    empty.anything = 1  # sets nothing, as there is nothing


def test_overlapping_views_hold_each_node_once_in_tree_order() -> None:
    root, upper, lower, leaf = Node("Root"), Node("Upper"), Node("Lower"), Node("Leaf")
    root.add_child(upper)
    upper.add_child(lower)
    lower.add_child(leaf)
    assert list(view(lower, upper, lower).all) == [upper, lower, leaf]


def test_the_old_import_path_warns_and_the_package_names_do_not() -> None:
    import importlib
    import sys
    import warnings

    import rlenv

    sys.modules.pop("rlenv.scene2d.views", None)
    with pytest.warns(DeprecationWarning, match="rlenv.scene2d.views moved to rlenv.views"):
        old = importlib.import_module("rlenv.scene2d.views")
    assert old.View is View and old.view is view
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert rlenv.View is View and rlenv.view is view
