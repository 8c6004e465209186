"""Plinko: a ball falls through a lattice of pegs into bins; move the catcher to catch it.

Every reset builds a new level from the episode's seeded generator, in a few lines, the
Blueprints way (see docs/procedural.md): a peg is made once and multiplied by
:meth:`~rlenv.Node2D.lattice` into two staggered grids, every peg is jittered with
``view.set``, the rows are coloured by a :func:`~rlenv.gradient`, and the bins' dividers and
coloured floors are copies mounted on :class:`~rlenv.Marker2D` placeholders. The spaces never
change, and ``difficulty`` (0 to 1, configurable) makes levels with more rows, more jitter,
bouncier pegs, more bins and a narrower catcher. ``reset(options={"level": data})`` plays a
given level (the data of a :class:`~rlenv.PackedScene`, e.g. an earlier episode's, read with
``client.get_property("World", "level")``), and ``client.edit_level(level, seed)`` edits one
for ACCEL (:meth:`PlinkoWorld._edit_level`: move, add or remove a peg, change a peg's
bounciness)::

    Plinko (PlinkoEnvironment)
    |___PhysicsFramesTimer
    |___Agent (PlinkoAgent)               moves the catcher, observes, is rewarded
    |___World (PlinkoWorld)               difficulty; builds everything at every reset
        |___Physics (PhysicsWorld)
            |___Walls (StaticBody)        the sides and the floor
            |___Catcher (KinematicBody)   a cup with a Pocket sensor
            |___Ball (RigidBody)
            |___Level (Node2D)            the part built from the seed (or given)
                |___Pegs (Node2D)         Peg, Peg2, ... (two lattices, jittered, coloured)
                |___Bins (Node2D)         divider* and bin* markers, a Divider or a BinFloor
                                          attached on each

## Action Space
``Box(-1, 1, (1,), float32)``: the catcher's horizontal velocity, as a fraction of
``max_speed`` (6 m/s); the catcher stops at the walls.

## Observation Space
``Box((6,), float32)``:

| index | observation                 | min  | max |
|-------|-----------------------------|------|-----|
| 0     | catcher position x (m)      | -4   | 4   |
| 1     | catcher velocity x (m/s)    | -6   | 6   |
| 2     | ball position x (m)         | -5   | 5   |
| 3     | ball position y (m)         | -1   | 12  |
| 4     | ball velocity x (m/s)       | -30  | 30  |
| 5     | ball velocity y (m/s)       | -30  | 30  |

## Rewards
+1 when the ball lands in the catcher's pocket; 0 otherwise.

## Episode End
Terminated when the ball lands in the catcher or on the floor (in a bin). There is no time
limit inside the environment (``rlenv/Plinko-v0``: 100 steps of 4 ticks).

## Starting State
The ball at the top, at x uniform in [-3, 3] with a small sideways velocity, the catcher at
rest in the middle, then the level: all drawn from the seeded generator, the ball first, so
that a given level with the same seed starts the same episode.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv import (
    CollisionShape,
    KinematicBody,
    Marker2D,
    Node2D,
    PhysicsWorld,
    RigidBody,
    RLAgent,
    RLEnvironment,
    StaticBody,
    gradient,
    view,
)
from rlenv.levels import LevelWorld
from rlenv.protocol.errors import ErrorCode, RequestError

__all__ = [
    "LEVEL_CLASSES",
    "TARGET",
    "BinFloor",
    "Divider",
    "EDITS",
    "Peg",
    "PlinkoAgent",
    "PlinkoEnvironment",
    "PlinkoWorld",
    "build_level",
    "edit_level",
    "follow",
    "main",
]

TARGET = f"{__name__}:PlinkoEnvironment"
"""What ``rlenv serve`` takes to serve this environment."""

HALF_WIDTH = 4.0  # the board spans [-4, 4] in x
TOP = 11.0
PEG_TOP, PEG_BOTTOM = 9.4, 2.6  # the rows of pegs lie between these heights
BALL_RADIUS = 0.15
PEG_RADIUS = 0.1
MAX_JITTER = 0.12  # a peg moves at most this far: the ball always fits between pegs
SIDE_MARGIN = 0.2  # and between the walls and the pegs
CATCHER_HEIGHT = 1.2
DIVIDER_HEIGHT = 0.8
BOUNCINESS = (0.3, 0.8)  # a peg's elasticity: build_level's at difficulty 0 and 1
PEG_EDGE = HALF_WIDTH - 0.05 - 2 * BALL_RADIUS - PEG_RADIUS  # the ball passes a wall and a peg
PEG_GAP = 2 * (PEG_RADIUS + BALL_RADIUS)  # centre to centre: the ball passes between two pegs
PALETTE = (
    "purple",
    "blue",
    "teal",
    "seagreen",
    "darkorange",
    "crimson",
    "gold",
    "deeppink",
    "royalblue",
    "mediumvioletred",
    "limegreen",
    "sienna",
)
"""The colours a level's gradients go between."""


def follow(observation: np.ndarray) -> np.ndarray:
    """Keep the catcher under the ball: a policy that catches most balls."""
    catcher, ball = float(observation[0]), float(observation[2])
    return np.array([np.clip((ball - catcher) * 3.0, -1.0, 1.0)], dtype=np.float32)


class Peg(StaticBody):
    """A round peg: a static body with one circle."""

    def __init__(
        self, radius: float = PEG_RADIUS, elasticity: float = 0.5, name: str = "Peg"
    ) -> None:
        super().__init__(name=name)
        self.add_child(
            CollisionShape.circle(radius, elasticity=elasticity, friction=0.2, name="Skin")
        )


class Divider(StaticBody):
    """A wall between two bins."""

    def __init__(self, height: float = DIVIDER_HEIGHT, name: str = "Divider") -> None:
        super().__init__(name=name)
        self.add_child(
            CollisionShape.segment(
                (0.0, 0.0), (0.0, height), 0.04, elasticity=0.2, color="dimgray", name="Wall"
            )
        )


class BinFloor(StaticBody):
    """The coloured floor of a bin: a sensor strip (drawn, never touched)."""

    def __init__(self, width: float = 1.0, name: str = "BinFloor") -> None:
        super().__init__(name=name)
        self.add_child(CollisionShape.box(width, 0.16, sensor=True, name="Patch"))


LEVEL_CLASSES = (Peg, Divider, BinFloor)
"""The classes a level's data may name besides rlenv's own."""


def build_level(
    rng: np.random.Generator, difficulty: float, columns: int = 8, rows: int | None = None
) -> Node2D:
    """A new level: staggered jittered pegs coloured by rows, bins on placeholders.

    Args:
        rng: where every random choice comes from.
        difficulty: 0 (few rows, regular, soft pegs, 4 bins) to 1 (more of everything).
        columns: pegs in the wide rows (they share the board's 8 m whatever their number).
        rows: rows of pegs; by default 5 to 10, more with difficulty.
    """
    rows = rows or 5 + int(round(5 * difficulty)) - int(rng.integers(0, 2))
    colors = [PALETTE[i] for i in rng.choice(len(PALETTE), size=3, replace=False)]
    level = Node2D("Level")

    dx = 2 * (HALF_WIDTH - SIDE_MARGIN) / columns
    dy = (PEG_TOP - PEG_BOTTOM) / (rows - 1)
    pegs = Node2D("Pegs", position=(-HALF_WIDTH + SIDE_MARGIN + dx / 2, PEG_TOP))
    level.add_child(pegs)
    peg = Peg(elasticity=0.3 + 0.5 * difficulty)
    pegs.add_child(peg)
    wide = peg.lattice([(0.0, -2 * dy), (dx, 0.0)], ((rows + 1) // 2, columns))
    narrow_peg = peg.duplicate()
    narrow_peg.position = (dx / 2, -dy)
    pegs.add_child(narrow_peg)
    narrow = narrow_peg.lattice([(0.0, -2 * dy), (dx, 0.0)], (rows // 2, columns - 1))
    row_colors = gradient(colors[0], colors[1], n_steps=rows)
    wide.shapes.set("color", [row_colors[2 * (k // columns)] for k in range(len(wide))])
    narrow.shapes.set(
        "color", [row_colors[2 * (k // (columns - 1)) + 1] for k in range(len(narrow))]
    )
    every_peg = view(pegs).children
    shifts = rng.normal(0.0, 0.03 + 0.09 * difficulty, size=(len(every_peg), 2))
    shifts /= np.maximum(np.hypot(shifts[:, 0], shifts[:, 1]) / MAX_JITTER, 1.0)[:, np.newaxis]
    every_peg.set(
        "position",
        [(x + sx, y + sy) for (x, y), (sx, sy) in zip(every_peg.position, shifts, strict=True)],
    )

    bins = Node2D("Bins")
    level.add_child(bins)
    count = 4 + int(round(4 * difficulty * rng.uniform(0.5, 1.0)))
    width = 2 * HALF_WIDTH / count
    for index in range(1, count):
        bins.add_child(Marker2D("divider", position=(-HALF_WIDTH + index * width, 0.0)))
    for index in range(count):
        bins.add_child(Marker2D("bin", position=(-HALF_WIDTH + (index + 0.5) * width, 0.08)))
    bins.placeholders.named("divider*").attach(Divider())
    floors = bins.placeholders.named("bin*").attach(BinFloor(width - 0.1))
    floors.shapes.set("color", gradient(colors[1], colors[2], n_steps=count))
    return level


EDITS = ("move", "add", "bounciness", "remove")
"""The kinds of edit :func:`edit_level` makes, each drawn with equal odds."""

_PLACES_TRIED = 16  # spots an edit tries for a moved or added peg
_MOVE_SCALE = 0.4  # how far a moved peg goes (standard deviation, m)


def edit_level(level: dict[str, Any], rng: np.random.Generator, n_edits: int) -> dict[str, Any]:
    """``n_edits`` random edits of a level's data, each one of :data:`EDITS`.

    A peg is *moved* (a step of about 0.4 m) or *added* (a copy of a peg, anywhere) only
    where the ball still passes it: inside ``[-PEG_EDGE, PEG_EDGE]`` (clear of the walls),
    between the rows' heights (above the bins and the catcher) and :data:`PEG_GAP` from every
    other peg; when none of 16 spots is free, the edit changes a peg's bounciness instead. A
    peg is *removed* only when another remains; its *bounciness* is drawn in
    :data:`BOUNCINESS`. A peg is a ``Peg`` below the level's ``Pegs`` with a shape.

    Args:
        level: the data of a level (checked already: ``PackedScene.from_data``); not changed.
        rng: where every choice comes from.
        n_edits: how many edits to make (>= 1).

    Returns:
        The edited copy.

    Raises:
        ValueError: the level has no ``Pegs`` with a peg, or turns its ``Level`` or ``Pegs``.
    """
    edited = copy.deepcopy(level)
    root = edited["root"]
    pegs = next((child for child in root.get("children", []) if child.get("name") == "Pegs"), None)
    if pegs is None:
        raise ValueError("the level has no Pegs node: it is not a Plinko level")
    for node in (root, pegs):
        if node.get("properties", {}).get("rotation", 0.0):
            raise ValueError(
                f"the level's {node['name']} is rotated: an edit places pegs on an upright board"
            )
    children: list[dict[str, Any]] = pegs.setdefault("children", [])
    origin = np.add(
        root.get("properties", {}).get("position", (0.0, 0.0)),
        pegs.get("properties", {}).get("position", (0.0, 0.0)),
    )
    for _ in range(n_edits):
        every = [child for child in children if child["class"] == "Peg" and _skin(child)]
        if not every:
            raise ValueError("the level has no peg to edit")
        kind = EDITS[int(rng.integers(len(EDITS) if len(every) > 1 else len(EDITS) - 1))]
        if kind == "remove":  # drawn only while another peg remains: it is last in EDITS
            children.remove(every[int(rng.integers(len(every)))])
            continue
        peg = every[int(rng.integers(len(every)))]
        if kind in ("move", "add"):
            others = [
                _position(other) + origin for other in every if other is not peg or kind == "add"
            ]
            start = _position(peg) + origin
            spot = _free_spot(rng, others, start if kind == "move" else None)
            if spot is not None:
                if kind == "add":
                    peg = copy.deepcopy(peg)
                    peg["name"] = _free_name(children)
                    children.append(peg)
                peg.setdefault("properties", {})["position"] = (spot - origin).tolist()
                continue
        skin = _skin(peg)
        assert skin is not None  # a peg has one
        skin.setdefault("properties", {})["elasticity"] = float(rng.uniform(*BOUNCINESS))
    return edited


def _skin(peg: dict[str, Any]) -> dict[str, Any] | None:
    """The peg's shape (its first CollisionShape), or ``None``."""
    return next(
        (child for child in peg.get("children", []) if child["class"] == "CollisionShape"), None
    )


def _position(peg: dict[str, Any]) -> np.ndarray:
    return np.asarray(peg.get("properties", {}).get("position", (0.0, 0.0)), dtype=float)


def _free_spot(
    rng: np.random.Generator, others: list[np.ndarray], start: np.ndarray | None
) -> np.ndarray | None:
    """A board position at least PEG_GAP from ``others``: near ``start``, or anywhere."""
    low = np.array([-PEG_EDGE, PEG_BOTTOM - MAX_JITTER])
    high = np.array([PEG_EDGE, PEG_TOP + MAX_JITTER])
    for _ in range(_PLACES_TRIED):
        spot = (
            rng.uniform(low, high)
            if start is None
            else np.clip(start + rng.normal(0.0, _MOVE_SCALE, 2), low, high)
        )
        if all(np.hypot(*(spot - other)) >= PEG_GAP for other in others):
            return spot
    return None


def _free_name(children: list[dict[str, Any]]) -> str:
    taken = {child.get("name") for child in children}
    number = len(children) + 1
    while f"Peg{number}" in taken:
        number += 1
    return f"Peg{number}"


def _ball_start(rng: np.random.Generator) -> tuple[float, float]:
    """The ball's x and sideways speed: the first draws of an episode, before the level."""
    return float(rng.uniform(-3.0, 3.0)), float(rng.uniform(-0.5, 0.5))


class PlinkoWorld(LevelWorld):
    """The board, the catcher, the ball and this episode's level (given, or from the seed)."""

    configurable = ("difficulty",)
    level_classes = LEVEL_CLASSES
    edit_level_data = staticmethod(edit_level)
    columns = 8
    """Pegs in the wide rows of the levels it builds."""
    rows: int | None = None
    """Rows of pegs of the levels it builds; by default from the difficulty."""

    def __init__(self) -> None:
        super().__init__("World")
        self.difficulty = 0.5
        self.physics: PhysicsWorld | None = None
        self.ball: RigidBody | None = None
        self.catcher: KinematicBody | None = None
        self.catcher_half_width = 0.0
        self.caught = False
        self.landed = False

    def check_config(self, config: Mapping[str, Any]) -> None:
        """Also refuse a difficulty outside [0, 1].

        Raises:
            RequestError: ``invalid_config``.
        """
        super().check_config(config)
        if "difficulty" in config and not 0.0 <= float(config["difficulty"]) <= 1.0:
            raise RequestError(
                ErrorCode.INVALID_CONFIG,
                f"PlinkoWorld.difficulty must be in [0, 1], got {config['difficulty']!r:.40}",
            )

    def reset(self, options: Mapping[str, Any]) -> None:
        """Build the board, the catcher and the ball, then a level (new, or the given one).

        Raises:
            PackedSceneError: ``options["level"]`` is not a level this environment may build.
        """
        (start_x, start_speed), level = self.new_level(options)
        if self.physics is not None:
            self.remove_child(self.physics)
        physics = self.physics = PhysicsWorld(gravity=(0.0, -9.81), name="Physics")
        physics.add_child(self._walls())
        self.catcher_half_width = 0.8 - 0.4 * self.difficulty
        self.catcher = self._catcher(self.catcher_half_width)
        physics.add_child(self.catcher)
        ball = self.ball = RigidBody(position=(start_x, TOP - 0.3), name="Ball")
        ball.add_child(
            CollisionShape.circle(
                BALL_RADIUS, mass=1.0, elasticity=0.3, friction=0.3, color="crimson", name="Skin"
            )
        )
        ball.velocity = (start_speed, 0.0)
        physics.add_child(ball)
        physics.add_child(level)
        self.level_node = level
        self.caught = self.landed = False
        self.add_child(physics)

    def draw_before_level(self, rng: np.random.Generator) -> tuple[float, float]:
        """The ball's x and sideways speed: drawn before the level, given or built."""
        return _ball_start(rng)

    def build_level(self, rng: np.random.Generator) -> Node2D:
        """A new level (:func:`build_level`) at the world's difficulty, columns and rows."""
        return build_level(rng, self.difficulty, self.columns, self.rows)

    def get_data(self, observation_request: Mapping[str, Any]) -> dict[str, Any]:
        """The ball and the catcher, the level's size and fingerprint (its data's digest)."""
        assert self.ball is not None and self.catcher is not None
        assert self.level_node is not None
        pegs = self.level_node.get_node_or_null("Pegs")
        return {
            "ball": list(self.ball.position),
            "catcher": list(self.catcher.position),
            "pegs": pegs.get_child_count() if pegs is not None else 0,
            "level": self.level_id,
        }

    def _walls(self) -> StaticBody:
        walls = StaticBody(name="Walls")
        for index, (a, b) in enumerate(
            [
                ((-HALF_WIDTH, 0.0), (-HALF_WIDTH, TOP + 1.0)),
                ((HALF_WIDTH, 0.0), (HALF_WIDTH, TOP + 1.0)),
            ]
        ):
            walls.add_child(
                CollisionShape.segment(
                    a, b, 0.05, elasticity=0.3, color="dimgray", name=f"Side{index}"
                )
            )
        floor = CollisionShape.segment(
            (-HALF_WIDTH, 0.0), (HALF_WIDTH, 0.0), 0.05, color="dimgray", name="Floor"
        )
        floor.collision_started.connect(self._on_floor_touched)
        walls.add_child(floor)
        return walls

    def _catcher(self, half: float) -> KinematicBody:
        catcher = KinematicBody(position=(0.0, CATCHER_HEIGHT), name="Catcher")
        for name, a, b in (
            ("Bottom", (-half, 0.0), (half, 0.0)),
            ("Left", (-half, 0.0), (-half, 0.35)),
            ("Right", (half, 0.0), (half, 0.35)),
        ):
            catcher.add_child(CollisionShape.segment(a, b, 0.04, color="goldenrod", name=name))
        inner = half - 0.06
        pocket = CollisionShape.poly(
            [(-inner, 0.02), (inner, 0.02), (inner, 0.2), (-inner, 0.2)],
            sensor=True,
            color="khaki",
            name="Pocket",
        )
        pocket.collision_started.connect(self._on_pocket_touched)
        catcher.add_child(pocket)
        return catcher

    def _on_pocket_touched(self, other: CollisionShape) -> None:
        if other.body_node is self.ball:
            self.caught = True

    def _on_floor_touched(self, other: CollisionShape) -> None:
        if other.body_node is self.ball:
            self.landed = True


class PlinkoAgent(RLAgent):
    """Moves the catcher; rewarded when the ball lands in it."""

    configurable = ("max_speed",)
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
    observation_space = spaces.Box(
        low=np.array([-HALF_WIDTH, -6.0, -5.0, -1.0, -30.0, -30.0], dtype=np.float32),
        high=np.array([HALF_WIDTH, 6.0, 5.0, 12.0, 30.0, 30.0], dtype=np.float32),
        dtype=np.float32,
    )

    def __init__(self) -> None:
        super().__init__("Agent")
        self.max_speed = 6.0
        self.speed = 0.0

    def reset(self, arguments: Any) -> None:
        """The catcher starts at rest."""
        self.speed = 0.0

    def set_action(self, action: np.ndarray) -> None:
        """Remember the catcher's speed for the ticks of this action."""
        self.speed = float(action[0]) * self.max_speed

    def _physics_process(self, delta: float) -> None:
        world = self._world()
        catcher = world.catcher
        if catcher is None:
            return
        limit = HALF_WIDTH - world.catcher_half_width
        x = catcher.position.x
        speed = self.speed
        if (x >= limit and speed > 0) or (x <= -limit and speed < 0):
            speed = 0.0
        elif abs(x + speed * delta) > limit:  # stop at the wall, not past it
            speed = (math.copysign(limit, speed) - x) / delta
        catcher.velocity = (speed, 0.0)

    def _after_physics_tick(self, delta: float) -> None:
        world = self._world()
        if world.caught:
            self.add_reward(1.0)
            self.set_terminated()
        elif world.landed:
            self.set_terminated()

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Catcher x and speed; ball position and velocity (within the space's bounds)."""
        world = self._world()
        assert world.catcher is not None and world.ball is not None
        ball = world.ball.body
        observation = np.array(
            (world.catcher.position.x, world.catcher.velocity.x, *ball.position, *ball.velocity),
            dtype=np.float32,
        )
        space = self.observation_space
        return np.clip(observation, space.low, space.high)  # type: ignore[attr-defined]

    def _world(self) -> PlinkoWorld:
        world = self.environment.world
        assert isinstance(world, PlinkoWorld)
        return world


class PlinkoEnvironment(RLEnvironment):
    """Plinko: an agent and a world under one node; a new level at every reset."""

    render_view = (-HALF_WIDTH - 0.5, -0.5, HALF_WIDTH + 0.5, TOP + 0.5)
    render_size = (450, 600)
    reset_options = ("level",)

    def __init__(self) -> None:
        super().__init__("Plinko", repeat_action=4)
        self.add_child(PlinkoAgent())
        self.add_child(PlinkoWorld())


def main() -> None:
    """Serve Plinko: ``python -m examples.plinko [--port P]``."""
    from rlenv_tools.cli import serve_command

    raise SystemExit(serve_command(TARGET))
