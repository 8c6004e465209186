"""Node2D: local poses, global poses, and physics bodies placed through their frames."""

from __future__ import annotations

import math

import pytest

from rlenv import (
    Camera,
    CollisionShape,
    Joint,
    Marker2D,
    Node,
    Node2D,
    PhysicsWorld,
    RigidBody,
    StaticBody,
)
from rlenv.tree import SceneTree


@pytest.fixture
def world(tree: SceneTree) -> PhysicsWorld:
    world = PhysicsWorld(gravity=(0.0, -10.0), name="World")
    tree.root.add_child(world)
    return world


def ticks(tree: SceneTree, count: int) -> None:
    tree.paused = False
    for _ in range(count):
        tree.physics_tick()


def ball(name: str = "Ball", **kwargs: object) -> RigidBody:
    body = RigidBody(name=name, **kwargs)  # type: ignore[arg-type]
    body.add_child(CollisionShape.circle(0.2, mass=1.0))
    return body


def close(a: object, b: object) -> bool:
    return all(x == pytest.approx(y, abs=1e-12) for x, y in zip(a, b, strict=True))  # type: ignore[call-overload]


def test_poses_compose_down_the_tree() -> None:
    frame = Node2D("Frame", position=(10.0, 0.0), rotation=math.pi / 2)
    arm = Node2D("Arm", position=(2.0, 0.0), rotation=math.pi / 2)
    tip = Marker2D("Tip", position=(1.0, 0.0))
    frame.add_child(arm)
    arm.add_child(tip)
    assert arm.global_position == pytest.approx((10.0, 2.0))
    assert tip.global_position == pytest.approx((9.0, 2.0))
    assert tip.global_rotation == pytest.approx(math.pi)
    assert frame.to_global((1.0, 0.0)) == pytest.approx((10.0, 1.0))
    assert frame.to_local((10.0, 1.0)) == pytest.approx((1.0, 0.0))
    assert arm.to_local(tip.global_position) == pytest.approx(tip.position)
    # a plain node between two Node2Ds does not break the chain: the nearest Node2D counts
    holder = Node("Holder")
    frame.remove_child(arm)
    frame.add_child(holder)
    holder.add_child(arm)
    assert arm.global_position == pytest.approx((10.0, 2.0))


def test_global_setters_place_the_node_in_its_parent_frame() -> None:
    frame = Node2D("Frame", position=(1.0, 1.0), rotation=math.pi)
    marker = Marker2D("M")
    frame.add_child(marker)
    marker.global_position = (0.0, 1.0)
    assert marker.position == pytest.approx((1.0, 0.0))
    marker.global_rotation = 0.0
    assert marker.rotation == pytest.approx(-math.pi)
    with pytest.raises(TypeError, match="position must be two numbers"):
        marker.position = (1.0, 2.0, 3.0)
    with pytest.raises(TypeError, match="rotation must be a number"):
        marker.rotation = "up"  # type: ignore[assignment]


def test_a_body_enters_its_space_at_the_pose_its_frames_give(world: PhysicsWorld) -> None:
    frame = Node2D("Frame", position=(10.0, 0.0), rotation=math.pi / 2)
    body = ball(position=(1.0, 0.0))
    frame.add_child(body)
    world.add_child(frame)
    assert close(body.body.position, (10.0, 1.0))
    assert body.body.angle == pytest.approx(math.pi / 2)
    assert tuple(body.position) == (1.0, 0.0)  # exactly as placed, while nothing moved
    assert body.rotation == 0.0
    assert close(body.global_position, (10.0, 1.0))


def test_then_the_simulation_moves_it_and_position_reads_relative(
    tree: SceneTree, world: PhysicsWorld
) -> None:
    frame = Node2D("Frame", position=(0.0, 5.0), rotation=math.pi)  # upside down
    body = ball(position=(1.0, 0.0))
    frame.add_child(body)
    world.add_child(frame)
    ticks(tree, 30)
    fallen = body.body.position
    assert fallen.y < 4.5 and fallen.x == pytest.approx(-1.0)
    # relative to a frame turned half round, falling is going up
    assert body.position.y > 0.5
    assert close(frame.to_global(body.position), fallen)


def test_bodies_under_plain_nodes_keep_world_poses(world: PhysicsWorld) -> None:
    group = Node("Group")
    body = ball(position=(3.0, 4.0), angle=0.5)
    group.add_child(body)
    world.add_child(group)
    assert tuple(body.body.position) == (3.0, 4.0) and body.body.angle == 0.5
    assert tuple(body.position) == (3.0, 4.0) and body.angle == body.rotation == 0.5
    body.position = (1.0, 2.0)
    assert tuple(body.body.position) == (1.0, 2.0)
    with pytest.raises(ValueError, match="rotation or its angle"):
        RigidBody(angle=0.1, rotation=0.2)


def test_moving_a_frame_carries_the_bodies_below(tree: SceneTree, world: PhysicsWorld) -> None:
    frame = Node2D("Frame", position=(0.0, 0.0))
    body = ball(position=(1.0, 0.0))
    inner = ball("Inner", position=(0.0, 1.0))
    body.add_child(inner)
    frame.add_child(body)
    world.add_child(frame)
    body.velocity = (0.5, 0.0)
    frame.position = (5.0, 5.0)
    assert close(body.body.position, (6.0, 5.0))
    assert close(inner.body.position, (6.0, 6.0))
    assert body.velocity == (0.5, 0.0)  # teleported, velocity kept
    frame.rotation = math.pi / 2
    assert close(body.body.position, (5.0, 6.0))
    assert close(inner.body.position, (4.0, 6.0))
    # a marker on a body follows the body as it moves
    mark = Marker2D("Mark", position=(0.0, -1.0))
    inner.add_child(mark)
    ticks(tree, 10)
    assert close(mark.global_position, inner.to_global((0.0, -1.0)))


def test_restart_puts_bodies_back_where_their_frames_placed_them(
    tree: SceneTree, world: PhysicsWorld
) -> None:
    frame = Node2D("Frame", position=(2.0, 3.0), rotation=0.3)
    body = ball(position=(1.0, 1.0), rotation=0.2)
    frame.add_child(body)
    world.add_child(frame)
    placed = (*body.body.position, body.body.angle)
    ticks(tree, 40)
    assert body.body.position != placed[:2]
    world.restart()
    assert (*body.body.position, body.body.angle) == placed
    assert body.velocity == (0.0, 0.0)


def test_a_body_leaving_the_tree_keeps_its_relative_pose(
    tree: SceneTree, world: PhysicsWorld
) -> None:
    frame = Node2D("Frame", position=(0.0, 10.0))
    body = ball(position=(0.0, 0.0))
    frame.add_child(body)
    world.add_child(frame)
    ticks(tree, 20)
    dropped = body.position
    frame.remove_child(body)
    assert body.position == pytest.approx(dropped) and body.world is None
    other = Node2D("Other", position=(-5.0, 0.0))
    other.add_child(body)
    world.add_child(other)
    assert close(body.body.position, (-5.0 + dropped.x, dropped.y))


def test_moving_a_static_body_reindexes_its_shapes(tree: SceneTree, world: PhysicsWorld) -> None:
    ledge = StaticBody(name="Ledge", position=(100.0, 0.0))
    ledge.add_child(CollisionShape.segment((-1.0, 0.0), (1.0, 0.0), 0.1))
    world.add_child(ledge)
    falling = ball(position=(0.0, 1.0))
    world.add_child(falling)
    ledge.position = (0.0, 0.0)  # under the ball now: it must land on it
    ticks(tree, 60)
    assert falling.body.position.y == pytest.approx(0.3, abs=0.05)


def test_a_pivot_anchor_is_in_the_frame_of_its_joint(world: PhysicsWorld) -> None:
    frame = Node2D("Frame", position=(4.0, 0.0), rotation=math.pi / 2)
    anchor = StaticBody(name="Anchor")
    bob = ball("Bob", position=(1.0, 0.0))
    frame.add_child(anchor)
    frame.add_child(bob)
    frame.add_child(Joint.pivot("../Anchor", "../Bob", (0.0, 0.0), name="Hinge"))
    world.add_child(frame)
    hinge = frame.get_node("Hinge")
    assert isinstance(hinge, Joint)
    assert close(anchor.body.local_to_world(hinge.constraint.anchor_a), (4.0, 0.0))  # type: ignore[union-attr]
    assert close(bob.body.local_to_world(hinge.constraint.anchor_b), (4.0, 0.0))  # type: ignore[union-attr]


def test_a_camera_follows_a_body_where_it_is_in_the_world(world: PhysicsWorld) -> None:
    frame = Node2D("Frame", position=(10.0, 0.0))
    target = StaticBody(name="Target", position=(1.0, 0.0))
    target.add_child(CollisionShape.circle(0.3, color=(250, 0, 0)))
    frame.add_child(target)
    world.add_child(frame)
    camera = Camera(view=(-1.0, -1.0, 1.0, 1.0), size=(9, 9), follow="../Frame/Target")
    world.add_child(camera)
    assert tuple(camera.capture()[4, 4]) == (250, 0, 0)  # centred on (11, 0), not on (1, 0)
