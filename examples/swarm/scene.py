"""The swarm's scene in bare pymunk and numpy: the code every version of the game shares.

A square room of :func:`room_half` metres a side, a nest (a circle) at a random spot, and one
disc per member. :class:`SwarmBodies` owns the discs in a ``pymunk.Space`` it is given (a
:class:`~rlenv.PhysicsWorld`'s in the environments, a bare one in the floor of
``benchmarks/swarm.py``) and moves data in and out of them two ways: every member at once
through ``pymunk.batch`` (the group, the floor), or one body at a time through Chipmunk's
accessors (the per-node version). The rest, forces from actions, rewards, arrivals and
observations, are functions of arrays of rows, called on all the members at once or on one
member's row: the same arithmetic in every version, element by element, so that the group and
the nodes move the bodies along the same trajectories bit for bit (``tests/test_swarm.py``).

``pymunk.batch`` reads and writes the fields of every body of a space in one call, in
Chipmunk's order (the dynamic bodies, then the static ones), which a body's removal changes:
:class:`SwarmBodies` reads the bodies' ids once after each change to know whose row is whose.
``benchmarks/pymunk_batch.py`` measured it against per-body access (docs/several-agents.md,
"Swarms").
"""

from __future__ import annotations

import math

import numpy as np
import pymunk
import pymunk.batch

from rlenv.scene2d import _chipmunk

__all__ = [
    "ARRIVAL_REWARD",
    "EPISODE_TICKS",
    "JOIN_TICKS",
    "MAX_FORCE",
    "NEST_FRACTION",
    "OBSERVATION_SIZE",
    "PROGRESS_REWARD",
    "RADIUS",
    "SPEED",
    "TICK_REWARD",
    "SwarmBodies",
    "SwarmFloor",
    "distances",
    "forces",
    "joining",
    "observe",
    "room_half",
    "starting",
    "steer",
]

RADIUS = 0.25
"""A member's disc radius (m); mass 1 kg."""
CELL = 1.0
"""The side of the grid cells members start on (m), one member a cell."""
MAX_FORCE = 3.0
"""The force of an action of 1 (N)."""
DAMPING = 0.3
"""The fraction of its velocity a disc keeps per second (the space's damping)."""
SPEED = 5.0
"""The observation's bound on a velocity (m/s)."""
NEST_FRACTION = 0.15
"""The nest's radius as a fraction of the room's half side."""
PROGRESS_REWARD = 0.1
"""Reward per metre a member comes closer to the nest (negative when it goes away)."""
ARRIVAL_REWARD = 1.0
"""Reward for reaching the nest."""
TICK_REWARD = -0.001
"""Reward per tick in play: the sooner home, the better."""
OBSERVATION_SIZE = 6
"""A member's observation: position, velocity, the nest relative to it."""
EPISODE_TICKS = 600
"""The ticks after which the members still in play are truncated (10 s)."""
JOIN_TICKS = 8
"""Ticks between two members joining, while some have not started."""
TICKS_PER_SECOND = 60

_ID = pymunk.batch.BodyFields.BODY_ID
_STATE = _ID | pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.VELOCITY
_FORCE = pymunk.batch.BodyFields.FORCE


def starting(count: int) -> int:
    """How many members of a flock of ``count`` start an episode: three quarters."""
    return max(1, count * 3 // 4)


def joining(tick: int, joined: int, count: int) -> bool:
    """Whether a member joins at ``tick`` (from 1), ``joined`` of ``count`` having started."""
    return joined < count and tick % JOIN_TICKS == 0


def room_half(count: int) -> float:
    """The half side of the room of ``count`` members: three grid cells a member."""
    return math.ceil(math.sqrt(3 * count)) * CELL / 2


def forces(actions: np.ndarray) -> np.ndarray:
    """The forces (float64, N) of ``actions`` (rows of 2 in [-1, 1])."""
    return actions.astype(np.float64) * MAX_FORCE


def distances(states: np.ndarray, nest: np.ndarray) -> np.ndarray:
    """Each row's distance to the nest (``states``: rows of position and velocity)."""
    dx = states[:, 0] - nest[0]
    dy = states[:, 1] - nest[1]
    return np.sqrt(dx * dx + dy * dy)  # sqrt is exact in every numpy loop, hypot is not


def observe(states: np.ndarray, nest: np.ndarray, half: float, out: np.ndarray) -> None:
    """Write the observations of ``states``' rows into ``out`` (float32 rows of 6, in [-1, 1]).

    A row: the member's position over the room's half side, its velocity over :data:`SPEED`,
    the nest relative to it over the room's side.
    """
    out[:, 0:2] = states[:, 0:2] / half
    out[:, 2:4] = states[:, 2:4] / SPEED
    out[:, 4:6] = (nest - states[:, 0:2]) / (2 * half)
    np.clip(out, -1.0, 1.0, out=out)


def steer(observations: np.ndarray) -> np.ndarray:
    """The scripted member: push towards the nest, braking a little (rows or one row)."""
    nest, velocity = observations[..., 4:6], observations[..., 2:4]
    return np.clip(8.0 * nest - 0.6 * velocity, -1.0, 1.0).astype(np.float32)


class SwarmBodies:
    """The room, the nest and one disc per member in a space; members in play and their state.

    Args:
        space: the space to build in (emptied of nothing: give it a fresh one).
        count: the most members (slots ``0 .. count - 1``).

    Attributes:
        half: the room's half side (m).
        nest: the nest's centre, float64 ``(2,)``, and ``nest_radius`` its radius.
        states: float64 ``(count, 4)``: each member's position and velocity as last read
            (rows of members not in play are stale).
        distances: float64 ``(count,)``: each member's distance to the nest as last read.
        in_play: bool ``(count,)``: whose disc is in the space.
    """

    def __init__(self, space: pymunk.Space, count: int) -> None:
        self.space = space
        self.count = count
        self.half = room_half(count)
        self.nest_radius = NEST_FRACTION * self.half
        self.nest = np.zeros(2)
        self.states = np.zeros((count, 4))
        self.distances = np.zeros(count)
        self.in_play = np.zeros(count, bool)
        self.bodies = [
            pymunk.Body(1.0, pymunk.moment_for_circle(1.0, 0.0, RADIUS)) for _ in range(count)
        ]
        self.discs = [pymunk.Circle(body, RADIUS) for body in self.bodies]
        for disc in self.discs:
            disc.elasticity = 0.2
            disc.friction = 0.5
        self.handles = [_chipmunk.handle(body) for body in self.bodies]
        self._slot_of = {body.id: slot for slot, body in enumerate(self.bodies)}
        self.spots = np.zeros((count, 2))
        self._buffer = pymunk.batch.Buffer()  # what batch reads fill (pymunk grows it)
        self._setter = pymunk.batch.Buffer()  # what batch writes read: self._written's memory
        self._rows = np.zeros(0, np.intp)  # the batch row of each member in play
        self._members = np.zeros(0, np.intp)  # the members in play, in batch row order
        self._written = np.zeros((0, 2))  # what a batch write sets, a row per body
        self._build_room()

    def _build_room(self) -> None:
        walls = pymunk.Body(body_type=pymunk.Body.STATIC)
        h = self.half
        corners = [(-h, -h), (h, -h), (h, h), (-h, h)]
        segments = [
            pymunk.Segment(walls, a, b, 0.05)
            for a, b in zip(corners, corners[1:] + corners[:1], strict=True)
        ]
        for segment in segments:
            segment.elasticity = 0.2
        self.nest_shape = pymunk.Circle(walls, self.nest_radius)
        self.nest_shape.sensor = True
        self.nest_shape.filter = pymunk.ShapeFilter(categories=0)  # touches nothing
        self.space.add(walls, *segments, self.nest_shape)
        self.walls = walls

    def reset(self, rng: np.random.Generator) -> None:
        """Take every disc out, draw the nest and each member's starting spot from ``rng``.

        The nest lies in the middle half of the room; the members' spots are distinct grid
        cells (jittered) clear of the nest. Nobody is in play until :meth:`add`.
        """
        self.remove(np.flatnonzero(self.in_play).tolist())
        h = self.half
        self.nest = rng.uniform(-h / 2, h / 2, 2)
        self.nest_shape.unsafe_set_offset(tuple(self.nest))
        side = round(2 * h / CELL)
        centres = (np.arange(side) + 0.5) * CELL - h
        cells = np.stack(np.meshgrid(centres, centres), -1).reshape(-1, 2)
        gap = np.sqrt(((cells - self.nest) ** 2).sum(1))
        cells = cells[gap > self.nest_radius + CELL]
        chosen = rng.choice(len(cells), self.count, replace=False)
        jitter = CELL / 2 - RADIUS - 0.05
        self.spots = cells[chosen] + rng.uniform(-jitter, jitter, (self.count, 2))

    def add(self, slots: list[int]) -> None:
        """Put the discs of members ``slots`` at their spots, at rest, into the space, in order."""
        if not slots:
            return
        for slot in slots:
            body = self.bodies[slot]
            x, y = self.spots[slot].tolist()
            body.position = (x, y)  # a new body, at rest (a slot plays once an episode)
            self.space.add(body, self.discs[slot])
            self.states[slot] = (x, y, 0.0, 0.0)
        self.in_play[slots] = True
        self.distances[slots] = distances(self.states[slots], self.nest)
        self._renumber()

    def remove(self, slots: list[int]) -> None:
        """Take the discs of members ``slots`` out of the space, in order."""
        if not slots:
            return
        for slot in slots:
            self.space.remove(self.bodies[slot], self.discs[slot])
        self.in_play[slots] = False
        self._renumber()

    def _renumber(self) -> None:
        """Read the bodies' ids: which batch row is which member's (a change reorders them)."""
        self._buffer.clear()
        pymunk.batch.get_space_bodies(self.space, _ID, self._buffer)
        ids = np.frombuffer(self._buffer.int_buf(), np.uintp)
        slot_of = self._slot_of
        rows = [(row, slot_of[each]) for row, each in enumerate(ids.tolist()) if each in slot_of]
        self._rows = np.array([row for row, _ in rows], np.intp)
        self._members = np.array([slot for _, slot in rows], np.intp)
        self._written = np.zeros((len(ids), 2))
        self._setter.set_float_buf(self._written)

    # every member at once (pymunk.batch): the group and the floor
    def read(self) -> None:
        """Read every member in play's position and velocity into :attr:`states`."""
        self._buffer.clear()
        pymunk.batch.get_space_bodies(self.space, _STATE, self._buffer)
        values = np.frombuffer(self._buffer.float_buf(), np.float64).reshape(-1, 4)
        self.states[self._members] = values[self._rows]

    def push(self, actions: np.ndarray) -> None:
        """Set the force of every member in play from its row of ``actions`` (N, 2)."""
        self._written[self._rows] = forces(actions[self._members])
        pymunk.batch.set_space_bodies(self.space, _FORCE, self._setter)

    # one member (Chipmunk's accessors): the per-node version
    def read_one(self, slot: int) -> None:
        """Read member ``slot``'s position and velocity into its row of :attr:`states`."""
        handle = self.handles[slot]
        position = _chipmunk.position_of(handle)
        velocity = _chipmunk.velocity_of(handle)
        self.states[slot] = (position.x, position.y, velocity.x, velocity.y)

    def push_one(self, slot: int, action: np.ndarray) -> None:
        """Set member ``slot``'s force from its ``action`` (2,)."""
        force = forces(action)
        _chipmunk.lib.cpBodySetForce(self.handles[slot], (float(force[0]), float(force[1])))

    def progress(self, rows: slice | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rewards of ``rows`` for the tick just read, and which of them reached the nest.

        Updates their :attr:`distances`. A row's reward is its progress and
        :data:`TICK_REWARD`, and :data:`ARRIVAL_REWARD` for a member that reached the nest.
        """
        now = distances(self.states[rows], self.nest)
        rewards = PROGRESS_REWARD * (self.distances[rows] - now) + TICK_REWARD
        self.distances[rows] = now
        arrived = now < self.nest_radius
        return rewards + ARRIVAL_REWARD * arrived, arrived


class SwarmFloor:
    """The floor of ``benchmarks/swarm.py``: the whole game in bare pymunk and numpy, no rlenv.

    What the group version does in a step, and nothing more: the same bodies, the same join
    schedule and time limit, forces pushed and states read by ``pymunk.batch``, rewards and
    observations as arrays (this module's functions), in a bare ``pymunk.Space``.

    Args:
        count: the most members.
        episode_ticks: the time limit.
    """

    def __init__(self, count: int, episode_ticks: int = EPISODE_TICKS) -> None:
        self.count = count
        self.episode_ticks = episode_ticks
        self.observations = np.zeros((count, OBSERVATION_SIZE), np.float32)
        self.rewards = np.zeros(count)
        self.actions = np.zeros((count, 2), np.float32)
        self.bodies = SwarmBodies(pymunk.Space(), count)
        self.tick = self.joined = 0

    def reset(self, rng: np.random.Generator) -> np.ndarray:
        """A new space and episode; the observations."""
        space = pymunk.Space()
        space.gravity = (0.0, 0.0)
        space.damping = DAMPING
        self.bodies = SwarmBodies(space, self.count)
        self.bodies.reset(rng)
        self.tick, self.joined = 0, starting(self.count)
        self.bodies.add(list(range(self.joined)))
        observe(self.bodies.states, self.bodies.nest, self.bodies.half, self.observations)
        return self.observations

    def step(self, actions: np.ndarray, ticks: int = 4) -> int:
        """``ticks`` ticks of ``actions`` (N, 2); how many members it stepped (in play or ending).

        :attr:`observations` and :attr:`rewards` hold the step's; the episode ended when no
        member is in play (:meth:`ended`). A member not in play when the step starts gets no
        force in it (as a group's ``actions`` rows of members out of play).
        """
        bodies, delta = self.bodies, 1.0 / TICKS_PER_SECOND
        np.copyto(self.actions, actions)
        self.actions[~bodies.in_play] = 0.0
        actions = self.actions
        self.rewards[:] = 0.0
        stepped = np.zeros(self.count, bool)
        for _ in range(ticks):
            self.tick += 1
            if joining(self.tick, self.joined, self.count):
                self.joined += 1
                bodies.add([self.joined - 1])
            bodies.push(actions)
            bodies.space.step(delta)
            bodies.read()
            rows = np.flatnonzero(bodies.in_play)
            stepped[rows] = True
            rewards, arrived = bodies.progress(rows)
            self.rewards[rows] += rewards
            ending = rows if self.tick >= self.episode_ticks else rows[arrived]
            bodies.remove(ending.tolist())
            if not bodies.in_play.any():
                break
        observe(bodies.states, bodies.nest, bodies.half, self.observations)
        return int(stepped.sum())

    def ended(self) -> bool:
        """Whether no member is in play."""
        return not self.bodies.in_play.any()
