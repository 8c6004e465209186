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
from typing import Any, ClassVar, Protocol

import numpy as np
from gymnasium.utils import seeding

from rlenv.agent import RLAgent
from rlenv.communication import Communication
from rlenv.node import Node
from rlenv.rl_node import RLNode
from rlenv.scene2d.render import draw, draw_list
from rlenv.timer import PhysicsFramesTimer
from rlenv.world import RLEnvWorld

__all__ = ["AgentWatch", "RLEnvironment", "give_action"]


class RLEnvironment(RLNode):
    """Override to build an environment; give it an :class:`RLAgent` and an :class:`RLEnvWorld`.

    Build the children in ``__init__`` (or ``_ready``). By default ``_ready`` takes the
    RLAgent children as :attr:`agents` (the first is :attr:`agent`) and the first RLEnvWorld
    child as :attr:`world`; override it to choose others (and, to host the environment
    yourself with :func:`rlenv.run`, call ``self.communication.start_server(port, host)``, as
    in the Godot seed).

    The hooks, all optional, are the seed's. Each request goes to :meth:`_on_got_connection`,
    which by default dispatches it: :meth:`_configure` (a ``config``), :meth:`_reset` (how an
    episode starts), :meth:`_step` (logic around an action: call ``super()._step``), then
    :meth:`_send_response` (the answer); once it went out, :meth:`_after_send_response`. An
    override calls ``super()`` to keep the default behaviour. Besides: :meth:`_get_info`
    (entries for ``info``), :meth:`_render` (frames) and :meth:`_draw` (vector draw lists).

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
        reset_options: the keys a reset's ``options`` may hold (others are refused with
            ``bad_request``); ``None``, the default, accepts any.
        rebuild_after_error: whether the server builds the environment again from its class
            (constructor, entering the tree, ``_ready``) at the reset after its code raised
            while serving, keeping its configuration and random generator; the reset's
            ``info["rebuilt"]`` says why. Set it to ``False`` to keep the same objects.
        possible_agents: every agent that may appear in an episode, a map from its name to
            its RLAgent class (PettingZoo's ``possible_agents``), or ``None`` (the default):
            the agents present once ``_ready`` ran are all there is. Declare it to let agents
            join during an episode (``add_child`` in a hook, a signal handler or a deferred
            call) and leave it (``queue_free``, ``remove_child``): the hello lists each one's
            spaces, so that clients size their buffers before the first spawn. Agents still
            need their spaces as class attributes. See docs/several-agents.md, "Agents that
            come and go".
        agent: the agent node (the first of :attr:`agents`).
        agents: the agents in play; several (or :attr:`possible_agents`) make the spaces
            ``Dict`` spaces keyed by agent name. While agents come and go, rlenv keeps this
            list: an agent joins it when added, and leaves it when its episode ends.
        world: the world node.
        physics_frames_timer: counts the ticks of the running action.
        communication: the environment's server (:class:`~rlenv.communication.Communication`).
        repeat_action: ticks an action runs unless the request says otherwise.
        CONFIG_KEY, RESET_KEY, ACTION_KEY, OBSERVATION_KEY: the keys of a request's parts.
        WORLD_KEY, AGENT_KEY, ENVIRONMENT_KEY: the keys of a ``config`` part and of an
            ``observation`` part.
    """

    CONFIG_KEY: ClassVar[str] = "config"
    RESET_KEY: ClassVar[str] = "reset"
    ACTION_KEY: ClassVar[str] = "action"
    OBSERVATION_KEY: ClassVar[str] = "observation"
    WORLD_KEY: ClassVar[str] = "world"
    AGENT_KEY: ClassVar[str] = "agent"
    ENVIRONMENT_KEY: ClassVar[str] = "environment"

    physics_ticks_per_second: ClassVar[int] = 60
    render_size: ClassVar[tuple[int, int]] = (600, 400)
    render_view: ClassVar[tuple[float, float, float, float] | None] = None
    configurable: ClassVar[tuple[str, ...]] = ("repeat_action",)
    exported: ClassVar[tuple[str, ...]] = ("real_time",)
    reset_options: ClassVar[tuple[str, ...] | None] = None
    rebuild_after_error: ClassVar[bool] = True
    possible_agents: ClassVar[Mapping[str, type[RLAgent]] | None] = None
    _IS_ENVIRONMENT: ClassVar[bool] = True

    def __init__(self, name: str | None = None, *, repeat_action: int = 4) -> None:
        super().__init__(name)
        self._agent_watch: AgentWatch | None = None  # the server's (rlenv.serving)
        self.agent: RLAgent | None = None
        self.agents: list[RLAgent] = []
        self.world: RLEnvWorld | None = None
        self.physics_frames_timer = PhysicsFramesTimer(name="PhysicsFramesTimer")
        self.add_child(self.physics_frames_timer)
        self.communication = Communication()
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
        """Whether the environment has several agents (spaces and outcomes keyed by name).

        A group of agents (:class:`~rlenv.agent_group.RLAgentGroup`) counts as several.
        """
        agents = self.agents
        return (
            len(agents) > 1
            or self.possible_agents is not None
            or any(agent._IS_GROUP for agent in agents)
        )

    def add_child(self, node: Node) -> None:
        """Add ``node`` (see :meth:`Node.add_child`); an RLAgent added in an episode joins it.

        Raises:
            ValueError: an agent that may not join: its name is used already in this episode
                (checked before the tree would make it unique), or the environment's
                :attr:`possible_agents` does not name it or names another class.
        """
        watch = self._agent_watch
        if watch is None or not isinstance(node, RLAgent):
            super().add_child(node)
            return
        watch.joining(node)
        super().add_child(node)
        if node.get_parent() is self:  # not deferred to the end of the pass
            watch.joined(node)

    def remove_child(self, node: Node) -> None:
        """Remove ``node`` (see :meth:`Node.remove_child`); an agent in play leaves the episode.

        Its last observation is taken first, while it is still in the tree.
        """
        watch = self._agent_watch
        tree = self.get_tree() if self.is_inside_tree() else None
        if (
            watch is not None
            and isinstance(node, RLAgent)
            and node.get_parent() is self
            and not (tree is not None and tree.is_processing())
        ):
            watch.leaving(node)
        super().remove_child(node)

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

    def _on_got_connection(self, request: dict[str, Any]) -> None:
        """Handle one request from a client: every request comes here, once.

        ``request`` maps each part to its value, checked already (a refused request never
        comes here), in the order they apply: :attr:`CONFIG_KEY` (a map of
        :attr:`ENVIRONMENT_KEY` / :attr:`AGENT_KEY` / :attr:`WORLD_KEY` settings),
        :attr:`RESET_KEY` (``{"seed": int or None, "options": map}``), ``"repeat_action"``
        (ticks for this action), :attr:`ACTION_KEY` (the action, in its space's form) and
        :attr:`OBSERVATION_KEY` (what to observe); the protocol's other parts (``snapshot``,
        ``restore``, ``inspect``) carry the server's checked form: pass them on as they are.

        By default it dispatches them: :meth:`_configure`, a new episode (:meth:`_reset`),
        :meth:`_step`, then :meth:`_send_response` with the observation part (``None`` when
        the request asked for none: every request gets exactly one answer). Override it to
        look at or change requests, and call ``super()._on_got_connection(request)``.
        """
        self.communication.dispatch(request)

    def _configure(self, configuration_request: Mapping[str, Any]) -> None:
        """Apply a ``config`` part (checked already) to the environment, agents and world.

        The part holds the settings of the environment (:attr:`ENVIRONMENT_KEY`:
        ``repeat_action``, ``real_time``, ``record`` and its :attr:`configurable` attributes),
        of the agents (:attr:`AGENT_KEY`: settings of every agent, or keyed by an agent's or
        a class's name those of that agent or class, see
        :func:`~rlenv.serving._settings.agent_settings`) and of the world (:attr:`WORLD_KEY`).
        Settings last across episodes. Override to react to a configuration, and call
        ``super()._configure(configuration_request)``.
        """
        self.communication.configure(configuration_request)

    def _send_response(self, observation_request: Mapping[str, Any] | None) -> None:
        """Gather the answer to the request being served, from agents and world, and send it.

        The answer holds what ``observation_request`` asks for (:attr:`AGENT_KEY`,
        :attr:`WORLD_KEY`, ``render``, ``draw``; ``None`` when the request asked for no
        observation), the rewards and ticks since the previous answer, the episode's flags and
        :meth:`_get_info`.

        Called once per request. Override to add to it, and call
        ``super()._send_response(observation_request)``.
        """
        self.communication.send_response(observation_request)

    def _after_send_response(self) -> None:
        """Called once the answer to a request went out (to clear recorded frames, say).

        An exception here ends the episode: the next action is refused with
        ``reset_required``, saying why.
        """

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
        give_action(self.agents, action, self.multi_agent)
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


class AgentWatch(Protocol):
    """What the server does when an agent joins or leaves an episode (set by rlenv.serving)."""

    def joining(self, agent: RLAgent) -> None:
        """Refuse ``agent`` (raise ``ValueError``, saying why) unless it may join now."""

    def joined(self, agent: RLAgent) -> None:
        """``agent`` is in the tree: it joins the episode at the next answer."""

    def leaving(self, agent: RLAgent) -> None:
        """``agent`` is about to leave the tree: its last transition is taken now."""


def give_action(agents: list[RLAgent], action: Any, several: bool = False) -> None:
    """Hand a checked action to the agents: the one agent's, or each its own from the map.

    The action is a map by agent name when there are ``several`` agents (or possible agents,
    while agents come and go), or more than one agent.
    """
    if len(agents) == 1 and not several:
        agents[0].set_action(action)
        return
    for agent in agents:
        if agent.name in action:
            agent.set_action(action[agent.name])
