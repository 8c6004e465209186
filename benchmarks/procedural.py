"""What building levels in code costs: ``python benchmarks/procedural.py [--rounds R]``.

Prints, in one run, each figure beside its baseline (rounds taken in turns, median and min):

- **duplicate, per node**: ``Node.duplicate()`` of a Plinko peg (a StaticBody and its
  CollisionShape: 2 nodes) and of a hinged pendulum (a Node2D frame, two bodies, two shapes and
  a pivot joint: 6 nodes), against building the same nodes with their constructors, and
  against raw pymunk making the same bodies, shapes and constraint (no nodes at all);
- **a 500-body lattice level at a reset**: Plinko's level builder with 25 columns and 20 rows
  of pegs (lattices, jitter through ``view.set``, gradients, bins on placeholders), then the
  level entering a PhysicsWorld inside a tree (every body and shape into the pymunk space),
  then a whole environment reset of that Plinko (board, catcher, ball, level, observation,
  through ``LocalClient.reset``); against raw pymunk building the same bodies and shapes
  (same kinds, poses and settings) into a new space.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np
import pymunk

from rlenv import CollisionShape, Joint, Node2D, PhysicsWorld, RigidBody, RLEnvironment, StaticBody
from rlenv.examples.plinko import Peg as PlinkoPeg
from rlenv.examples.plinko import PlinkoAgent, PlinkoWorld, build_level
from rlenv.scene2d.physics import PhysicsBody
from rlenv.tree import SceneTree
from rlenv_client import LocalClient

COLUMNS, ROWS = 25, 20
COPIES = 400  # duplicates per round


class BigPlinkoWorld(PlinkoWorld):
    """Plinko's world with 25 x 20 rows of pegs: about 500 bodies per level."""

    columns = COLUMNS
    rows = ROWS


class BigPlinko(RLEnvironment):
    """Plinko with the big levels."""

    def __init__(self) -> None:
        super().__init__("Plinko")
        self.add_child(PlinkoAgent())
        self.add_child(BigPlinkoWorld())


def timed(*runs: Callable[[], object], rounds: int) -> list[tuple[float, float]]:
    """(median, min) seconds of each ``run()``, rounds taken in turns after a warm-up.

    A run that returns a number has timed itself (leaving out what it had to prepare).
    """
    for run in runs:
        run()
    times: list[list[float]] = [[] for _ in runs]
    for _ in range(rounds):
        for run, kept in zip(runs, times, strict=True):
            start = time.perf_counter()
            took = run()
            kept.append(took if isinstance(took, float) else time.perf_counter() - start)
    return [(statistics.median(kept), min(kept)) for kept in times]


def pendulum() -> Node2D:
    rig = Node2D("Rig", position=(0.0, 3.0))
    anchor = StaticBody(name="Anchor")
    anchor.add_child(CollisionShape.circle(0.05, sensor=True))
    bob = RigidBody(name="Bob", position=(1.0, 0.0))
    bob.add_child(CollisionShape.circle(0.1, mass=1.0, friction=0.9, elasticity=0.4))
    rig.add_child(anchor)
    rig.add_child(bob)
    rig.add_child(Joint.pivot("../Anchor", "../Bob", (0.0, 0.0), name="Hinge"))
    return rig


def raw_peg() -> None:
    body = pymunk.Body(body_type=pymunk.Body.STATIC)
    body.position = (1.0, 2.0)
    shape = pymunk.Circle(body, 0.1)
    shape.elasticity, shape.friction = 0.55, 0.2


def raw_pendulum() -> None:
    anchor = pymunk.Body(body_type=pymunk.Body.STATIC)
    anchor.position = (0.0, 3.0)
    sensor = pymunk.Circle(anchor, 0.05)
    sensor.sensor = True
    bob = pymunk.Body()
    bob.position = (1.0, 3.0)
    skin = pymunk.Circle(bob, 0.1)
    skin.mass, skin.friction, skin.elasticity = 1.0, 0.9, 0.4
    pymunk.PivotJoint(anchor, bob, (0.0, 3.0))


def per_node(make: Callable[[], object], count: int, nodes: int) -> Callable[[], None]:
    def run() -> None:
        for _ in range(count):
            make()

    run.per = count * nodes  # type: ignore[attr-defined]
    return run


def level_recipe(level: Node2D) -> list[tuple[tuple[float, float, float], list[pymunk.Shape]]]:
    """The level's bodies as raw data: each body's pose and its shapes (to copy)."""
    world = PhysicsWorld()
    tree = SceneTree(60)
    tree.root.add_child(world)
    world.add_child(level)
    recipe = []
    for node in level.iter_subtree():
        if isinstance(node, PhysicsBody):
            shapes = [
                child.shape for child in node.get_children() if isinstance(child, CollisionShape)
            ]
            recipe.append(((*node.body.position, node.body.angle), shapes))
    return recipe


def raw_level(recipe: list[tuple[tuple[float, float, float], list[pymunk.Shape]]]) -> None:
    """The floor: the same static bodies and shapes, built and added with pymunk alone."""
    space = pymunk.Space()
    space.gravity = (0.0, -9.81)
    for (x, y, angle), shapes in recipe:
        body = pymunk.Body(body_type=pymunk.Body.STATIC)
        body.angle = angle
        body.position = (x, y)
        made = []
        for shape in shapes:
            if isinstance(shape, pymunk.Circle):
                copy: pymunk.Shape = pymunk.Circle(body, shape.radius, shape.offset)
            elif isinstance(shape, pymunk.Segment):
                copy = pymunk.Segment(body, shape.a, shape.b, shape.radius)
            else:
                copy = pymunk.Poly(body, shape.get_vertices(), radius=shape.radius)
            copy.friction, copy.elasticity = shape.friction, shape.elasticity
            copy.sensor = shape.sensor
            made.append(copy)
        space.add(body, *made)


def main() -> None:
    """Measure and print every figure."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=9)
    rounds = parser.parse_args().rounds

    peg, rig = PlinkoPeg(elasticity=0.55), pendulum()
    runs = [
        per_node(peg.duplicate, COPIES, 2),
        per_node(PlinkoPeg, COPIES, 2),
        per_node(raw_peg, COPIES, 2),
        per_node(rig.duplicate, COPIES // 3, 6),
        per_node(pendulum, COPIES // 3, 6),
        per_node(raw_pendulum, COPIES // 3, 6),
    ]
    (dup, new, raw, rig_dup, rig_new, rig_raw) = [
        (median / run.per * 1e6, least / run.per * 1e6)  # type: ignore[attr-defined]
        for (median, least), run in zip(timed(*runs, rounds=rounds), runs, strict=True)
    ]
    print(f"duplicate, microseconds per node (median, min of {rounds} rounds taken in turns)")
    for label, (ours, made, bare) in (
        ("Plinko peg (StaticBody + CollisionShape)", (dup, new, raw)),
        ("pendulum (frame, 2 bodies, 2 shapes, joint)", (rig_dup, rig_new, rig_raw)),
    ):
        print(
            f"  {label}: duplicate {ours[0]:.1f} (min {ours[1]:.1f}); constructors "
            f"{made[0]:.1f} (min {made[1]:.1f}); raw pymunk objects {bare[0]:.1f} "
            f"(min {bare[1]:.1f}); duplicate / constructors {ours[0] / made[0]:.2f}x, "
            f"/ raw pymunk {ours[0] / bare[0]:.1f}x"
        )

    rng = np.random.default_rng(0)
    probe = build_level(rng, 0.5, COLUMNS, ROWS)
    bodies = sum(isinstance(node, PhysicsBody) for node in probe.iter_subtree())
    recipe = level_recipe(probe)
    tree = SceneTree(60)
    waiting: list[Node2D] = []
    client = LocalClient(BigPlinko)
    seeds = iter(range(10**6))

    def build() -> None:
        waiting.append(build_level(np.random.default_rng(1), 0.5, COLUMNS, ROWS))

    def enter() -> float:
        world = PhysicsWorld(gravity=(0.0, -9.81))
        world.add_child(waiting.pop())
        start = time.perf_counter()
        tree.root.add_child(world)
        took = time.perf_counter() - start
        tree.root.remove_child(world)
        return took

    def reset() -> None:
        client.reset(seed=next(seeds))

    (built, entered, whole, bare) = [
        (median * 1e3, least * 1e3)
        for median, least in timed(build, enter, reset, lambda: raw_level(recipe), rounds=rounds)
    ]
    print(
        f"a {bodies}-body lattice level ({COLUMNS} x {ROWS} pegs, bins on placeholders) at "
        f"a reset, milliseconds (median, min of {rounds} rounds taken in turns)"
    )
    print(
        f"  build (lattices, jitter, gradients, placeholders) {built[0]:.1f} (min "
        f"{built[1]:.1f}); enter the space {entered[0]:.1f} (min {entered[1]:.1f}); "
        f"together {built[0] + entered[0]:.1f}"
    )
    print(
        f"  whole Plinko reset (board, catcher, ball, that level, observation) {whole[0]:.1f} "
        f"(min {whole[1]:.1f})"
    )
    print(
        f"  raw pymunk, the same bodies and shapes into a new space: {bare[0]:.1f} (min "
        f"{bare[1]:.1f}); build + enter / raw {(built[0] + entered[0]) / bare[0]:.1f}x, "
        f"whole reset / raw {whole[0] / bare[0]:.1f}x"
    )
    client.close()


if __name__ == "__main__":
    main()
