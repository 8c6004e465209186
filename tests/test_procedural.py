"""Building in code, the Blueprints way: lattices, gradients, placeholders, bulk sets."""

from __future__ import annotations

import math

import pytest

from rlenv import (
    CollisionShape,
    Marker2D,
    Node,
    Node2D,
    PhysicsWorld,
    RigidBody,
    StaticBody,
    View,
    gradient,
    view,
)
from rlenv.scene2d.colors import CSS_COLORS, to_rgb
from rlenv.tree import SceneTree


@pytest.fixture
def world(tree: SceneTree) -> PhysicsWorld:
    world = PhysicsWorld(gravity=(0.0, -9.81), name="World")
    tree.root.add_child(world)
    return world


def domino(position: tuple[float, float] = (0.0, 0.3)) -> RigidBody:
    body = RigidBody(name="Domino", position=position)
    body.add_child(CollisionShape.box(0.06, 0.6, density=1.0, friction=0.6, name="Tile"))
    return body


def floor() -> StaticBody:
    ground = StaticBody(name="Floor")
    ground.add_child(CollisionShape.segment((-5.0, 0.0), (20.0, 0.0), 0.05, friction=0.8))
    return ground


# --- lattices ------------------------------------------------------------------------------------


def test_a_row_of_dominos_topples_and_takes_a_gradient(
    tree: SceneTree, world: PhysicsWorld
) -> None:
    world.add_child(floor())
    first = domino()
    world.add_child(first)
    row = first.lattice((0.4, 0.0), 20)
    assert isinstance(row, View) and len(row) == 20 and row[0] is first
    assert [n.name for n in row][:3] == ["Domino", "Domino2", "Domino3"]
    assert [round(p.x, 9) for p in row.position] == [round(0.4 * i, 9) for i in range(20)]
    assert world.get_children()[1:] == row.nodes  # beside it, in lattice order
    colors = gradient("purple", "blue", n_steps=20)
    row.shapes.set("color", colors)
    assert row.shapes.color == colors
    assert len({id(body.body) for body in row}) == 20
    assert len({id(shape.shape) for shape in row.shapes}) == 20
    row[0].rotation = -math.tau / 32  # tip the first
    tree.paused = False
    for _ in range(400):
        tree.physics_tick()
    assert all(abs(angle) > 0.5 for angle in row.angle)  # every domino fell


def test_a_grid_puts_the_last_dimension_fastest() -> None:
    frame = Node2D("Frame")
    peg = Marker2D("Peg", position=(1.0, 2.0), rotation=0.25)
    frame.add_child(Node("Before"))
    frame.add_child(peg)
    frame.add_child(Node("After"))
    grid = peg.lattice([(1.0, 0.0), (0.0, -1.0)], (4, 3))
    assert len(grid) == 12 and grid[0] is peg
    expected = [(1.0 + i, 2.0 - j) for i in range(4) for j in range(3)]
    assert [tuple(n.position) for n in grid] == expected
    assert set(grid.rotation) == {0.25}
    names = [child.name for child in frame.get_children()]
    assert names[0] == "Before" and names[-1] == "After" and names[1:-1] == grid.name
    assert len(set(names)) == len(names)
    # a lattice of a lattice node keeps naming freely
    more = grid[-1].lattice((0.0, 5.0), [2])
    assert more[1].name not in names and len(frame.get_children()) == 15


def test_bad_lattices_are_refused() -> None:
    orphan = Node2D("Orphan")
    with pytest.raises(ValueError, match="no parent"):
        orphan.lattice((1.0, 0.0), 3)
    frame = Node2D("Frame")
    frame.add_child(orphan)
    with pytest.raises(ValueError, match="2 counts for 1 offset vectors"):
        orphan.lattice((1.0, 0.0), (3, 2))
    with pytest.raises(ValueError, match="at least 1"):
        orphan.lattice([(1.0, 0.0), (0.0, 1.0)], (3, 0))
    with pytest.raises(ValueError, match="shape"):
        orphan.lattice((0.0, 0.06, 0.0), 20)  # Blueprints' 3D vectors
    with pytest.raises(ValueError, match="finite"):
        orphan.lattice((math.nan, 0.0), 2)
    assert frame.get_child_count() == 1  # nothing was added


def test_restart_puts_every_copy_back_where_it_was_placed(
    tree: SceneTree, world: PhysicsWorld
) -> None:
    world.add_child(floor())
    balls = Node2D("Balls", position=(0.0, 2.0))
    ball = RigidBody(name="Ball", position=(0.0, 0.0))
    ball.add_child(CollisionShape.circle(0.2, mass=1.0, elasticity=0.5))
    balls.add_child(ball)
    row = ball.lattice([(0.5, 0.0), (0.0, 0.5)], (3, 2))
    world.add_child(balls)
    placed = [tuple(b.body.position) for b in row]
    assert placed == [(0.5 * i, 2.0 + 0.5 * j) for i in range(3) for j in range(2)]
    tree.paused = False
    for _ in range(90):
        tree.physics_tick()
    assert [tuple(b.body.position) for b in row] != placed
    world.restart()
    assert [tuple(b.body.position) for b in row] == placed


# --- gradients and colours --------------------------------------------------------------------


def test_gradients_go_from_first_to_last_exactly() -> None:
    steps = gradient("purple", "blue", n_steps=20)
    assert len(steps) == 20 and steps[0] == (128, 0, 128) and steps[-1] == (0, 0, 255)
    assert all(isinstance(c, int) and 0 <= c <= 255 for step in steps for c in step)
    reds = [step[0] for step in steps]
    assert reds == sorted(reds, reverse=True)  # monotone on the way
    assert gradient("#ff0000", (0, 255, 0), "blue", n_steps=5) == [
        (255, 0, 0),
        (128, 128, 0),
        (0, 255, 0),
        (0, 128, 128),
        (0, 0, 255),
    ]
    assert gradient("Teal", n_steps=3) == [(0, 128, 128)] * 3
    assert gradient("red", "blue", n_steps=1) == [(255, 0, 0)]
    assert to_rgb("#f30") == (255, 51, 0) and len(CSS_COLORS) == 148


@pytest.mark.parametrize(
    ("colors", "steps", "error", "match"),
    [
        (("notacolor",), 3, ValueError, "CSS colour name"),
        (("#12345",), 3, ValueError, "#rrggbb"),
        (((1, 2, 300),), 3, ValueError, r"\[0, 255\]"),
        (((1.5, 2, 3),), 3, TypeError, "integers"),
        ((), 3, ValueError, "at least one colour"),
        (("red",), 0, ValueError, "at least 1"),
    ],
)
def test_bad_colours_are_refused(colors: tuple, steps: int, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        gradient(*colors, n_steps=steps)


def test_shapes_and_bodies_take_any_colour_form() -> None:
    body = RigidBody(name="B")
    body.add_child(CollisionShape.circle(0.1, color="steelblue"))
    body.add_child(CollisionShape.circle(0.2))
    assert body.get_child(0).color == (70, 130, 180)
    body.color = "#010203"
    assert [shape.color for shape in body.get_children()] == [(1, 2, 3)] * 2
    assert body.color == (1, 2, 3)
    with pytest.raises(ValueError, match="CSS colour"):
        body.get_child(0).color = "bleu"


def test_view_set_gives_one_value_per_node() -> None:
    frame = Node2D("Frame")
    for index in range(3):
        frame.add_child(Marker2D(f"M{index}"))
    markers = view(frame).children
    markers.set("position", [(0.0, 1.0), (2.0, 3.0), (4.0, 5.0)])
    assert [tuple(p) for p in markers.position] == [(0.0, 1.0), (2.0, 3.0), (4.0, 5.0)]
    with pytest.raises(ValueError, match="2 values for the 3 nodes"):
        markers.set("rotation", [0.0, 1.0])


# --- placeholders --------------------------------------------------------------------------------


def table() -> StaticBody:
    top = StaticBody(name="Table", position=(0.0, 1.0))
    top.add_child(CollisionShape.box(2.0, 0.1, color="saddlebrown", name="Top"))
    for x in (0.9, -0.9):
        top.add_child(Marker2D("leg", position=(x, 0.0), rotation=math.pi))
    top.add_child(Marker2D("plate", position=(-0.7, 0.05)))
    top.add_child(Marker2D("plate", position=(0.7, 0.05)))
    return top


def test_a_table_gets_its_legs_and_plates(tree: SceneTree, world: PhysicsWorld) -> None:
    furniture = table()
    leg = RigidBody(name="Leg")
    leg.add_child(CollisionShape.segment((0.0, 0.0), (0.0, 1.0), 0.03, mass=0.5))
    bowl = RigidBody(name="Bowl", position=(0.0, 0.1))
    bowl.add_child(CollisionShape.circle(0.1, mass=0.2))
    assert furniture.placeholders.name == ["leg", "leg2", "plate", "plate2"]
    legs = furniture.placeholders.named("leg*").attach(leg)
    bowls = furniture.placeholders["plate*"].attach(bowl)
    assert len(legs) == 2 and len(bowls) == 2 and leg.parent is None  # the template stays
    assert [copy.parent.name for copy in legs] == ["leg", "leg2"]
    world.add_child(furniture)
    # a leg hangs from its marker, turned half round with it: from the top down to the floor
    assert legs[0].body.position == pytest.approx((0.9, 1.0))
    assert legs[0].body.local_to_world((0.0, 1.0)) == pytest.approx((0.9, 0.0))
    assert bowls[1].body.position == pytest.approx((0.7, 1.15))
    assert furniture.placeholders.named("plate*").children.name == ["Bowl", "Bowl"]
    assert len({id(b.body) for b in [*legs, *bowls]}) == 4


def test_a_marker_attaches_one_copy_and_views_only_markers() -> None:
    mount = Marker2D("Mount", position=(1.0, 0.0))
    thing = Node2D("Thing", position=(0.0, 1.0))
    copy = mount.attach(thing)
    assert copy.parent is mount and copy is not thing
    assert copy.global_position == pytest.approx((1.0, 1.0))
    assert mount.placeholders.name == []  # below it, not itself
    with pytest.raises(TypeError, match="not a Marker2D"):
        view(mount, thing).attach(thing)
    assert mount.get_child_count() == 1  # nothing attached on refusal
    assert View([]).attach(thing).nodes == []


def test_a_lattice_made_during_a_tick_lands_after_the_pass(tree: SceneTree) -> None:
    class Spawner(Node2D):
        made: View | None = None

        def _physics_process(self, delta: float) -> None:
            if self.made is None:
                self.made = self.get_node("Seed").lattice((1.0, 0.0), 3)

    spawner = Spawner("Spawner")
    spawner.add_child(Marker2D("Seed"))
    spawner.add_child(Marker2D("Tail"))
    tree.root.add_child(spawner)
    tree.paused = False
    tree.physics_tick()
    assert spawner.made is not None
    assert [child.name for child in spawner.get_children()] == ["Seed", "Seed2", "Seed3", "Tail"]
    assert all(node.is_inside_tree() for node in spawner.made)
