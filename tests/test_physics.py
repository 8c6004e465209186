"""pymunk-backed physics nodes: space membership, stepping, errors, collision signals, joints."""

from __future__ import annotations

import logging
import math
import re
import subprocess
import sys

import numpy as np
import pymunk
import pytest

from rlenv.node import Node, ProcessMode
from rlenv.scene2d._chipmunk import collision_handlers
from rlenv.scene2d.physics import (
    CollisionShape,
    Joint,
    KinematicBody,
    PhysicsWorld,
    RigidBody,
    StaticBody,
)
from rlenv.tree import SceneTree
from rlenv_client import Client, ErrorCode, RemoteError


@pytest.fixture
def world(tree: SceneTree) -> PhysicsWorld:
    world = PhysicsWorld(gravity=(0.0, -10.0), name="World")
    tree.root.add_child(world)
    return world


def ball(name: str = "Ball", position=(0.0, 2.0), radius: float = 0.5, **shape_kwargs):
    body = RigidBody(position=position, name=name)
    shape_kwargs.setdefault("mass", 1.0)
    body.add_child(CollisionShape.circle(radius, name=f"{name}Shape", **shape_kwargs))
    return body


def floor(name: str = "Floor", **shape_kwargs) -> StaticBody:
    body = StaticBody(name=name)
    body.add_child(
        CollisionShape.segment((-10.0, 0.0), (10.0, 0.0), 0.1, name=f"{name}Shape", **shape_kwargs)
    )
    return body


def ticks(tree: SceneTree, count: int) -> None:
    for _ in range(count):
        tree.physics_tick()


# --- space membership ------------------------------------------------------------------------


def test_body_and_shape_enter_and_leave_space(world: PhysicsWorld) -> None:
    body = RigidBody(name="Body")
    shape = CollisionShape.box(1.0, 2.0, mass=2.0, name="Box")
    body.add_child(shape)
    assert body.body.space is None and shape.shape.space is None
    world.add_child(body)
    assert body.body in world.space.bodies
    assert shape.shape in world.space.shapes
    assert shape.shape.body is body.body
    assert shape.body_node is body
    assert body.world is world
    # the body takes its mass from the shape
    assert body.body.mass == pytest.approx(2.0)
    world.remove_child(body)
    assert list(world.space.bodies) == []
    assert list(world.space.shapes) == []
    assert shape.body_node is None and body.world is None
    # and back again
    world.add_child(body)
    assert list(world.space.bodies) == [body.body]
    assert list(world.space.shapes) == [shape.shape]


def test_shape_added_to_body_already_in_tree(world: PhysicsWorld) -> None:
    body = RigidBody(mass=1.0, moment=1.0, name="Body")
    world.add_child(body)
    assert list(world.space.shapes) == []
    shape = CollisionShape.poly([(0, 0), (1, 0), (0, 1)], mass=1.0)
    body.add_child(shape)
    assert list(world.space.shapes) == [shape.shape]
    body.remove_child(shape)
    assert list(world.space.shapes) == []
    assert list(world.space.bodies) == [body.body]


def test_static_and_kinematic_bodies_enter_space(world: PhysicsWorld) -> None:
    static = floor()
    kinematic = KinematicBody(position=(1.0, 2.0), name="Platform")
    world.add_child(static)
    world.add_child(kinematic)
    assert static.body.body_type == pymunk.Body.STATIC
    assert kinematic.body.body_type == pymunk.Body.KINEMATIC
    assert set(world.space.bodies) == {static.body, kinematic.body}
    assert len(world.space.shapes) == 1


def test_bodies_below_intermediate_nodes_use_nearest_world(tree: SceneTree) -> None:
    outer = PhysicsWorld(name="Outer")
    inner = PhysicsWorld(name="Inner")
    group = Node("Group")
    body = ball()
    group.add_child(body)
    inner.add_child(group)
    outer.add_child(inner)
    tree.root.add_child(outer)
    assert body.world is inner
    assert list(inner.space.bodies) == [body.body]
    assert list(outer.space.bodies) == []


def test_joint_enters_and_leaves_space(world: PhysicsWorld) -> None:
    anchor = StaticBody(name="Anchor")
    bob = ball("Bob", position=(1.0, 0.0))
    joint = Joint.pivot("../Anchor", "../Bob", (0.0, 0.0), name="Hinge")
    world.add_child(anchor)
    world.add_child(bob)
    world.add_child(joint)
    assert isinstance(joint.constraint, pymunk.PivotJoint)
    assert list(world.space.constraints) == [joint.constraint]
    assert joint.constraint.a is anchor.body and joint.constraint.b is bob.body
    assert not joint.constraint.collide_bodies
    world.remove_child(joint)
    assert list(world.space.constraints) == []
    world.add_child(joint)
    assert list(world.space.constraints) == [joint.constraint]


def test_removing_world_subtree_empties_space(tree: SceneTree, world: PhysicsWorld) -> None:
    world.add_child(floor())
    world.add_child(ball("A", position=(0.0, 1.0)))
    world.add_child(ball("B", position=(1.0, 0.0)))
    world.add_child(Joint.pivot("../A", "../B", (0.5, 0.5)))
    assert len(world.space.bodies) == 3
    assert len(world.space.shapes) == 3
    assert len(world.space.constraints) == 1
    tree.root.remove_child(world)
    assert list(world.space.bodies) == []
    assert list(world.space.shapes) == []
    assert list(world.space.constraints) == []


def test_queue_free_removes_from_space(tree: SceneTree, world: PhysicsWorld) -> None:
    body = ball()
    world.add_child(body)
    body.queue_free()
    assert list(world.space.bodies) == [body.body]
    tree.physics_tick()
    assert list(world.space.bodies) == []
    assert list(world.space.shapes) == []
    assert body.is_freed()


# --- stepping --------------------------------------------------------------------------------


@pytest.mark.parametrize("ticks_per_second", [60, 30])
def test_body_falls_under_gravity(ticks_per_second: int) -> None:
    tree = SceneTree(ticks_per_second)
    world = PhysicsWorld(gravity=(0.0, -10.0))
    tree.root.add_child(world)
    body = ball(position=(0.0, 0.0))
    world.add_child(body)
    steps: list[float] = []
    world.stepped.connect(steps.append)
    ticks(tree, ticks_per_second)  # one simulated second
    assert steps == [1 / ticks_per_second] * ticks_per_second
    assert body.velocity.x == 0.0
    assert body.velocity.y == pytest.approx(-10.0, abs=1e-9)
    # chipmunk moves each body with the velocity it had before the step, then accelerates it:
    # after n steps of dt, y = -g * dt**2 * n * (n - 1) / 2
    n, dt = ticks_per_second, 1 / ticks_per_second
    assert body.position.y == pytest.approx(-10.0 * dt * dt * n * (n - 1) / 2, abs=1e-9)


def test_half_second_of_falling(tree: SceneTree, world: PhysicsWorld) -> None:
    body = ball(position=(0.0, 0.0))
    world.add_child(body)
    ticks(tree, 30)
    assert body.velocity.y == pytest.approx(-5.0, abs=1e-9)


def test_world_does_not_step_while_paused(tree: SceneTree, world: PhysicsWorld) -> None:
    body = ball(position=(0.0, 0.0))
    world.add_child(body)
    tree.paused = True
    for _ in range(10):
        tree.iteration()
        tree.physics_tick()
    assert body.velocity.y == 0.0 and body.position.y == 0.0
    world.process_mode = ProcessMode.ALWAYS
    tree.physics_tick()
    assert body.velocity.y == pytest.approx(-10.0 / 60)


def test_world_steps_after_physics_process(tree: SceneTree, world: PhysicsWorld) -> None:
    seen: list[float] = []

    class Pusher(Node):
        """Sets the velocity in _physics_process; the step of the same tick uses it."""

        def _physics_process(self, delta: float) -> None:
            body = self.get_node("../World/Ball")
            seen.append(body.position.x)
            body.velocity = (60.0, 0.0)

    world.space.gravity = (0.0, 0.0)
    body = ball(position=(0.0, 0.0))
    world.add_child(body)
    tree.root.add_child(Pusher("Pusher"))  # after the world in tree order
    tree.physics_tick()
    assert seen == [0.0]
    assert body.position.x == pytest.approx(1.0)


def test_rigid_body_accessors_and_impulse(tree: SceneTree, world: PhysicsWorld) -> None:
    world.space.gravity = (0.0, 0.0)
    body = ball(position=(1.0, 2.0))
    world.add_child(body)
    assert tuple(body.position) == (1.0, 2.0)
    body.angle = 0.5
    body.angular_velocity = 2.0
    assert body.body.angle == 0.5 and body.body.angular_velocity == 2.0
    body.apply_impulse((3.0, 0.0))
    assert tuple(body.velocity) == pytest.approx((3.0, 0.0))
    body.position = (0.0, 0.0)
    body.velocity = (0.0, 0.0)
    body.apply_force((60.0, 0.0))
    tree.physics_tick()
    assert body.velocity.x == pytest.approx(1.0)


def test_godot_s_names_read_and_push_the_body(tree: SceneTree, world: PhysicsWorld) -> None:
    world.space.gravity = (0.0, 0.0)
    body = RigidBody(name="Lopsided")  # its centre of gravity is off its origin
    body.add_child(CollisionShape.circle(0.5, offset=(1.0, 0.0), mass=2.0))
    world.add_child(body)
    body.rotation = 0.25
    body.linear_velocity = (1.5, -2.0)
    assert body.velocity == body.body.velocity == body.linear_velocity == (1.5, -2.0)
    assert type(body.position) is type(body.linear_velocity) is pymunk.Vec2d
    assert body.position == body.body.position and body.rotation == body.body.angle == 0.25
    body.linear_velocity = (0.0, 0.0)
    body.apply_central_force((60.0, 30.0))
    tree.physics_tick()
    assert body.angular_velocity == 0.0  # at the centre of gravity: it does not turn the body
    assert tuple(body.linear_velocity) == pytest.approx((0.5, 0.25))  # F / m for one 1/60 s tick
    body.apply_force((60.0, 30.0))  # at its origin, off its centre of gravity: it turns it
    tree.physics_tick()
    assert body.angular_velocity != 0.0


# --- placement errors ------------------------------------------------------------------------


def test_shape_outside_body_raises(world: PhysicsWorld) -> None:
    shape = CollisionShape.circle(1.0, name="Orphan")
    with pytest.raises(RuntimeError, match="must be a child of a body node") as info:
        world.add_child(shape)
    assert "Orphan" in str(info.value)
    assert "World" in str(info.value)


def test_shape_under_plain_node_raises(world: PhysicsWorld) -> None:
    holder = Node("Holder")
    holder.add_child(CollisionShape.circle(1.0))
    with pytest.raises(RuntimeError, match="must be a child of a body node, not of <Node"):
        world.add_child(holder)


def test_body_outside_world_raises(tree: SceneTree) -> None:
    with pytest.raises(RuntimeError, match="must be placed below a PhysicsWorld") as info:
        tree.root.add_child(RigidBody(name="Lost"))
    assert "Lost" in str(info.value)


def test_joint_outside_world_raises(tree: SceneTree) -> None:
    with pytest.raises(RuntimeError, match="must be placed below a PhysicsWorld"):
        tree.root.add_child(Joint.pivot("../A", "../B", (0.0, 0.0)))


def test_joint_without_bodies_raises_when_ready(world: PhysicsWorld) -> None:
    world.add_child(ball("A"))
    with pytest.raises(RuntimeError, match="no body node in the space at path '../Missing'"):
        world.add_child(Joint.pivot("../A", "../Missing", (0.0, 0.0)))


# --- collisions ------------------------------------------------------------------------------


def watch(log: list, tree: SceneTree, *nodes: Node) -> None:
    """Log every collision signal of ``nodes`` as (signal, node, other, tick)."""
    for node in nodes:
        for signal in ("collision_started", "collision_ended", "body_entered", "body_exited"):
            if node.has_signal(signal):
                node.connect(
                    signal,
                    lambda other, s=signal, n=node: log.append(
                        (s, n.name, other.name, tree.physics_frames)
                    ),
                )


def drop_ball(tree: SceneTree, world: PhysicsWorld, log: list, *, elasticity=0.0, sensor=False):
    ground = floor(elasticity=elasticity, sensor=sensor)
    falling = ball(elasticity=elasticity)
    world.add_child(ground)
    world.add_child(falling)
    ground_shape, ball_shape = ground.get_child(0), falling.get_child(0)
    watch(log, tree, ground, falling, ground_shape, ball_shape)
    return ground, falling, ground_shape, ball_shape


def until(tree: SceneTree, condition, limit: int = 600) -> int:
    for _ in range(limit):
        tree.physics_tick()
        if condition():
            return tree.physics_frames
    raise AssertionError("condition never became true")


def test_collision_started_on_both_shapes_and_bodies(
    tree: SceneTree, world: PhysicsWorld, log: list
) -> None:
    drop_ball(tree, world, log)
    contact = until(tree, lambda: bool(log))
    # the ball (radius 0.5, starting 2 above the floor) needs about 0.5 s to touch it
    assert 25 < contact < 40
    assert sorted(log) == sorted(
        [
            ("collision_started", "BallShape", "FloorShape", contact),
            ("collision_started", "FloorShape", "BallShape", contact),
            ("body_entered", "Ball", "Floor", contact),
            ("body_entered", "Floor", "Ball", contact),
        ]
    )
    # resting on the floor: no more signals, the ball stays on top of it (within pymunk's
    # collision slop of 0.1)
    log.clear()
    ticks(tree, 60)
    assert log == []
    resting = world.get_node("Ball")
    assert 0.45 < resting.position.y <= 0.6
    assert resting.velocity.y == pytest.approx(0.0, abs=0.05)


def test_a_world_without_contact_monitor_simulates_alike_and_reports_no_contact(
    tree: SceneTree,
) -> None:
    """contact_monitor=False: no handler of rlenv's, no signal, the same bodies bit for bit."""
    worlds, logs = [], []
    for monitor in (True, False):
        world = PhysicsWorld(gravity=(0.0, -10.0), contact_monitor=monitor, name=f"W{monitor}")
        tree.root.add_child(world)
        log: list = []
        drop_ball(tree, world, log, elasticity=0.5)
        worlds.append(world)
        logs.append(log)
    tree.paused = False
    states = []
    for _ in range(120):
        tree.physics_tick()
        states.append(
            [(*w.get_node("Ball").position, *w.get_node("Ball").velocity) for w in worlds]
        )
    assert all(monitored == unmonitored for monitored, unmonitored in states)
    assert logs[0] and logs[1] == []  # the ball bounced on both floors; one world said so
    assert worlds[0].contact_monitor and not worlds[1].contact_monitor
    assert collision_handlers(worlds[1].space) == {}
    worlds[1].restart()  # a new space, as unmonitored
    assert collision_handlers(worlds[1].space) == {} and worlds[1].space.own == {}
    seen: list = []
    worlds[1].space.on_collision(begin=lambda arbiter, space, data: seen.append(data), data=7)
    for _ in range(60):
        tree.physics_tick()
    assert 7 in seen and logs[1] == []  # the user's catch-all is pymunk's own there


def test_signal_arguments_are_the_other_nodes(tree: SceneTree, world: PhysicsWorld) -> None:
    ground, falling, ground_shape, ball_shape = drop_ball(tree, world, [])
    received: dict[str, Node] = {}
    ground.body_entered.connect(lambda other: received.setdefault("floor", other))
    falling.body_entered.connect(lambda other: received.setdefault("ball", other))
    ground_shape.collision_started.connect(lambda other: received.setdefault("fs", other))
    ball_shape.collision_started.connect(lambda other: received.setdefault("bs", other))
    until(tree, lambda: len(received) == 4)
    assert received == {"floor": falling, "ball": ground, "fs": ball_shape, "bs": ground_shape}


def test_collision_ended_when_ball_bounces_away(
    tree: SceneTree, world: PhysicsWorld, log: list
) -> None:
    _, falling, _, _ = drop_ball(tree, world, log, elasticity=1.0)
    contact = until(tree, lambda: bool(log))
    separation = until(tree, lambda: any(entry[0] == "collision_ended" for entry in log))
    assert separation > contact
    assert falling.velocity.y > 0  # it bounced up
    ended = sorted(entry for entry in log if entry[3] == separation)
    assert ended == sorted(
        [
            ("collision_ended", "BallShape", "FloorShape", separation),
            ("collision_ended", "FloorShape", "BallShape", separation),
            ("body_exited", "Ball", "Floor", separation),
            ("body_exited", "Floor", "Ball", separation),
        ]
    )


def test_collision_ended_when_ball_removed(tree: SceneTree, world: PhysicsWorld, log: list) -> None:
    _, falling, _, _ = drop_ball(tree, world, log)
    until(tree, lambda: bool(log))
    ticks(tree, 5)  # resting on the floor
    log.clear()
    world.remove_child(falling)
    assert sorted(entry[:3] for entry in log) == sorted(
        [
            ("collision_ended", "BallShape", "FloorShape"),
            ("collision_ended", "FloorShape", "BallShape"),
            ("body_exited", "Ball", "Floor"),
            ("body_exited", "Floor", "Ball"),
        ]
    )


def test_removal_from_collision_handler_is_deferred(
    tree: SceneTree, world: PhysicsWorld, log: list
) -> None:
    ground, falling, _, _ = drop_ball(tree, world, [])

    def on_entered(other: Node) -> None:
        world.remove_child(other)  # inside the space step: deferred to the end of the tick
        log.append(("handler", other.is_inside_tree(), other.body.space is world.space))

    ground.body_entered.connect(on_entered)
    until(tree, lambda: bool(log))
    assert log == [("handler", True, True)]
    assert not falling.is_inside_tree()
    assert list(world.space.bodies) == [ground.body]
    assert len(world.space.shapes) == 1


def test_sensor_reports_but_does_not_stop_ball(
    tree: SceneTree, world: PhysicsWorld, log: list
) -> None:
    _, falling, ground_shape, _ = drop_ball(tree, world, log, sensor=True)
    assert ground_shape.shape.sensor
    contact = until(tree, lambda: bool(log))
    assert ("collision_started", "FloorShape", "BallShape", contact) in log
    assert ("body_entered", "Ball", "Floor", contact) in log
    until(tree, lambda: falling.position.y < -1.0, limit=120)
    assert falling.velocity.y < -5.0  # still falling freely
    assert ("collision_ended", "FloorShape", "BallShape") in [entry[:3] for entry in log]


# --- joints ----------------------------------------------------------------------------------


def pendulum(joint_first: bool, origin=(0.0, 0.0)) -> tuple[Node, StaticBody, RigidBody, Joint]:
    """Model/{Anchor, Bob, Hinge}: a 1 m pendulum hinged at ``origin``, starting horizontal."""
    x, y = origin
    model = Node("Model")
    anchor = StaticBody(position=origin, name="Anchor")
    bob = ball("Bob", position=(x + 1.0, y), radius=0.1)
    hinge = Joint.pivot("../Anchor", "../Bob", origin, name="Hinge")
    children = [hinge, anchor, bob] if joint_first else [anchor, bob, hinge]
    for child in children:
        model.add_child(child)
    return model, anchor, bob, hinge


@pytest.mark.parametrize("joint_first", [False, True])
def test_pivot_keeps_bodies_together(
    tree: SceneTree, world: PhysicsWorld, joint_first: bool
) -> None:
    model, anchor, bob, hinge = pendulum(joint_first)
    world.add_child(model)
    assert list(world.space.constraints) == [hinge.constraint]
    assert hinge.constraint.a is anchor.body and hinge.constraint.b is bob.body
    lowest = 0.0
    for _ in range(90):
        tree.physics_tick()
        assert math.hypot(*bob.position) == pytest.approx(1.0, abs=0.02)
        lowest = min(lowest, bob.position.y)
    assert lowest < -0.9  # it swung down instead of falling away


def test_unjointed_body_falls_away(tree: SceneTree, world: PhysicsWorld) -> None:
    """Control for the pivot test: without the joint the bob does not stay 1 m from the hinge."""
    model, _, bob, hinge = pendulum(joint_first=False)
    model.remove_child(hinge)
    world.add_child(model)
    ticks(tree, 60)
    assert math.hypot(*bob.position) > 2.0


def test_pivot_between_dynamic_bodies_transfers_motion(
    tree: SceneTree, world: PhysicsWorld
) -> None:
    world.space.gravity = (0.0, 0.0)
    model = Node("Model")
    a = ball("A", position=(0.0, 0.0))
    b = ball("B", position=(2.0, 0.0))
    model.add_child(Joint.pivot("../A", "../B", (1.0, 0.0), name="Link"))
    model.add_child(a)
    model.add_child(b)
    world.add_child(model)
    b.velocity = (0.0, 3.0)
    ticks(tree, 30)
    assert a.position.get_distance(b.position) == pytest.approx(2.0, abs=0.02)
    assert a.position.y > 0.1  # pulled along by b


def test_joint_before_bodies_reattaches_after_readding(
    tree: SceneTree, world: PhysicsWorld
) -> None:
    model, _, bob, hinge = pendulum(joint_first=True)
    world.add_child(model)
    world.remove_child(model)
    assert list(world.space.constraints) == []
    world.add_child(model)
    assert list(world.space.constraints) == [hinge.constraint]


def test_joint_after_bodies_reattaches_after_readding(tree: SceneTree, world: PhysicsWorld) -> None:
    model, _, bob, hinge = pendulum(joint_first=False)
    world.add_child(model)
    world.remove_child(model)
    world.add_child(model)
    assert list(world.space.constraints) == [hinge.constraint]
    ticks(tree, 30)
    assert math.hypot(*bob.position) == pytest.approx(1.0, abs=0.02)


# --- determinism -----------------------------------------------------------------------------


def build_scene() -> tuple[SceneTree, list[RigidBody]]:
    tree = SceneTree(60)
    world = PhysicsWorld(gravity=(0.0, -9.81))
    tree.root.add_child(world)
    world.add_child(floor(elasticity=0.5, friction=0.7))
    bodies = []
    for index in range(6):
        body = ball(
            f"Ball{index}",
            position=(0.3 * index - 0.7, 1.0 + 1.1 * index),
            radius=0.4,
            elasticity=0.5,
        )
        body.angular_velocity = 0.3 * index
        world.add_child(body)
        bodies.append(body)
    box = RigidBody(position=(0.1, 9.0), angle=0.3, name="Crate")
    box.add_child(CollisionShape.box(1.0, 0.6, density=2.0, elasticity=0.2))
    world.add_child(box)
    bodies.append(box)
    model, _, bob, _ = pendulum(joint_first=True, origin=(3.0, 3.0))
    world.add_child(model)
    bodies.append(bob)
    return tree, bodies


def state(bodies: list[RigidBody]) -> list[tuple[float, ...]]:
    return [(*b.position, *b.velocity, b.angle, b.angular_velocity) for b in bodies]


def test_deterministic() -> None:
    first, first_bodies = build_scene()
    second, second_bodies = build_scene()
    ticks(first, 150)
    ticks(second, 150)
    a, b = state(first_bodies), state(second_bodies)
    assert a == b  # bit-identical, not approximately equal
    # and the scene actually moved and collided
    assert state(build_scene()[1]) != a
    assert all(y > -0.5 for _, y, *_ in a[:6])


def test_a_restarted_world_runs_as_a_freshly_built_one() -> None:
    """Contacts, a joint and the solver's warm starting all in play: after ``restart`` and the
    same starting velocities, the run is bit-identical to a newly built scene's."""
    fresh_tree, fresh_bodies = build_scene()
    tree, bodies = build_scene()
    ticks(tree, 150)  # balls resting on the floor, the pendulum swinging, impulses cached
    world = tree.root.get_child(0)
    assert isinstance(world, PhysicsWorld)
    nodes, old_space = list(world.iter_subtree()), world.space
    ended: list[object] = []
    world.get_child(0).get_child(0).collision_ended.connect(ended.append)  # the floor's shape
    world.restart()
    assert list(world.iter_subtree()) == nodes and world.space is not old_space
    assert ended, "contacts in progress end when the world restarts"
    assert not old_space.bodies and not old_space.shapes and not old_space.constraints
    for index, body in enumerate(bodies[:6]):  # what build_scene sets besides the build pose
        body.angular_velocity = 0.3 * index
    assert state(bodies) == state(fresh_bodies)
    ticks(tree, 150)
    ticks(fresh_tree, 150)
    assert state(bodies) == state(fresh_bodies)  # bit-identical, not approximately equal


def jointed_scene(kind: str) -> tuple[SceneTree, list[RigidBody], Joint]:
    """A wheel on an arm, held by a ``kind`` joint that works hard all the time."""
    tree = SceneTree(60)
    world = PhysicsWorld(gravity=(0.0, -9.81))
    tree.root.add_child(world)
    base = StaticBody(position=(0.0, 0.0), name="Base")
    wheel = ball("Wheel", position=(1.0, 0.5), radius=0.3)
    world.add_child(base)
    world.add_child(wheel)
    joints = {
        "pivot": lambda: Joint.pivot("../Base", "../Wheel", (0.2, 0.1), name="Joint"),
        "groove": lambda: Joint.groove(
            "../Base", "../Wheel", (-2.0, 0.5), (2.0, 0.5), name="Joint"
        ),
        "motor": lambda: Joint.motor("../Base", "../Wheel", rate=3.0, max_force=5.0, name="Joint"),
        "spring": lambda: Joint.spring(
            "../Base", "../Wheel", (0.0, 0.0), (0.0, 0.0), 0.5, 40.0, 0.8, name="Joint"
        ),
    }
    joint = joints[kind]()
    world.add_child(joint)
    if kind == "motor":  # a motor alone lets the wheel fall: pin it too
        world.add_child(Joint.pivot("../Base", "../Wheel", (1.0, 0.5), name="Pin"))
    return tree, [wheel], joint


@pytest.mark.parametrize("kind", ["pivot", "groove", "motor", "spring"])
def test_a_restart_refreshes_each_kind_of_joint_in_place(kind: str) -> None:
    """The constraint is set up again as when made (no impulse carried over), not replaced,
    and the run after the restart is bit-identical to a newly built scene's."""
    fresh_tree, fresh_bodies, _ = jointed_scene(kind)
    tree, bodies, joint = jointed_scene(kind)
    constraint = joint.constraint
    constraint.error_bias = 0.5  # settings the joint was given survive the refresh
    fresh_tree.root.get_child(0).get_node("Joint").constraint.error_bias = 0.5
    ticks(tree, 90)
    assert constraint.impulse != 0.0  # the solver's warm start is in play
    tree.root.get_child(0).restart()
    assert joint.constraint is constraint and constraint.impulse == 0.0
    assert constraint.error_bias == 0.5 and constraint.max_force == (
        5.0 if kind == "motor" else math.inf
    )
    ticks(tree, 120)
    ticks(fresh_tree, 120)
    assert state(bodies) == state(fresh_bodies)  # bit-identical, not approximately equal


@pytest.mark.parametrize("kind", ["pivot", "groove", "motor", "spring"])
def test_a_space_without_contacts_restarts_in_place_exactly(kind: str) -> None:
    """The same space, emptied and renumbered, runs every episode bit-identical to a new
    scene's, however long the episodes before it ran."""
    tree, bodies, _ = jointed_scene(kind)
    world = tree.root.get_child(0)
    spaces = []
    for episode, length in enumerate([40, 7, 120, 1, 60]):
        world.restart()
        spaces.append(world.space)
        fresh_tree, fresh_bodies, _ = jointed_scene(kind)
        for ticks_so_far in range(length):
            tree.physics_tick()
            fresh_tree.physics_tick()
            assert state(bodies) == state(fresh_bodies), (episode, ticks_so_far)
    assert all(space is spaces[0] for space in spaces[1:])  # the first restart made a new one


def test_a_space_that_saw_contacts_or_changed_restarts_as_a_new_one() -> None:
    tree, bodies = build_scene()  # balls on a floor: contacts cached in Chipmunk's tables
    world = tree.root.get_child(0)
    world.restart()
    first = world.space
    ticks(tree, 60)
    world.restart()
    assert world.space is not first  # contacts began since the previous restart
    second = world.space
    world.restart()  # nothing ran: nothing touched, nothing moved in the tree
    assert world.space is second
    world.add_child(ball("Late", position=(4.0, 4.0), radius=0.2))
    world.restart()
    assert world.space is not second  # the tree below changed


def test_a_restart_in_place_leaves_pymunk_s_records_as_a_new_space_has_them() -> None:
    """Emptied and refilled with Chipmunk's calls alone, the space lists its bodies, shapes and
    constraints as pymunk lists a new space's (in tree order); its bodies were checked as
    pymunk checks added ones (and passed), so the next step is the quick one."""
    tree, bodies, joint = jointed_scene("groove")
    world = tree.root.get_child(0)
    assert isinstance(world, PhysicsWorld)
    fresh_tree, _, _ = jointed_scene("groove")
    fresh = fresh_tree.root.get_child(0).space
    names = {
        id(node.body): node.name
        for node in world.iter_subtree()
        if isinstance(node, StaticBody | RigidBody)
    }
    fresh_names = {
        id(node.body): node.name
        for node in fresh_tree.root.get_child(0).iter_subtree()
        if isinstance(node, StaticBody | RigidBody)
    }
    for turn in range(3):
        ticks(tree, 20)
        world.restart()
        space = world.space
        assert [names[id(b)] for b in space.bodies] == [fresh_names[id(b)] for b in fresh.bodies]
        assert [names[id(s.body)] for s in space.shapes] == [
            fresh_names[id(s.body)] for s in fresh.shapes
        ]
        assert list(space.constraints) == [joint.constraint]
        assert all(body.space is space for body in space.bodies)
        # The first restart re-adds through pymunk (which checks at the next step); the others
        # are in place, and checked already.
        assert set(space._bodies_to_check) == (set() if turn else set(space.bodies))


def test_a_restart_leaves_a_body_without_a_valid_mass_to_pymunk_s_check() -> None:
    """A body turned dynamic without a mass (its shapes have none) is refused at the next step,
    as after space.add."""
    tree, _, _ = jointed_scene("groove")
    world = tree.root.get_child(0)
    assert isinstance(world, PhysicsWorld)
    world.restart()
    ticks(tree, 1)  # pymunk checks the bodies the first restart added
    world.restart()  # the quick way from now on
    assert not world.space._bodies_to_check
    base = world.get_node("Base").body
    base.body_type = pymunk.Body.DYNAMIC
    world.restart()
    assert world.space._bodies_to_check == {base}
    with pytest.raises(
        ValueError,
        match=re.escape("<StaticBody /root/PhysicsWorld/Base> has mass 0.0 and moment 0.0"),
    ):
        ticks(tree, 1)


def test_a_restart_takes_out_what_was_added_to_the_space_by_hand() -> None:
    tree, bodies, _ = jointed_scene("pivot")
    world = tree.root.get_child(0)
    world.restart()
    world.restart()
    space = world.space
    extra = pymunk.Body(1.0, 1.0)
    space.add(extra, pymunk.Circle(extra, 0.1))
    ticks(tree, 5)
    world.restart()
    assert extra.space is None
    assert list(world.space.bodies) == [node.body for node in (world.get_node("Base"), *bodies)]
    fresh_tree, fresh_bodies, _ = jointed_scene("pivot")
    ticks(tree, 60)
    ticks(fresh_tree, 60)
    assert state(bodies) == state(fresh_bodies)


# --- what Chipmunk would abort on is a Python error (issue 32) --------------------------------


_TWICE = """
from rlenv.node import Node
from rlenv.scene2d.physics import CollisionShape, PhysicsWorld, StaticBody
from rlenv.tree import SceneTree

tree = SceneTree(60)
world = PhysicsWorld(name="World")
tree.root.add_child(world)
body = StaticBody(name="Peg")
body.add_child(CollisionShape.circle(0.1, name="Skin"))
world.add_child(body)
for node in (body.get_node("Skin"), body):
    try:
        node._enter_tree()
    except RuntimeError as error:
        print(error)
tree.physics_tick()
"""


def test_a_body_or_shape_entering_its_space_twice_is_an_error_not_an_abort() -> None:
    # In a process of its own: before, Chipmunk's assertion aborted it (status -6).
    run = subprocess.run([sys.executable, "-c", _TWICE], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines() == [
        "<CollisionShape /root/World/Peg/Skin>: its shape is in a space already (was "
        "_enter_tree called outside the tree's lifecycle?)",
        "<StaticBody /root/World/Peg>: its body is in a space already (was _enter_tree "
        "called outside the tree's lifecycle?)",
    ]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: PhysicsWorld(iterations=0), "iterations must be an integer in [1,"),
        (lambda: PhysicsWorld(damping=-1.0), "damping must be a number finite and >= 0"),
        (lambda: PhysicsWorld(gravity=(math.nan, 0.0)), "gravity must be a number finite"),
        (lambda: CollisionShape.circle(-0.1), "radius must be a number finite and >= 0"),
        (lambda: CollisionShape.segment((0, 0), (1, 0), -0.1), "radius must be"),
        (lambda: CollisionShape.circle(0.1, friction=-1.0), "friction must be"),
        (lambda: CollisionShape.circle(0.1, elasticity=math.inf), "elasticity must be"),
        (lambda: CollisionShape.circle(0.1, mass=-1.0), "mass must be"),
        (lambda: Joint.pivot("../A", "../B", (0, 0), max_force=-1.0), "max_force must be"),
    ],
)
def test_values_chipmunk_refuses_are_refused_by_name(make, message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        make()


def test_setting_what_chipmunk_refuses_names_the_node(world: PhysicsWorld) -> None:
    body = floor()
    world.add_child(body)
    shape = body.get_node("FloorShape")
    with pytest.raises(
        ValueError,
        match=re.escape("<CollisionShape /root/World/Floor/FloorShape>: friction must be a number"),
    ):
        shape.friction = -0.5
    with pytest.raises(ValueError, match=re.escape("<PhysicsWorld /root/World>: damping")):
        world.damping = -1.0
    with pytest.raises(ValueError, match="gravity must be two numbers"):
        world.gravity = (1.0,)
    assert shape.friction == 0.5 and world.damping == 1.0  # nothing changed


def test_a_client_setting_a_negative_damping_is_refused_and_the_server_serves_on(
    serve,
) -> None:
    server = serve()
    with Client(server.host, server.port, timeout=20) as client:
        client.reset(seed=1)
        with pytest.raises(RemoteError, match="damping must be a number finite and >= 0") as no:
            client.set_property("World/Physics", "damping", -1.0)
        assert no.value.code == ErrorCode.BAD_REQUEST
        client.step(client.action_space.sample())  # the episode goes on
        assert server.is_alive()


def test_a_dynamic_body_without_mass_is_named_at_its_first_step(
    tree: SceneTree,
    world: PhysicsWorld,
) -> None:
    body = RigidBody(name="Ghost")
    body.add_child(CollisionShape.circle(0.5))  # no mass, no density
    world.add_child(body)
    with pytest.raises(
        ValueError, match=re.escape("<RigidBody /root/World/Ghost> has mass 0.0 and moment 0.0")
    ):
        tree.physics_tick()


def test_a_second_physics_world_beside_the_first_is_logged(
    world: PhysicsWorld,
    caplog: pytest.LogCaptureFixture,
) -> None:
    with caplog.at_level(logging.WARNING, "rlenv.scene2d.physics"):
        world.parent.add_child(PhysicsWorld(name="World"))
    assert "<PhysicsWorld /root/World2> enters beside World" in caplog.text


_SPACE_SETTINGS = {
    "collision_slop": 0.3,
    "collision_bias": 0.2,
    "collision_persistence": 5,
    "idle_speed_threshold": 0.01,
    "iterations": 25,
    "damping": 0.9,
}


def _space_settings(space: pymunk.Space) -> dict[str, object]:
    return {
        name: getattr(space, name) for name in [*_SPACE_SETTINGS, "gravity", "sleep_time_threshold"]
    }


@pytest.mark.parametrize("slop", [0.1, 0.0])
def test_a_restart_leaves_no_bias_velocity_of_the_last_contacts(slop: float) -> None:
    """With ``collision_slop`` 0 the solver pushes a resting ball out of the floor at every
    step, and Chipmunk keeps that push (the bias velocity) in the body for its next move: a
    restart that kept it made the next episode differ (1.8e-11 in the ball's height here)."""
    runs = []
    for contact in (True, False):
        tree = SceneTree(60)
        world = PhysicsWorld(gravity=(0.0, -9.81))
        tree.root.add_child(world)
        world.add_child(floor())
        body = ball(position=(0.0, 1.0))
        world.add_child(body)
        world.space.collision_slop = slop
        world.restart()
        ticks(tree, 90 if contact else 5)
        assert (body.position.y < 0.7) is contact  # resting on the floor, or still falling
        world.restart()
        ticks(tree, 120)
        runs.append(state([body]))
    assert runs[0] == runs[1]  # bit for bit


def test_the_same_seed_and_actions_give_the_same_bits_whatever_came_before() -> None:
    """Over the serving path, with the space configured by a client (``slop`` sets
    ``collision_slop``): the episode after one whose ball hit the floor and the episode after
    one whose ball never reached it are the same, bit for bit."""
    from rlenv_client import LocalClient

    def episode(client: LocalClient, seed: int, steps: int) -> list[bytes]:
        observation, _ = client.reset(seed=seed)
        seen = [observation.tobytes()]
        for step in range(steps):
            observation, *_ = client.step(np.array([0.3 if step % 7 else -0.5], np.float32))
            seen.append(observation.tobytes())
        return seen

    runs = []
    for before in (60, 1):  # the ball lands after about 20 steps of 4 ticks
        with LocalClient("restart_envs:DroppedBall") as client:
            client.configure(world={"slop": 0.0})
            landed = bool(np.frombuffer(episode(client, 1, before)[-1])[1] < 0.31)  # at rest
            assert landed is (before == 60)
            runs.append(episode(client, 5, 60))
    assert runs[0] == runs[1]


@pytest.mark.parametrize("handler", [False, True])
def test_a_restart_gives_the_same_space_whether_or_not_the_episode_saw_a_contact(
    handler: bool,
) -> None:
    """Settings given to the pymunk space and the user's collision handlers survive a restart,
    in place or into a new space: before, a new space dropped them, and whether one was made
    depended on the last episode's contacts (the same seed and actions then diverged)."""
    runs = []
    for contact in (True, False):
        tree, bodies = build_scene()
        world = tree.root.get_child(0)
        assert isinstance(world, PhysicsWorld)
        for name, value in _SPACE_SETTINGS.items():
            setattr(world.space, name, value)
        solved: list[int] = []
        if handler:
            world.space.on_collision(
                0, 0, post_solve=lambda arbiter, space, data, seen=solved: seen.append(1)
            )
        world.restart()
        if contact:
            ticks(tree, 60)
        world.restart()
        solved.clear()
        ticks(tree, 120)
        runs.append((_space_settings(world.space), state(bodies), len(solved)))
    assert runs[0] == runs[1]  # bit for bit
    assert runs[0][0] == {
        **_space_settings(pymunk.Space()),
        **_SPACE_SETTINGS,
        "gravity": (0.0, -9.81),
    }
    assert runs[0][2] > 0 if handler else runs[0][2] == 0


# --- the user's collision handlers beside rlenv's ----------------------------------------------


def _landing(tree: SceneTree, world: PhysicsWorld) -> tuple[RigidBody, list[object]]:
    body = ball(position=(0.0, 0.8))
    world.add_child(floor())
    world.add_child(body)
    signals: list[object] = []
    body.body_entered.connect(lambda other: signals.append(("entered", other.name)))
    body.body_exited.connect(lambda other: signals.append(("exited", other.name)))
    return body, signals


def test_a_user_s_handler_without_collision_types_runs_beside_rlenv_s_signals(
    tree: SceneTree,
    world: PhysicsWorld,
) -> None:
    """pymunk's catch-all handler is rlenv's, which emits the signals: a user's ``begin`` or
    ``separate`` there used to replace it, and ``body_entered`` stopped firing."""
    body, signals = _landing(tree, world)
    theirs: list[object] = []
    world.space.on_collision(
        begin=lambda arbiter, space, data: theirs.append(("begin", data)),
        separate=lambda arbiter, space, data: theirs.append(("end", data)),
        post_solve=lambda arbiter, space, data: theirs.append(data),
        data="mine",
    )
    ticks(tree, 30)
    assert signals[0] == ("entered", "Floor") and theirs[0] == ("begin", "mine")
    assert "mine" in theirs  # post_solve, with the user's data
    body.queue_free()  # its contact ends: both separates
    ticks(tree, 1)
    assert signals[-1] == ("exited", "Floor") and theirs[-1] == ("end", "mine")


def test_the_user_s_catch_all_handler_survives_a_restart_and_can_be_removed() -> None:
    tree = SceneTree(60)
    world = PhysicsWorld(gravity=(0.0, -10.0))
    tree.root.add_child(world)
    _, signals = _landing(tree, world)
    theirs: list[object] = []
    world.space.on_collision(begin=lambda arbiter, space, data: theirs.append(data), data=7)
    ticks(tree, 30)
    old = world.space
    world.restart()  # a contact began: a new space, the handlers carried over
    assert world.space is not old and theirs == [7]
    signals.clear()
    ticks(tree, 30)
    assert signals == [("entered", "Floor")] and theirs == [7, 7]
    world.space.on_collision(begin=pymunk.empty_callback)  # the user's goes, rlenv's stays
    world.restart()
    signals.clear()
    ticks(tree, 30)
    assert signals == [("entered", "Floor")] and theirs == [7, 7]


def test_a_duplicated_world_reports_its_own_contacts(tree: SceneTree) -> None:
    """The copy's space called the original world, which knew none of the copy's shapes."""
    world = PhysicsWorld(gravity=(0.0, -10.0), name="World")
    _landing(tree, world)
    copy = world.duplicate()
    copy.name = "Copy"
    tree.root.add_child(copy)
    copied: list[object] = []
    copy.get_node("Ball").body_entered.connect(copied.append)
    ticks(tree, 30)
    assert [node.name for node in copied] == ["Floor"]
