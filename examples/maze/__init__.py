"""Maze: find a goal you cannot see, behind walls, in a grid of rooms (a top-down world).

The levels of PLR and ACCEL's mazes, on pymunk: an agent (a small round body) moves on a
grid of 11 x 11 one-metre cells, the outer ring a wall, walls on some of the 9 x 9 cells
inside, and a goal (a sensor) on one free cell. The agent does not observe where it or the
goal is: it casts 16 rays (a :class:`~rlenv.RaycastSensor2D` on its body) and sees how far
each goes before a wall, and whether (and how near) the goal is along it. So levels differ in
what they teach: a goal in sight of the start is reached by walking to it, a goal behind walls
needs exploring.

Every reset builds a new level from the episode's seeded generator (walls at random cells, as
many as ``difficulty``, 0 to 1 and configurable, asks for; the agent's start and the goal on
two random free cells, the layout drawn again until the goal is reachable);
``reset(options={"level": data})`` plays a given level (the data of a
:class:`~rlenv.PackedScene`, e.g. an earlier episode's, read with
``client.get_property("World", "level")``), and ``client.edit_level(level, seed)`` edits one
for ACCEL (:meth:`MazeWorld._edit_level`: add a wall, remove a wall, move the goal, the goal
kept reachable)::

    Maze (MazeEnvironment)
    |___PhysicsFramesTimer
    |___Agent (MazeAgent)                 moves the agent's body, casts the rays, is rewarded
    |___World (MazeWorld)                 difficulty; builds everything at every reset
        |___Physics (PhysicsWorld)        no gravity
            |___Border (StaticBody)       the outer ring
            |___Level (Node2D)            the part built from the seed (or given)
            |   |___Walls (Node2D)        Wall, Wall2, ... one per walled cell
            |   |___Goal (Goal)           a sensor box on its cell
            |   |___Start (Marker2D)      where the agent starts
            |___Body (RigidBody)          the agent
                |___Eyes (RaycastSensor2D) its 16 rays

## Action Space
``Discrete(5)``: 0 stop, 1 up (+y), 2 down, 3 left (-x), 4 right; the agent's body moves at
``max_speed`` (3 m/s) that way for the step's 4 ticks (a fifth of a cell per step).

## Observation Space
``Box(0, 1, (34,), float32)``, for the 16 rays ``i`` (the ``i``-th at ``i * 22.5`` degrees
from +x, counter-clockwise, each :data:`RAY_LENGTH` = 6 m long, from the agent's centre):

| index   | observation                                                          | min | max |
|---------|----------------------------------------------------------------------|-----|-----|
| 0-15    | distance to the first wall along ray ``i`` / 6 (1: no wall in reach)  | 0   | 1   |
| 16-31   | 1 - distance to the goal along ray ``i`` / 6 if seen before a wall, else 0 | 0 | 1 |
| 32, 33  | the agent's velocity x and y, / (2 * ``max_speed``), + 0.5          | 0   | 1   |

## Rewards
``1 - 0.9 * steps / max_steps`` when the agent reaches the goal (MiniGrid's; ``max_steps`` is
250, configurable on the agent, ``steps`` counted from the reset and capped at ``max_steps``);
0 otherwise.

## Episode End
Terminated when the agent touches the goal. There is no time limit inside the environment
(``rlenv/Maze-v0``: 250 steps of 4 ticks).

## Starting State
The agent at rest on the level's ``Start``. Nothing else is random: a level plays the same
whatever the seed, and the same seed builds the same level on any server.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv import (
    CollisionShape,
    Marker2D,
    Node2D,
    PackedScene,
    PhysicsWorld,
    RaycastSensor2D,
    RigidBody,
    RLAgent,
    RLEnvironment,
    StaticBody,
)
from rlenv.levels import LevelWorld
from rlenv.protocol.errors import ErrorCode, RequestError

__all__ = [
    "ACTIONS",
    "EDITS",
    "LEVEL_CLASSES",
    "SIZE",
    "TARGET",
    "Goal",
    "MazeAgent",
    "MazeEnvironment",
    "MazeWorld",
    "Wall",
    "build_level",
    "cell_center",
    "cell_of",
    "edit_level",
    "grid_of",
    "main",
    "make_level",
    "shortest_path",
]

TARGET = f"{__name__}:MazeEnvironment"
"""What ``rlenv serve`` takes to serve this environment."""

SIZE = 11
"""Cells along a side, the outer ring (a wall) included: the agent moves on the 9 x 9 inside."""
HALF = SIZE / 2  # the grid spans [-HALF, HALF] in x and y; cells are 1 m
AGENT_RADIUS = 0.3
GOAL_SIZE = 0.8
RAYS = 16
RAY_LENGTH = 6.0
DENSITY = (0.1, 0.45)  # the fraction of inner cells walled: build_level's at difficulty 0 and 1
ACTIONS = ((0.0, 0.0), (0.0, 1.0), (0.0, -1.0), (-1.0, 0.0), (1.0, 0.0))
"""The direction of each action: stop, up, down, left, right."""

Cell = tuple[int, int]
"""A cell as (column, row), 0 to SIZE - 1 from the bottom left; the inside is 1 to SIZE - 2."""


def cell_center(cell: Cell) -> tuple[float, float]:
    """The world position of a cell's centre."""
    return (cell[0] + 0.5 - HALF, cell[1] + 0.5 - HALF)


def cell_of(position: Iterable[float]) -> Cell:
    """The cell a world position lies in."""
    x, y = position
    return (int(math.floor(x + HALF)), int(math.floor(y + HALF)))


def _inside(cell: Cell) -> bool:
    return 1 <= cell[0] <= SIZE - 2 and 1 <= cell[1] <= SIZE - 2


INSIDE = [(column, row) for row in range(1, SIZE - 1) for column in range(1, SIZE - 1)]
"""The cells inside the border, row by row."""


def shortest_path(walls: set[Cell], start: Cell, goal: Cell) -> list[Cell] | None:
    """A shortest path from ``start`` to ``goal`` by breadth-first search, or ``None``.

    The path's cells, both ends included, are 4-connected and avoid ``walls`` and the border.
    """
    if start in walls or goal in walls or not (_inside(start) and _inside(goal)):
        return None
    came: dict[Cell, Cell | None] = {start: None}
    queue = deque([start])
    while queue:
        cell = queue.popleft()
        if cell == goal:
            path = [cell]
            while came[path[-1]] is not None:
                path.append(came[path[-1]])  # type: ignore[arg-type]
            return path[::-1]
        for dx, dy in ((0, 1), (0, -1), (-1, 0), (1, 0)):
            step = (cell[0] + dx, cell[1] + dy)
            if step not in came and _inside(step) and step not in walls:
                came[step] = cell
                queue.append(step)
    return None


class Wall(StaticBody):
    """A walled cell: a static body with one 1 m box."""

    def __init__(self, name: str = "Wall") -> None:
        super().__init__(name=name)
        self.add_child(CollisionShape.box(1.0, 1.0, friction=0.0, color="dimgray", name="Block"))


class Goal(StaticBody):
    """The goal: a sensor box on its cell (touched, never bumped into)."""

    def __init__(self, name: str = "Goal") -> None:
        super().__init__(name=name)
        self.add_child(
            CollisionShape.box(GOAL_SIZE, GOAL_SIZE, sensor=True, color="limegreen", name="Patch")
        )


LEVEL_CLASSES = (Wall, Goal)
"""The classes a level's data may name besides rlenv's own."""


def _layout(rng: np.random.Generator, difficulty: float) -> tuple[set[Cell], Cell, Cell]:
    """Walls, start and goal, drawn again until the goal is reachable.

    One wall fewer after every 50 failed draws, so it ends.
    """
    count = int(round((DENSITY[0] + (DENSITY[1] - DENSITY[0]) * difficulty) * len(INSIDE)))
    tries = 0
    while True:
        chosen = rng.choice(len(INSIDE), size=count + 2, replace=False)
        walls = {INSIDE[int(index)] for index in chosen[:count]}
        start, goal = INSIDE[int(chosen[count])], INSIDE[int(chosen[count + 1])]
        if shortest_path(walls, start, goal) is not None:
            return walls, start, goal
        tries += 1
        if tries % 50 == 0 and count > 0:
            count -= 1


def _level_node(walls: Iterable[Cell], start: Cell, goal: Cell) -> Node2D:
    level = Node2D("Level")
    group = Node2D("Walls")
    level.add_child(group)
    template = Wall()
    for index, cell in enumerate(sorted(walls, key=lambda c: (c[1], c[0]))):
        wall = template.duplicate()
        wall.name = "Wall" if index == 0 else f"Wall{index + 1}"
        wall.position = cell_center(cell)
        group.add_child(wall)
    target = Goal()
    target.position = cell_center(goal)
    level.add_child(target)
    level.add_child(Marker2D("Start", position=cell_center(start)))
    return level


def make_level(walls: Iterable[Cell], start: Cell, goal: Cell) -> dict[str, Any]:
    """The data of a level with these walled cells, start and goal.

    The level :func:`build_level` would build with them, for ``reset(options={"level": ...})``;
    :func:`grid_of` reads it back.
    """
    return PackedScene.pack(_level_node(walls, start, goal)).to_data()


def build_level(rng: np.random.Generator, difficulty: float) -> Node2D:
    """A new level: walls on random inner cells, the start and the goal on free ones.

    10% of the inner cells are walled at difficulty 0, 45% at 1; the start and the goal are two
    random free cells, the goal reachable from the start.

    Args:
        rng: where every random choice comes from.
        difficulty: 0 (few walls) to 1 (many).
    """
    return _level_node(*_layout(rng, difficulty))


def grid_of(level: Mapping[str, Any]) -> tuple[set[Cell], Cell, Cell]:
    """The walled cells, the start cell and the goal cell of a level's data.

    A wall is a ``Wall`` below the level's ``Walls``, the goal the level's ``Goal``, the start
    its ``Start`` (positions composed from the level's root down; rotations are refused).

    Raises:
        ValueError: the data has no ``Goal`` or ``Start``, or turns a node.
    """
    root = level["root"]
    origin = _position(root)
    walls: set[Cell] = set()
    goal = start = None
    for child in root.get("children", []):
        _upright(child)
        if child.get("name") == "Walls":
            corner = origin + _position(child)
            for wall in child.get("children", []):
                if wall.get("class") == "Wall":
                    walls.add(cell_of(corner + _position(wall)))
        elif child.get("name") == "Goal" and child.get("class") == "Goal":
            goal = cell_of(origin + _position(child))
        elif child.get("name") == "Start":
            start = cell_of(origin + _position(child))
    _upright(root)
    if goal is None or start is None:
        raise ValueError("the level has no Goal or no Start: it is not a Maze level")
    return walls, start, goal


def _position(entry: Mapping[str, Any]) -> np.ndarray:
    return np.asarray(entry.get("properties", {}).get("position", (0.0, 0.0)), dtype=float)


def _upright(entry: Mapping[str, Any]) -> None:
    if entry.get("properties", {}).get("rotation", 0.0):
        raise ValueError(f"the level's {entry.get('name')} is rotated: a maze is upright")


EDITS = ("add", "remove", "goal")
"""The kinds of edit :func:`edit_level` makes, each drawn with equal odds: add a wall, remove a
wall, move the goal."""

_PLACES_TRIED = 16  # cells an edit tries for an added wall or a moved goal


def edit_level(level: dict[str, Any], rng: np.random.Generator, n_edits: int) -> dict[str, Any]:
    """``n_edits`` random edits of a level's data, each one of :data:`EDITS`.

    A wall is *added* on a free inner cell (not the start's, not the goal's) only where the goal
    stays reachable; the *goal moves* to a free inner cell reachable from the start (not the
    start's); a wall is *removed* when there is one. When no wall is there to remove, or none
    of 16 cells drawn fits, the edit does nothing. The result is a level as
    :func:`build_level` makes it (its walls renamed in order).

    Args:
        level: the data of a level (checked already: ``PackedScene.from_data``); not changed.
        rng: where every choice comes from.
        n_edits: how many edits to make (>= 1).

    Returns:
        The edited level's data.

    Raises:
        ValueError: the level is not a Maze level (see :func:`grid_of`).
    """
    walls, start, goal = grid_of(level)
    walls = {cell for cell in walls if _inside(cell)}
    for _ in range(n_edits):
        kind = EDITS[int(rng.integers(len(EDITS)))]
        if kind == "remove":
            if walls:
                ordered = sorted(walls)
                walls.discard(ordered[int(rng.integers(len(ordered)))])
            continue
        for _ in range(_PLACES_TRIED):
            cell = INSIDE[int(rng.integers(len(INSIDE)))]
            if cell in walls or cell in (start, goal):
                continue
            if kind == "add" and shortest_path(walls | {cell}, start, goal) is not None:
                walls.add(cell)
                break
            if kind == "goal" and shortest_path(walls, start, cell) is not None:
                goal = cell
                break
    return make_level(walls, start, goal)


class MazeWorld(LevelWorld):
    """The border, the agent's body and this episode's level (given, or from the seed)."""

    configurable = ("difficulty",)
    level_classes = LEVEL_CLASSES
    edit_level_data = staticmethod(edit_level)

    def __init__(self) -> None:
        super().__init__("World")
        self.difficulty = 0.5
        self.physics: PhysicsWorld | None = None
        self.body: RigidBody | None = None
        self.goal: Goal | None = None
        self.reached = False

    def check_config(self, config: Mapping[str, Any]) -> None:
        """Also refuse a difficulty outside [0, 1].

        Raises:
            RequestError: ``invalid_config``.
        """
        super().check_config(config)
        if "difficulty" in config and not 0.0 <= float(config["difficulty"]) <= 1.0:
            raise RequestError(
                ErrorCode.INVALID_CONFIG,
                f"MazeWorld.difficulty must be in [0, 1], got {config['difficulty']!r:.40}",
            )

    def reset(self, options: Mapping[str, Any]) -> None:
        """Build the border, a level (new, or the given one) and the agent on its start.

        Raises:
            PackedSceneError: ``options["level"]`` is not a level this environment may build.
            ValueError: the given level has no ``Goal`` or no ``Start``.
        """
        _, level = self.new_level(options)
        goal, start = level.get_node("Goal"), level.get_node("Start")  # as check_level wants
        if self.physics is not None:
            self.remove_child(self.physics)
        physics = self.physics = PhysicsWorld(gravity=(0.0, 0.0), name="Physics")
        physics.add_child(self._border())
        physics.add_child(level)
        body = self.body = RigidBody(position=tuple(start.global_position), name="Body")
        body.add_child(
            CollisionShape.circle(
                AGENT_RADIUS, mass=1.0, friction=0.0, color="crimson", name="Skin"
            )
        )
        body.add_child(RaycastSensor2D(n_rays=RAYS, ray_length=RAY_LENGTH, name="Eyes"))
        physics.add_child(body)
        self.goal = goal
        for shape in goal.get_children():
            if isinstance(shape, CollisionShape):
                shape.collision_started.connect(self._on_goal_touched)
        self.level_node = level
        self.reached = False
        self.add_child(physics)

    def check_level(self, level: Node2D) -> None:
        """Refuse a level without a ``Goal`` (a Goal) or a ``Start`` (a Node2D).

        Raises:
            ValueError: it has none.
        """
        if not isinstance(level.get_node_or_null("Goal"), Goal) or not isinstance(
            level.get_node_or_null("Start"), Node2D
        ):
            raise ValueError("the level has no Goal (a Goal) or no Start: it is not a Maze level")

    def build_level(self, rng: np.random.Generator) -> Node2D:
        """A new level (:func:`build_level`) at the world's difficulty."""
        return build_level(rng, self.difficulty)

    def get_data(self, observation_request: Mapping[str, Any]) -> dict[str, Any]:
        """The agent's position, the level's walls and fingerprint (its data's digest)."""
        assert self.body is not None and self.level_node is not None
        walls = self.level_node.get_node_or_null("Walls")
        return {
            "agent": list(self.body.position),
            "walls": walls.get_child_count() if walls is not None else 0,
            "level": self.level_id,
        }

    def _border(self) -> StaticBody:
        border = StaticBody(name="Border")
        for name, (x, y), (w, h) in (
            ("Bottom", (0.0, 0.5 - HALF), (SIZE, 1.0)),
            ("Top", (0.0, HALF - 0.5), (SIZE, 1.0)),
            ("Left", (0.5 - HALF, 0.0), (1.0, SIZE - 2.0)),
            ("Right", (HALF - 0.5, 0.0), (1.0, SIZE - 2.0)),
        ):
            border.add_child(
                CollisionShape.poly(
                    [
                        (x - w / 2, y - h / 2),
                        (x + w / 2, y - h / 2),
                        (x + w / 2, y + h / 2),
                        (x - w / 2, y + h / 2),
                    ],
                    friction=0.0,
                    color="dimgray",
                    name=name,
                )
            )
        return border

    def _on_goal_touched(self, other: CollisionShape) -> None:
        if other.body_node is self.body:
            self.reached = True


class MazeAgent(RLAgent):
    """Moves the agent's body, casts its rays; rewarded when it reaches the goal."""

    configurable = ("max_speed", "max_steps")
    action_space = spaces.Discrete(len(ACTIONS))
    observation_space = spaces.Box(0.0, 1.0, (2 * RAYS + 2,), np.float32)

    def __init__(self) -> None:
        super().__init__("Agent")
        self.max_speed = 3.0
        self.max_steps = 250
        self.direction = (0.0, 0.0)
        self.steps = 0

    def reset(self, arguments: Any) -> None:
        """The agent starts at rest; the steps count from 0."""
        self.direction = (0.0, 0.0)
        self.steps = 0

    def set_action(self, action: Any) -> None:
        """Remember the direction for the ticks of this action; count the step."""
        self.direction = ACTIONS[int(action)]
        self.steps += 1

    def _physics_process(self, delta: float) -> None:
        body = self._world().body
        if body is not None:
            body.velocity = (self.direction[0] * self.max_speed, self.direction[1] * self.max_speed)

    def _after_physics_tick(self, delta: float) -> None:
        world = self._world()
        if world.reached:  # the action stops at the end of this tick
            self.add_reward(1.0 - 0.9 * min(self.steps, self.max_steps) / self.max_steps)
            self.set_terminated()

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """The rays' wall and goal channels and the agent's velocity (see the module)."""
        world = self._world()
        assert world.body is not None and world.physics is not None and world.goal is not None
        goal = world.goal
        eyes = world.body.get_node("Eyes")
        observation = np.zeros(2 * RAYS + 2, dtype=np.float32)
        for index, crossed in enumerate(eyes.cast()):  # the goal is a sensor: rays cross it
            wall = next((d for d, node in crossed if node.body_node is not goal), RAY_LENGTH)
            seen = next((d for d, node in crossed if node.body_node is goal), RAY_LENGTH)
            observation[index] = wall / RAY_LENGTH
            observation[RAYS + index] = 1.0 - seen / RAY_LENGTH if seen < wall else 0.0
        vx, vy = world.body.velocity
        scale = 2.0 * self.max_speed
        observation[2 * RAYS :] = (vx / scale + 0.5, vy / scale + 0.5)
        return np.clip(observation, 0.0, 1.0)

    def _world(self) -> MazeWorld:
        world = self.environment.world
        assert isinstance(world, MazeWorld)
        return world


class MazeEnvironment(RLEnvironment):
    """Maze: an agent and a world under one node; a new level at every reset."""

    render_view = (-HALF - 0.2, -HALF - 0.2, HALF + 0.2, HALF + 0.2)
    render_size = (440, 440)
    reset_options = ("level",)

    def __init__(self) -> None:
        super().__init__("Maze", repeat_action=4)
        self.add_child(MazeAgent())
        self.add_child(MazeWorld())


def main() -> None:
    """Serve Maze: ``python -m examples.maze [--port P]``."""
    from rlenv_tools.cli import serve_command

    raise SystemExit(serve_command(TARGET))
