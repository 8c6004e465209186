"""RLEnvironment: the top of an environment's tree (the seed's RLEnvironment).

The tree of an environment follows the Godot seed::

    Environment (RLEnvironment)
    |___PhysicsFramesTimer
    |___Agent (RLAgent)            acts, observes, is rewarded
    |___World (RLEnvWorld)         everything else

How requests are served (checks, episode state, snapshots, inspection) lives in
:mod:`rlenv.serving`, beside this class, never inside it: a subclass may name its attributes
and methods freely (only the documented hooks, with a leading underscore as in Godot, are
called by rlenv).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from gymnasium.utils import seeding

from rlenv.agent import RLAgent
from rlenv.rl_node import RLNode
from rlenv.scene2d.render import draw, draw_list
from rlenv.timer import PhysicsFramesTimer
from rlenv.world import RLEnvWorld

__all__ = ["RLEnvironment"]


class RLEnvironment(RLNode):
    """Override to build an environment; give it an :class:`RLAgent` and an :class:`RLEnvWorld`.

    Build the children in ``__init__`` (or ``_ready``). By default ``_ready`` takes the
    RLAgent children as :attr:`agents` (the first is :attr:`agent`) and the first RLEnvWorld
    child as :attr:`world`; override it to choose others. The hooks, all optional:
    :meth:`_reset` (how an episode starts), :meth:`_step` (logic around an action: call
    ``super()._step``), :meth:`_get_info` (entries for ``info``), :meth:`_render` (frames) and
    :meth:`_draw` (vector draw lists).

    Args:
        name: the node name; also the environment name the client sees.
        repeat_action: physics ticks an action runs by default; clients may configure it.

    Attributes:
        physics_ticks_per_second: the physics rate the environment is designed for (class
            attribute; the server builds its tree with it).
        render_size: default (width, height) of rendered frames.
        render_view: the world rectangle (x_min, y_min, x_max, y_max) frames show; by default
            the bounding box of everything, frame by frame.
        configurable: what clients may configure (besides ``real_time`` and ``record``, which
            the server handles).
        exported: what clients may read remotely (besides :attr:`configurable`).
        agent: the agent node (the first of :attr:`agents`).
        agents: every agent; several make the spaces ``Dict`` s keyed by agent name.
        world: the world node.
        physics_frames_timer: counts the ticks of the running action.
        repeat_action: ticks an action runs unless the request says otherwise.
    """

    physics_ticks_per_second: ClassVar[int] = 60
    render_size: ClassVar[tuple[int, int]] = (600, 400)
    render_view: ClassVar[tuple[float, float, float, float] | None] = None
    configurable: ClassVar[tuple[str, ...]] = ("repeat_action",)
    exported: ClassVar[tuple[str, ...]] = ("real_time",)
    _IS_ENVIRONMENT: ClassVar[bool] = True

    def __init__(self, name: str | None = None, *, repeat_action: int = 4) -> None:
        super().__init__(name)
        self.agent: RLAgent | None = None
        self.agents: list[RLAgent] = []
        self.world: RLEnvWorld | None = None
        self.physics_frames_timer = PhysicsFramesTimer(name="PhysicsFramesTimer")
        self.add_child(self.physics_frames_timer)
        self.repeat_action = repeat_action
        self.__np_random: np.random.Generator | None = None

    @property
    def np_random(self) -> np.random.Generator:
        """The episode's random generator (seeded from entropy until a seed is given)."""
        if self.__np_random is None:
            self.__np_random, _ = seeding.np_random(None)
        return self.__np_random

    @np_random.setter
    def np_random(self, generator: np.random.Generator) -> None:
        self.__np_random = generator

    @property
    def real_time(self) -> bool:
        """Whether the environment runs in real time (ticks follow the clock) or in lockstep."""
        return self.is_inside_tree() and self.get_tree().real_time

    @property
    def multi_agent(self) -> bool:
        """Whether the environment has several agents (spaces and outcomes keyed by name)."""
        return len(self.agents) > 1

    def _ready(self) -> None:
        if not self.agents:
            self.agents = self.find_children("*", RLAgent, recursive=False)
        if self.agent is None and self.agents:
            self.agent = self.agents[0]
        if not self.agents and self.agent is not None:
            self.agents = [self.agent]
        if self.world is None:
            self.world = self.find_child("*", RLEnvWorld, recursive=False)

    # --- hooks --------------------------------------------------------------------------------

    def _reset(self, options: Mapping[str, Any]) -> None:
        """Start an episode: reset the world, then each agent at a sampled initial position."""
        world = self.world
        assert world is not None
        world.reset(options)
        for agent in self.agents:
            agent.reset(world.sample_initial_position())

    def _step(self, action: Any, frames: int | None = None) -> None:
        """Give ``action`` to the agents and run ``frames`` ticks (default :attr:`repeat_action`).

        The tree is unpaused until :attr:`physics_frames_timer` stops (after ``frames`` ticks,
        or earlier when the episode ends), then paused again. Override to add logic around an
        action and call ``super()._step(action, frames)``: code after it runs once the ticks
        have run (the seed's ``yield(._step(action), "completed")``).

        ``action`` is checked already: one agent's action, or with several agents a map from
        agent name to action for the agents still in the episode.
        """
        agents = self.agents
        if len(agents) == 1:
            agents[0].set_action(action)
        else:
            for agent in agents:
                if agent.name in action:
                    agent.set_action(action[agent.name])
        tree = self.get_tree()
        timer = self.physics_frames_timer
        timer.start(frames or self.repeat_action)
        tree.paused = False
        tree.iterate_until(timer.is_stopped)
        tree.paused = True

    def _get_info(self) -> dict[str, Any]:
        """Extra diagnostics for ``info``; override to add entries (msgpack-able values)."""
        return {}

    def _render(self, width: int, height: int) -> np.ndarray:
        """Draw the current state as a ``(height, width, 3)`` uint8 array.

        By default every pymunk space below the environment is drawn, framed by
        :attr:`render_view`; override to draw something else.
        """
        return draw(self, width, height, self.render_view)

    def _draw(self) -> dict[str, Any]:
        """The current state as a vector draw list, for viewers (the inspector's canvas).

        By default every pymunk shape below the environment, framed by :attr:`render_view`
        (see :func:`rlenv.scene2d.render.draw_list` for the format); override to describe something
        else.
        """
        return draw_list(self, self.render_view)
