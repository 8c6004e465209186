"""Environments with a group of agents (issue 46): discs in one pymunk space, stepped as arrays.

``Discs`` (an ``RLAgentGroup`` of 8): each member is a disc of radius 0.5 pushed by its action
(``Box(-1, 1, (2,))``, a force); it observes its position and velocity (``Box((4,))``) and
earns ``-0.01 * distance from the centre`` per tick. The discs start packed on a grid 1.0
apart, so they push each other (pymunk contacts). A member whose disc leaves the square
``|x|, |y| <= EDGE`` terminates (its disc leaves the space); at tick ``TIME_LIMIT`` every
member still in play is truncated. Only the first 6 members start (``initial_count``); at tick
``JOIN_TICK`` one more joins (``add_member``) at the centre.

``SwarmEnvironment``: the group alone. ``MixedEnvironment``: the group beside ``Shepherd``, an
ordinary ``RLAgent`` (a heavier disc in the same space). ``PacedSwarmEnvironment``: the group
decides every 3 ticks. ``DiscreteSwarmEnvironment``: members with ``Discrete(5)`` actions.

The world's settings ask for hostile changes at tick 3: ``overfill`` (more members than
``instance_count``), ``rejoin`` (member 0 again), ``remove_twice`` (a member not in play), and
``nan`` (a member's observation is NaN).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pymunk
from gymnasium import spaces

from rlenv import RLAgent, RLAgentGroup, RLEnvironment, RLEnvWorld

__all__ = [
    "EDGE",
    "JOIN_TICK",
    "TIME_LIMIT",
    "BadCountEnvironment",
    "ChosenSwarmEnvironment",
    "DiscreteSwarmEnvironment",
    "Discs",
    "MixedEnvironment",
    "PacedSwarmEnvironment",
    "Shepherd",
    "SwarmEnvironment",
]

EDGE = 3.0
JOIN_TICK = 10
TIME_LIMIT = 120
RADIUS = 0.5
FORCE = 40.0
_MOVES = np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]], np.float64)


class DiscWorld(RLEnvWorld):
    """The pymunk space every disc lives in; it steps after the agents pushed (tree order)."""

    configurable = ("overfill", "rejoin", "remove_twice", "nan")

    def __init__(self) -> None:
        super().__init__("World")
        self.space = pymunk.Space()
        self.ticks = 0
        self.overfill = self.rejoin = self.remove_twice = self.nan = False

    def reset(self, options: Mapping[str, Any]) -> None:
        self.space = pymunk.Space()
        self.space.damping = 0.5
        self.ticks = 0

    def _physics_process(self, delta: float) -> None:
        self.space.step(delta)
        self.ticks += 1

    def get_data(self, observation_request: Mapping[str, Any]) -> Any:
        return {"ticks": self.ticks}

    def sample_initial_position(self) -> Any:
        return None


def _disc(space: pymunk.Space, x: float, y: float, mass: float = 1.0) -> pymunk.Body:
    body = pymunk.Body(mass, pymunk.moment_for_circle(mass, 0, RADIUS))
    body.position = (x, y)
    space.add(body, pymunk.Circle(body, RADIUS))
    return body


class Discs(RLAgentGroup):
    """Eight discs pushed by their actions; they leave at the edge and one joins at tick 10."""

    instance_count = 8
    initial_count = 6
    member_observation_space = spaces.Box(-50.0, 50.0, (4,), np.float32)
    member_action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)

    def __init__(self, name: str = "Discs") -> None:
        super().__init__(name)
        self.bodies: list[pymunk.Body] = []
        self.applied: list[np.ndarray] = []  # the actions as _physics_process applied them

    @property
    def world(self) -> DiscWorld:
        world = self.environment.world
        assert isinstance(world, DiscWorld)
        return world

    def reset(self, arguments: Any) -> None:
        space = self.world.space
        self.bodies = [_disc(space, -1.5 + (i % 4), -0.5 + (i // 4)) for i in range(6)]
        self.bodies += [pymunk.Body(1.0, 1.0), pymunk.Body(1.0, 1.0)]  # slots 6, 7: not yet
        self.applied = []

    def forces(self) -> np.ndarray:
        """The force on each member's disc (``actions`` scaled)."""
        return np.asarray(self.actions, np.float64) * FORCE

    def _physics_process(self, delta: float) -> None:
        world = self.world
        if world.ticks + 1 == JOIN_TICK:
            slot = self.add_member()
            self.bodies[slot] = _disc(world.space, 0.0, 0.0)
        if world.ticks + 1 == 3:
            self._hostile(world)
        self.applied.append(self.actions.copy())
        forces = self.forces()
        for i in np.flatnonzero(self.active):
            self.bodies[i].apply_force_at_local_point(tuple(forces[i]))

    def _hostile(self, world: DiscWorld) -> None:
        if world.overfill:
            for _ in range(3):
                self.add_member()
        if world.rejoin:
            self.add_member(0)
        if world.remove_twice:
            self.remove_member(5)
            self.remove_member(5)

    def positions(self) -> np.ndarray:
        """``(N, 2)``: every slot's disc position."""
        return np.array([tuple(body.position) for body in self.bodies])

    def _after_physics_tick(self, delta: float) -> None:
        positions = self.positions()
        self.rewards += -0.01 * np.hypot(positions[:, 0], positions[:, 1])
        out = np.abs(positions).max(axis=1) > EDGE
        leaving = out & self.active
        self.terminations[leaving] = True
        space = self.world.space
        for i in np.flatnonzero(leaving):
            space.remove(self.bodies[i], *self.bodies[i].shapes)
        if self.world.ticks >= TIME_LIMIT:
            self.truncations[self.active] = True

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        observations = self.observations
        for i, body in enumerate(self.bodies):
            observations[i, :2] = body.position
            observations[i, 2:] = body.velocity
        if self.world.nan and self.world.ticks >= 3:
            observations[1, 0] = np.nan
        return observations


class DiscreteDiscs(Discs):
    """The same discs, pushed by one of five moves (``Discrete(5)``: none, +x, -x, +y, -y)."""

    member_action_space = spaces.Discrete(5)

    def forces(self) -> np.ndarray:
        return _MOVES[np.asarray(self.actions)] * FORCE


class Shepherd(RLAgent):
    """An ordinary agent beside the group: a heavier disc that pushes the others."""

    action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    observation_space = spaces.Box(-50.0, 50.0, (2,), np.float32)

    def __init__(self) -> None:
        super().__init__("Shepherd")
        self.body: pymunk.Body | None = None
        self.action = np.zeros(2)

    def reset(self, arguments: Any) -> None:
        world = self.environment.world
        assert isinstance(world, DiscWorld)
        self.body = _disc(world.space, 0.0, -2.0, mass=3.0)

    def set_action(self, action: Any) -> None:
        self.action = np.asarray(action, np.float64)

    def _physics_process(self, delta: float) -> None:
        assert self.body is not None
        self.body.apply_force_at_local_point(tuple(self.action * FORCE * 3))

    def _after_physics_tick(self, delta: float) -> None:
        assert self.body is not None
        self.add_reward(0.1)
        if self.environment.world.ticks >= TIME_LIMIT:  # type: ignore[union-attr]
            self.set_truncated()

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        assert self.body is not None
        return np.array(self.body.position, np.float32)


class SwarmEnvironment(RLEnvironment):
    """The group of discs alone."""

    group_class: type[Discs] = Discs

    def __init__(self) -> None:
        super().__init__("Swarm", repeat_action=4)
        self.add_child(self.group_class())
        self.add_child(DiscWorld())


class DiscreteSwarmEnvironment(SwarmEnvironment):
    """The group of discs with ``Discrete(5)`` actions."""

    group_class = DiscreteDiscs


class PacedDiscs(Discs):
    """The discs, deciding together every 3 ticks."""

    decision_period = 3


class ChosenDiscs(Discs):
    """Its reset chooses who starts: member 0 sits out (its slot stays free), member 7 starts.

    Rows out of play get an action of its own (``no_action``): a push of -1 in x.
    """

    def reset(self, arguments: Any) -> None:
        super().reset(arguments)
        self.remove_member(0)
        self.space_of_disc(0)
        self.add_member(7)
        self.bodies[7] = _disc(self.world.space, 1.5, 1.5)

    def space_of_disc(self, index: int) -> None:
        """Take disc ``index`` out of the space (its member does not start)."""
        body = self.bodies[index]
        self.world.space.remove(body, *body.shapes)
        self.bodies[index] = pymunk.Body(1.0, 1.0)

    def no_action(self) -> np.ndarray:
        idle = np.zeros(self.action_space.shape, np.float32)
        idle[:, 0] = -1.0
        return idle


class ChosenSwarmEnvironment(SwarmEnvironment):
    """The group of discs whose reset chooses who starts (``ChosenDiscs``)."""

    group_class = ChosenDiscs


class PacedSwarmEnvironment(SwarmEnvironment):
    """The group of discs, deciding every 3 ticks (``decision_period`` on the group)."""

    group_class = PacedDiscs


class MixedEnvironment(RLEnvironment):
    """The group of discs beside an ordinary RLAgent, the shepherd."""

    def __init__(self) -> None:
        super().__init__("Mixed", repeat_action=4)
        self.add_child(Discs())
        self.add_child(Shepherd())
        self.add_child(DiscWorld())


class TooManyDiscs(Discs):
    instance_count = 65_537


class BadCountEnvironment(RLEnvironment):
    """A group whose instance_count is out of range: the server does not start."""

    def __init__(self) -> None:
        super().__init__("Bad")
        self.add_child(TooManyDiscs())
        self.add_child(DiscWorld())
