"""RaycastSensor2D: distances along rays in a real pymunk space, and what each ray hit."""

from __future__ import annotations

import math

import numpy as np
import pymunk
import pytest

from rlenv.scene2d.packed_scene import PackedScene, PackedSceneError
from rlenv.scene2d.physics import CollisionShape, PhysicsWorld, RigidBody, StaticBody
from rlenv.scene2d.raycast_sensor import RaycastSensor2D
from rlenv.tree import SceneTree


@pytest.fixture
def world(tree: SceneTree) -> PhysicsWorld:
    world = PhysicsWorld(gravity=(0.0, 0.0), name="World")
    tree.root.add_child(world)
    return world


def _walls(half: float = 2.0) -> StaticBody:
    """Four segments around the origin, ``half`` metres away."""
    walls = StaticBody(name="Walls")
    corners = [(-half, -half), (half, -half), (half, half), (-half, half)]
    for index, (a, b) in enumerate(zip(corners, corners[1:] + corners[:1], strict=True)):
        walls.add_child(CollisionShape.segment(a, b, 0.0, name=f"Wall{index}"))
    return walls


def _disc(position: tuple[float, float] = (0.0, 0.0), **sensor: object) -> RigidBody:
    disc = RigidBody(position=position, name="Disc")
    disc.add_child(CollisionShape.circle(0.3, mass=1.0, name="Body"))
    disc.add_child(RaycastSensor2D(name="Eyes", **sensor))  # type: ignore[arg-type]
    return disc


def test_each_ray_reads_the_distance_to_the_nearest_wall(world: PhysicsWorld) -> None:
    world.add_child(_walls())
    disc = _disc((0.5, 0.0), n_rays=4, ray_length=5.0)
    world.add_child(disc)
    eyes = disc.get_node("Eyes")
    distances = eyes.distances()
    assert distances.dtype == np.float32 and distances.shape == (4,)
    # +x, +y, -x, -y from (0.5, 0): the disc's own circle is left out
    np.testing.assert_allclose(distances, [1.5, 2.0, 2.5, 2.0], rtol=1e-6)
    assert [hit.name if hit else None for hit in eyes.hits()] == [
        "Wall1",
        "Wall2",
        "Wall3",
        "Wall0",
    ]


def test_a_ray_that_hits_nothing_reads_its_length(world: PhysicsWorld) -> None:
    disc = _disc(n_rays=3, ray_length=4.0, cone_width=math.pi / 2)
    world.add_child(disc)
    eyes = disc.get_node("Eyes")
    np.testing.assert_array_equal(eyes.distances(), np.full(3, 4.0, np.float32))
    assert eyes.hits() == [None, None, None]


def test_the_rays_turn_with_the_body(world: PhysicsWorld) -> None:
    world.add_child(_walls())
    disc = _disc((0.5, 0.0), n_rays=1, ray_length=5.0, cone_width=0.0)
    world.add_child(disc)
    eyes = disc.get_node("Eyes")
    assert eyes.distances()[0] == pytest.approx(1.5)
    disc.rotation = math.pi  # now looking along -x
    assert eyes.distances()[0] == pytest.approx(2.5)


def test_a_cone_spreads_its_rays_evenly_and_a_full_turn_starts_straight_ahead() -> None:
    np.testing.assert_allclose(
        RaycastSensor2D(n_rays=3, cone_width=math.pi / 2).angles(), [-math.pi / 4, 0.0, math.pi / 4]
    )
    np.testing.assert_allclose(
        RaycastSensor2D(n_rays=4).angles(), [0.0, math.pi / 2, math.pi, 3 * math.pi / 2]
    )
    assert RaycastSensor2D(n_rays=1, cone_width=1.0).angles().tolist() == [0.0]


def test_the_collision_mask_and_sensors_choose_what_stops_a_ray(world: PhysicsWorld) -> None:
    world.add_child(_walls())
    near = StaticBody(name="Near")
    post = CollisionShape.circle(0.1, offset=(1.0, 0.0), name="Post")
    post.shape.filter = pymunk.ShapeFilter(categories=0b10)
    near.add_child(post)
    area = StaticBody(name="Area")
    area.add_child(CollisionShape.circle(0.1, offset=(0.5, 0.0), sensor=True, name="Zone"))
    world.add_child(near)
    world.add_child(area)
    sees_all = _disc(n_rays=1, cone_width=0.0)
    world.add_child(sees_all)
    eyes = sees_all.get_node("Eyes")
    assert eyes.distances()[0] == pytest.approx(0.9)  # the post; the sensor is passed through
    eyes.collide_with_sensors = True
    assert eyes.distances()[0] == pytest.approx(0.4)
    assert eyes.hits()[0].name == "Zone"
    eyes.collide_with_sensors = False
    eyes.collision_mask = 0b01  # the post's layer is not seen
    assert eyes.distances()[0] == pytest.approx(2.0)


def test_cast_lists_everything_a_ray_crosses_nearest_first(world: PhysicsWorld) -> None:
    world.add_child(_walls())
    area = StaticBody(name="Area")
    area.add_child(CollisionShape.circle(0.1, offset=(1.0, 0.0), sensor=True, name="Zone"))
    world.add_child(area)
    disc = _disc(n_rays=2, ray_length=5.0, cone_width=math.pi)  # along -y, then +y
    world.add_child(disc)
    disc.rotation = math.pi / 2  # along +x, then -x
    along_x, along_minus_x = disc.get_node("Eyes").cast()
    assert [node.name for _, node in along_x] == ["Zone", "Wall1"]
    np.testing.assert_allclose([distance for distance, _ in along_x], [0.9, 2.0], rtol=1e-6)
    assert [node.name for _, node in along_minus_x] == ["Wall3"]
    assert disc.get_node("Eyes").distances().tolist() == pytest.approx([2.0, 2.0])


def test_exclude_parent_false_sees_the_own_body(world: PhysicsWorld) -> None:
    disc = _disc(n_rays=1, ray_length=1.0, exclude_parent=False)
    world.add_child(disc)
    assert disc.get_node("Eyes").distances()[0] == 0.0


def test_reading_a_sensor_leaves_the_simulation_bit_for_bit_the_same(tree: SceneTree) -> None:
    def run(read: bool) -> list[tuple[float, ...]]:
        scene = SceneTree(60)
        world = PhysicsWorld(gravity=(0.0, -9.8), name="World")
        scene.root.add_child(world)
        world.add_child(_walls())
        disc = _disc((0.3, 0.7), n_rays=8)
        world.add_child(disc)
        disc.body.velocity = (3.0, 1.0)
        eyes = disc.get_node("Eyes")
        trajectory = []
        for _ in range(200):
            scene.physics_tick()
            if read:
                eyes.distances()
            trajectory.append((*disc.body.position, *disc.body.velocity, disc.body.angle))
        return trajectory

    assert run(read=True) == run(read=False)


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        ({"n_rays": 0}, r"n_rays must be an integer in \[1, 1024\]"),
        ({"n_rays": 2.5}, "n_rays must be an integer"),
        ({"n_rays": 10**9}, "n_rays must be an integer"),
        ({"ray_length": 0.0}, "ray_length must be more than 0"),
        ({"ray_length": math.nan}, "ray_length"),
        ({"cone_width": -1.0}, "cone_width"),
        ({"collision_mask": -1}, "collision_mask must be an integer"),
        ({"exclude_parent": 1}, "exclude_parent must be true or false"),
    ],
)
def test_bad_arguments_are_refused_by_name(arguments: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        RaycastSensor2D(**arguments)  # type: ignore[arg-type]


def test_a_sensor_outside_a_world_says_so(tree: SceneTree) -> None:
    eyes = RaycastSensor2D()
    tree.root.add_child(eyes)
    with pytest.raises(RuntimeError, match="below a PhysicsWorld"):
        eyes.distances()


def test_a_sensor_packs_as_data_and_comes_back_the_same(world: PhysicsWorld) -> None:
    world.add_child(_walls())
    disc = _disc(
        (0.5, 0.0),
        n_rays=5,
        ray_length=3.0,
        cone_width=1.0,
        collision_mask=0b11,
        collide_with_sensors=True,
    )
    world.add_child(disc)
    data = PackedScene.pack(disc).to_data()
    eyes = next(child for child in data["root"]["children"] if child["name"] == "Eyes")
    assert eyes["class"] == "RaycastSensor2D"
    assert eyes["properties"] == {
        "position": [0.0, 0.0],
        "n_rays": 5,
        "ray_length": 3.0,
        "cone_width": 1.0,
        "collision_mask": 3,
        "collide_with_sensors": True,
    }
    world.remove_child(disc)
    copy = PackedScene.from_data(data).instantiate()
    world.add_child(copy)
    built = copy.get_node("Eyes")
    assert isinstance(built, RaycastSensor2D)
    assert (built.n_rays, built.ray_length, built.cone_width) == (5, 3.0, 1.0)
    np.testing.assert_allclose(built.distances()[2], 1.5, rtol=1e-6)


def test_level_data_asking_for_too_many_rays_is_refused_before_building() -> None:
    data = PackedScene.pack(RaycastSensor2D(name="Eyes")).to_data()
    data["root"]["properties"] = {"n_rays": 10**7}
    with pytest.raises(PackedSceneError, match="n_rays must be an integer in"):
        PackedScene.from_data(data)
