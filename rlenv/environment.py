"""RLEnvironment: the node that serves an agent and its world to a client.

The tree of an environment follows the Godot seed::

    Environment (RLEnvironment)
    |___Agent (RLAgent)
    |___World (RLEnvWorld)

The environment keeps the tree paused while it waits for its client. A request applies, in
order, ``config``, ``reset``, ``action`` and ``observation``. An action unpauses the tree for
exactly ``repeat_action`` physics ticks (fewer only if the episode ends first), then pauses it
again and answers with the observation, the summed reward, ``terminated``, ``truncated``,
``info`` and the number of ticks that ran. Every request gets exactly one answer; a refused
request changes nothing.
"""

from __future__ import annotations

import logging
import traceback
from collections.abc import Callable, Mapping
from enum import Enum
from pathlib import Path
from typing import Any, ClassVar, NamedTuple, TypeVar

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding

from rlenv.agent import RLAgent
from rlenv.communication import Communication, Endpoint
from rlenv.episode import EpisodeLog, generator_from_state, parse_snapshot
from rlenv.errors import ErrorCode, RequestError
from rlenv.inspector import check_inspect, get_property, set_property, tree
from rlenv.node import ProcessMode
from rlenv.protocol import ErrorReply, Hello, Request, Response
from rlenv.recording import VideoRecorder
from rlenv.rl_node import RLNode
from rlenv.spaces import SpaceMismatch, check, find_non_finite
from rlenv.timer import PhysicsFramesTimer
from rlenv.world import RLEnvWorld

__all__ = ["Outcome", "RLEnvironment", "non_finite_error"]

logger = logging.getLogger(__name__)
_T = TypeVar("_T")

_CONFIG_PARTS = frozenset({"environment", "agent", "world"})
_RESET_KEYS = frozenset({"seed", "options"})
_OBSERVATION_PARTS = frozenset({"agent", "world", "render"})
_AGENT_ONLY: Mapping[str, Any] = {"agent": {}}
_RENDER_KEYS = frozenset({"width", "height"})
_MAX_RENDER_SIZE = 4096


class RLEnvironment(RLNode):
    """Override to build an environment; give it an :class:`RLAgent` and an :class:`RLEnvWorld`.

    Build the children in ``__init__`` (or ``_ready``). By default ``_ready`` takes the first
    RLAgent child as :attr:`agent` and the first RLEnvWorld child as :attr:`world`; override it
    to choose others. Override :meth:`_reset` to change how an episode starts, :meth:`_step` to
    add logic around an action (call ``super()._step``), and :meth:`_get_info` to add to
    ``info``.

    Args:
        name: the node name; also the environment name the client sees.
        repeat_action: physics ticks an action runs by default; clients may configure it.

    Attributes:
        physics_ticks_per_second: the physics rate the environment is designed for (class
            attribute; the server builds its tree with it).
        render_size: default (width, height) of rendered frames.
        render_view: the world rectangle (x_min, y_min, x_max, y_max) frames show; by default
            the bounding box of everything, frame by frame.
        record_dir: where ``configure(record="name.mp4")`` may write videos (one frame per
            physics tick of every action, drawn by :meth:`_render`); ``None`` (the default)
            refuses recording requests. Set by ``rlenv serve --record-dir``.
        agent: the agent node.
        world: the world node.
        communication: the TCP endpoint.
        physics_frames_timer: counts the ticks of the running action.
        repeat_action: ticks an action runs unless the request says otherwise.
        np_random: the episode's random generator, seeded on ``reset(seed=...)``.
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
    configurable: ClassVar[tuple[str, ...]] = ("repeat_action", "real_time", "record")

    def __init__(self, name: str | None = None, *, repeat_action: int = 4) -> None:
        super().__init__(name)
        self.process_mode = ProcessMode.ALWAYS
        self.agent: RLAgent | None = None
        self.agents: list[RLAgent] = []
        self.world: RLEnvWorld | None = None
        self.communication: Endpoint = Communication(self.hello)
        self.physics_frames_timer = PhysicsFramesTimer(
            name="PhysicsFramesTimer", process_mode=ProcessMode.PAUSABLE
        )
        self.physics_frames_timer.timeout.connect(self._finish_action)
        self.add_child(self.physics_frames_timer)
        self.repeat_action = repeat_action
        self._np_random: np.random.Generator | None = None
        self._episode = _Episode.NOT_STARTED
        self._request: Request | None = None
        self._ticks = 0  # ticks the episode ran since the last answer
        self._ended_unseen = False  # real time: the episode ended between two requests
        self._last_action_at = 0
        self._late = False
        self._late_actions = 0
        self.record_dir: Path | None = None
        self._recorder: VideoRecorder | None = None
        self._log = EpisodeLog()
        self._replaying = False
        self._inspection: dict[str, Any] = {}

    # --- Godot lifecycle --------------------------------------------------------------------

    def _enter_tree(self) -> None:
        self.get_tree().paused = True

    @property
    def real_time(self) -> bool:
        """Real-time mode, blendtorch's ``real_time=True`` (lockstep, the default, when false).

        Ticks follow the clock whether or not the client answered; actions apply when they
        arrive and are answered at once with the latest state; ``info["late_actions"]`` counts
        actions later than ``repeat_action`` ticks after the previous one. Lockstep is
        deterministic; real time is not.
        """
        return self.is_inside_tree() and self.get_tree().real_time

    @real_time.setter
    def real_time(self, value: bool) -> None:
        tree = self.get_tree()
        tree.real_time = value
        tree.paused = not (value and self._episode is _Episode.RUNNING and
                           not self._ended_unseen)

    @property
    def multi_agent(self) -> bool:
        """Whether the environment has several agents (spaces and outcomes keyed by name)."""
        return len(self.agents) > 1

    @property
    def request_in_progress(self) -> bool:
        """Whether a request is being served (an action may be running)."""
        return self._request is not None

    def _ready(self) -> None:
        if not self.agents:
            self.agents = self.find_children("*", RLAgent, recursive=False)
        if self.agent is None and self.agents:
            self.agent = self.agents[0]
        if not self.agents and self.agent is not None:
            self.agents = [self.agent]
        if self.world is None:
            self.world = self.find_child("*", RLEnvWorld, recursive=False)

    def _process(self, delta: float) -> None:
        if self._request is not None:  # an action is running; its client waits for the answer
            return
        tree = self.get_tree()
        timeout = tree.time_to_next_tick() if tree.real_time else None if tree.paused else 0.0
        request = self.communication.poll(timeout=timeout)
        if request is not None:
            self.call_deferred(self._on_got_connection, request)

    def _physics_process(self, delta: float) -> None:
        if self._episode is _Episode.ACTING or (
            self._episode is _Episode.RUNNING and self.get_tree().real_time
            and not self._ended_unseen
        ):
            self.call_deferred(self._end_tick, delta)  # runs after the physics stepped

    # --- the seed's contract ----------------------------------------------------------------

    @property
    def np_random(self) -> np.random.Generator:
        """The episode's random generator (seeded from entropy until a seed is given)."""
        if self._np_random is None:
            self._np_random, _ = seeding.np_random(None)
        return self._np_random

    def hello(self) -> Hello:
        """What a client is told on connecting: name, spaces and rates.

        Raises:
            RuntimeError: the agent or the world is not set, or the agent has no spaces.
        """
        agent = self._require_agent()
        self._require_world()
        for each in self.agents:
            for attribute in ("action_space", "observation_space"):
                if not hasattr(each, attribute):
                    raise RuntimeError(f"{each!r} must set {attribute} to a gymnasium space")
        action_space, observation_space = agent.action_space, agent.observation_space
        if self.multi_agent:  # the joint spaces, keyed by agent name
            action_space = spaces.Dict({a.name: a.action_space for a in self.agents})
            observation_space = spaces.Dict({a.name: a.observation_space for a in self.agents})
        return Hello(
            environment=self.name,
            action_space=action_space,
            observation_space=observation_space,
            agents=tuple(a.name for a in self.agents),
            physics_ticks_per_second=self.get_tree().physics_ticks_per_second,
            repeat_action=self.repeat_action,
            render_modes=("rgb_array",),
        )

    def _on_got_connection(self, request: Request) -> None:
        """Answer a request that came from :attr:`communication` (outside processing passes)."""
        self.communication.send(self.answer(request))

    def answer(self, request: Request) -> Response | ErrorReply:
        """Apply a request's parts in order and return its one answer.

        A lockstep action runs its ticks here, turning the tree's loop (so ``_process`` and
        ``_physics_process`` run as under the main loop); a real-time action applies at once.
        A refused request changes nothing; an exception in user code becomes an
        ``environment_error`` answer (the next action then needs a reset). Call it outside the
        tree's processing passes (from a deferred call, or from outside the loop).
        """
        return self._serve(request, lambda: self._apply(request))

    def _apply(self, request: Request) -> Response:
        action = self._check_request(request)
        if request.restore is not None:
            self._restore(request.restore)
        if request.inspect is not None:
            self._inspection = self._inspect(request.inspect)
        if request.config is not None:
            self._configure(request.config)
        if request.reset is not None:
            self._begin_episode(request.reset)
        if request.action is not None:
            self._act(action, request.repeat_action or self.repeat_action)
        return self._response(request)

    def _serve(self, request: Request, work: Callable[[], _T]) -> _T | ErrorReply:
        """``work()`` while ``request`` is being served; its refusal or failure as an error."""
        self._request = request
        try:
            return work()
        except RequestError as error:
            return ErrorReply(request.id, error.code, str(error))
        except Exception as error:  # user code raised: report it, keep serving
            return self.environment_error(request.id, error)
        finally:
            self._request = None

    def configure(self, config: Mapping[str, Any]) -> None:
        """Apply the ``environment`` part of a configuration.

        ``record`` starts (a file name) or stops (``""``) a recording; see :attr:`record_dir`.
        """
        settings = dict(config)
        if "record" in settings:
            self._record(settings.pop("record"))
        super().configure(settings)

    def check_config(self, config: Mapping[str, Any]) -> None:
        """Check the ``environment`` part of a configuration without applying it."""
        settings = dict(config)
        if "record" in settings:
            _check_recording(settings.pop("record"), self.record_dir)
        super().check_config(settings)

    def _record(self, name: str) -> None:
        if self._recorder is not None:
            self._recorder.close()
            self._recorder = None
        if name:
            assert self.record_dir is not None
            self._recorder = VideoRecorder(self.record_dir / name,
                                           self.get_tree().physics_ticks_per_second)

    def _exit_tree(self) -> None:
        self._record("")

    def _configure(self, configuration_request: Mapping[str, Any]) -> None:
        """Apply the ``environment``, ``agent`` and ``world`` parts of a configuration."""
        self._log.configured(configuration_request)
        if "environment" in configuration_request:
            self.configure(configuration_request["environment"])
        if "agent" in configuration_request:
            for agent in self.agents:
                agent.configure(configuration_request["agent"])
        if "world" in configuration_request:
            self._require_world().configure(configuration_request["world"])

    def _reset(self, options: Mapping[str, Any]) -> None:
        """Start an episode: reset the world, then each agent at a sampled initial position."""
        world = self._require_world()
        world.reset(options)
        for agent in self.agents:
            agent.reset(world.sample_initial_position())

    def _step(self, action: Any, frames: int | None = None) -> None:
        """Give ``action`` to the agent and run ``frames`` ticks (default :attr:`repeat_action`).

        The tree is unpaused until :attr:`physics_frames_timer` fires (or the episode ends),
        then paused again. Override to add logic around an action and call
        ``super()._step(action, frames)``: code after it runs once the ticks have run.
        """
        self._give_action(action)
        tree = self.get_tree()
        tree.paused = False
        self.physics_frames_timer.start(frames or self.repeat_action)
        while self._episode is _Episode.ACTING:
            tree.iteration()

    def _give_action(self, action: Any) -> None:
        """Hand the (checked) action to the agent, or to each agent named in a joint action."""
        if self.multi_agent:
            for agent in self.agents:
                if agent.name in action:
                    agent.set_action(action[agent.name])
        else:
            self._require_agent().set_action(action)

    def _response(self, request: Request) -> Response:
        """The answer to ``request``: what it asks to observe and the outcome since the last."""
        return Response(request.id, *self._outcome(request, request.observation,
                                                   acted=request.action is not None))

    def answer_part(self, request: Request, action: Any, reset: bool, *,
                    check_observation: bool = True) -> Outcome | ErrorReply:
        """Serve one instance's share of a ``steps`` request (see :class:`rlenv.protocol.Steps`).

        Resets the episode when ``reset``, else runs ``action`` (already checked against the
        action space, e.g. for the whole batch at once) for ``request.steps.repeat_action``
        ticks; returns the outcome with the agent observation, or the error :meth:`answer`
        would give. ``check_observation=False`` leaves the refusal of NaN and infinity to the
        caller (who checks every instance's observation at once, and calls
        :meth:`environment_error` with :func:`non_finite_error` for one that holds any).
        """
        steps = request.steps
        assert steps is not None

        def work() -> Outcome:
            if reset:
                self._begin_episode({})
            else:
                self.check_can_act()
                self._act(action, steps.repeat_action or self.repeat_action)
            return self._outcome(request, _AGENT_ONLY, acted=not reset,
                                 check_observation=check_observation)
        return self._serve(request, work)

    def _outcome(self, request: Request, observation_request: Mapping[str, Any] | None,
                 acted: bool, check_observation: bool = True) -> Outcome:
        """The observation asked for, and the rewards, flags and ticks since the last answer.

        Rewards and the tick count start again from zero.
        """
        observation = None
        if observation_request is not None:
            observation = self._observation(observation_request, check_observation)
        agents = self.agents
        outcomes = None
        if len(agents) > 1:
            outcomes = {each.name: {"reward": float(each.reward),
                                    "terminated": bool(each.terminated),
                                    "truncated": bool(each.truncated)} for each in agents}
            ended = all(o["terminated"] or o["truncated"] for o in outcomes.values())
            terminated = ended and any(o["terminated"] for o in outcomes.values())
            truncated = ended and not terminated
            reward = sum(o["reward"] for o in outcomes.values())
        else:
            agent = self._require_agent()
            reward = float(agent.reward)
            terminated, truncated = bool(agent.terminated), bool(agent.truncated)
        frames, self._ticks = self._ticks, 0
        for each in agents:
            each.reward = 0.0
        if terminated or truncated:  # real time: the client now knows the episode ended
            self._episode = _Episode.ENDED
        return Outcome(observation, reward, terminated, truncated,
                       self._response_info(request, acted), frames if acted else 0, outcomes)

    def _observation(self, observation_request: Mapping[str, Any],
                     check: bool = True) -> dict[str, Any]:
        """The parts of the state an ``observation`` request asks for.

        Agent observations holding NaN or infinity raise ``FloatingPointError`` (if ``check``).
        """
        observation = {}
        if "agent" in observation_request:
            asked = observation_request["agent"]
            observation["agent"] = (
                {each.name: _observe(each, asked, check) for each in self.agents}
                if self.multi_agent else _observe(self._require_agent(), asked, check)
            )
        if "world" in observation_request:
            observation["world"] = self._require_world().get_data(observation_request["world"])
        if "render" in observation_request:
            size = observation_request["render"]
            observation["render"] = self._render(
                size.get("width", self.render_size[0]), size.get("height", self.render_size[1])
            )
        return observation

    def _render(self, width: int, height: int) -> np.ndarray:
        """Draw the current state as a ``(height, width, 3)`` uint8 array.

        By default every pymunk space below the environment is drawn, framed by
        :attr:`render_view`; override to draw something else.
        """
        from rlenv.render import draw

        return draw(self, width, height, self.render_view)

    def _response_info(self, request: Request, acted: bool) -> dict[str, Any]:
        info = self._get_info()
        if acted and self.get_tree().real_time:
            info = {**info, "late": self._late, "late_actions": self._late_actions}
        if request.snapshot is not None:
            info = {**info, "snapshot": self._log.snapshot()}
        if request.inspect is not None:
            info = {**info, **self._inspection}
        return info

    def _check_inspect(self, spec: Any) -> None:
        operation, arguments = check_inspect(spec)
        if operation == "get":
            get_property(self, arguments["path"], arguments["property"])
        elif operation == "set":
            set_property(self, arguments["path"], arguments["property"], arguments["value"],
                         dry_run=True)

    def _inspect(self, spec: Mapping[str, Any]) -> dict[str, Any]:
        """Answer an ``inspect`` part (see :mod:`rlenv.inspector`).

        A ``set`` during an episode is logged, so that snapshots reproduce it.
        """
        operation, arguments = check_inspect(spec)
        if operation == "tree":
            return {"tree": tree(self)}
        if operation == "get":
            return {"value": get_property(self, arguments["path"], arguments["property"])}
        set_property(self, arguments["path"], arguments["property"], arguments["value"])
        if self._log.started:
            self._log.record(["set", arguments["path"], arguments["property"],
                              arguments["value"]])
        return {}

    def _get_info(self) -> dict[str, Any]:
        """Extra diagnostics for ``info``; override to add entries (msgpack-able values)."""
        return {}

    def environment_error(self, request_id: int, error: BaseException) -> ErrorReply:
        """The ``environment_error`` answer for an exception in user code (its traceback in it).

        The tree is paused and the next action needs a reset first.
        """
        logger.error("environment error", exc_info=error)
        self.physics_frames_timer.stop()
        if self.is_inside_tree():
            self.get_tree().paused = True
        self._episode = _Episode.NOT_STARTED
        detail = "".join(traceback.format_exception(error)).rstrip()
        return ErrorReply(request_id, ErrorCode.ENVIRONMENT_ERROR,
                          f"{error}; reset required\n{detail}")

    # --- internals --------------------------------------------------------------------------

    def _config_state(self) -> dict[str, dict[str, Any]]:
        """The current value of everything a client may configure (for snapshots)."""
        parts: dict[str, dict[str, Any]] = {}
        for part, node in (("environment", self), ("agent", self.agent), ("world", self.world)):
            if node is not None:
                parts[part] = {key: getattr(node, key) for key in node.configurable
                               if key != "record"}
        return parts

    def _check_config(self, config: Mapping[str, Any]) -> None:
        _check_keys(config, _CONFIG_PARTS, "config")
        world = [] if self.world is None else [self.world]
        for part, nodes in (("environment", [self]), ("agent", self.agents), ("world", world)):
            if part in config:
                if not isinstance(config[part], Mapping):
                    raise RequestError(ErrorCode.BAD_REQUEST, f"config.{part} must be a map")
                for node in nodes:  # every node _configure will apply the part to
                    node.check_config(config[part])
        if "environment" in config and "repeat_action" in config["environment"]:
            _check_repeat(config["environment"]["repeat_action"])

    def check_action(self, action: Any, where: str = "") -> Any:
        """Check ``action`` against the action space without applying it.

        A joint action (several agents) is checked for every agent still in the episode.

        Returns:
            The action in its space's native form.

        Raises:
            RequestError: ``invalid_action``, the message prefixed with ``where``.
        """
        return self._check_action(action, fresh=False, where=where)

    def check_can_act(self) -> None:
        """Raise ``RequestError`` (``reset_required``) before the first reset or after the end."""
        if self._episode is _Episode.NOT_STARTED:
            raise RequestError(ErrorCode.RESET_REQUIRED, "no episode has started; reset first")
        if self._episode is _Episode.ENDED:
            raise RequestError(ErrorCode.RESET_REQUIRED, "the episode has ended; reset first")

    def _check_action(self, action: Any, fresh: bool, where: str = "") -> Any:
        """``action`` in its space's native form; ``invalid_action`` (prefixed ``where``) if not."""
        try:
            if self.multi_agent:
                return self._check_joint_action(action, fresh=fresh)
            return check(self._require_agent().action_space, action, "action")
        except SpaceMismatch as error:
            raise RequestError(ErrorCode.INVALID_ACTION, f"{where}{error}") from None

    def _check_request(self, request: Request) -> Any:
        """Check every part of ``request`` before anything is applied; return the action."""
        if request.batch is not None or request.steps is not None:
            raise RequestError(ErrorCode.BAD_REQUEST, "this server hosts one environment "
                               "instance; 'batch' and 'steps' need a server started with "
                               "--instances K")
        special = [name for name in ("snapshot", "restore", "inspect")
                   if getattr(request, name) is not None]
        if special and (
            request.config is not None or request.reset is not None or request.action is not None
        ):
            raise RequestError(ErrorCode.BAD_REQUEST, f"{special[0]} goes alone (with an "
                               "observation at most)")
        if len(special) > 1:
            raise RequestError(ErrorCode.BAD_REQUEST, f"{special[0]} or {special[1]}, not both")
        if request.inspect is not None:
            self._check_inspect(request.inspect)
        if (request.snapshot is not None or request.restore is not None) and \
                self.get_tree().real_time:
            raise RequestError(ErrorCode.BAD_REQUEST, "snapshots need lockstep mode: configure "
                               "real_time=False first")
        if request.snapshot:
            raise RequestError(ErrorCode.BAD_REQUEST, "snapshot takes an empty map")
        if request.snapshot is not None:
            self._log.check_snapshot()
        if request.config is not None:
            self._check_config(request.config)
        reset = request.reset
        if reset is not None:
            _check_keys(reset, _RESET_KEYS, "reset")
            seed = reset.get("seed")
            if seed is not None and (type(seed) is not int or seed < 0):
                raise RequestError(ErrorCode.BAD_REQUEST, f"reset.seed must be an integer >= 0, "
                                   f"got {seed!r:.40}")
            options = reset.get("options")
            if options is not None and not isinstance(options, Mapping):
                raise RequestError(ErrorCode.BAD_REQUEST, "reset.options must be a map")
        if request.observation is not None:
            _check_keys(request.observation, _OBSERVATION_PARTS, "observation")
            if "render" in request.observation:
                _check_render(request.observation["render"])
        fresh = reset is not None or request.restore is not None
        if not fresh and request.observation is not None and \
                self._episode is _Episode.NOT_STARTED:
            raise RequestError(ErrorCode.RESET_REQUIRED, "no episode has started; reset first")
        if request.action is None:
            return None
        if not fresh:
            self.check_can_act()
        return self._check_action(request.action, fresh=fresh)

    def _check_joint_action(self, action: Any, fresh: bool) -> dict[str, Any]:
        """One action per agent still in the episode, keyed by name (PettingZoo's convention).

        Actions for agents whose episode has ended are ignored, so that a client holding the
        joint ``Dict`` action space may keep sending them.
        """
        if not isinstance(action, Mapping):
            raise SpaceMismatch(f"action must be a map from agent name to action, one per "
                                f"agent in the episode: {[a.name for a in self.agents]}")
        live = {a.name: a for a in self.agents if fresh or not (a.terminated or a.truncated)}
        unknown = sorted(map(str, action.keys() - {a.name for a in self.agents}))
        if unknown:
            raise SpaceMismatch(f"action for unknown agent {unknown[0]!r}")
        missing = sorted(live.keys() - action.keys())
        if missing:
            raise SpaceMismatch(f"no action for agent {missing[0]!r}")
        return {name: check(agent.action_space, action[name], f"action[{name!r}]")
                for name, agent in live.items()}

    def _begin_episode(self, arguments: Mapping[str, Any], reseed: bool = True) -> None:
        seed = arguments.get("seed")
        if seed is not None and reseed:
            self._np_random, _ = seeding.np_random(seed)
        self._log.begin(self._config_state(), self.np_random, arguments.get("options") or {})
        self._require_agent()
        for agent in self.agents:
            agent.reward = 0.0
            agent.terminated = agent.truncated = False
        tree = self.get_tree()
        self._ended_unseen = False
        self._late_actions = 0
        self._last_action_at = tree.physics_frames
        self._ticks = 0
        tree.paused = not tree.real_time
        self._episode = _Episode.RUNNING
        self._reset(arguments.get("options") or {})

    def _end_tick(self, delta: float) -> None:
        if not self.agents or self._episode not in _IN_EPISODE:
            return
        self._ticks += 1
        for agent in self.agents:
            agent._after_physics_tick(delta)
        if self._recorder is not None:
            self._recorder.add(self._render(*self.render_size))
        if self._all_ended():
            if self._episode is _Episode.RUNNING:  # real time: stop, tell the next request
                self.get_tree().paused = True
                self._ended_unseen = True
                return
            self.physics_frames_timer.stop()
            self._finish_action()

    def _all_ended(self) -> bool:
        """Whether every agent's episode has ended (the one agent's, with a single agent)."""
        for agent in self.agents:
            if not (agent.terminated or agent.truncated):
                return False
        return True

    def _finish_action(self) -> None:
        """End the running action (its ticks ran, or the episode ended): pause."""
        self.get_tree().paused = True
        self._episode = _Episode.ENDED if self._all_ended() else _Episode.RUNNING
        if self._replaying:  # restoring a snapshot: the episode moves on silently
            for agent in self.agents:
                agent.reward = 0.0

    def _act(self, action: Any, frames: int) -> None:
        tree = self.get_tree()
        if tree.real_time:
            self._act_now(action)
            return
        self._ticks = 0
        self._episode = _Episode.ACTING
        self._log.acted(action, frames)
        self._step(action, frames)

    def _act_now(self, action: Any) -> None:
        """Real time: apply the action at once and answer with the latest state.

        An action arriving more than ``repeat_action`` ticks after the previous one is late; an
        action after the episode ended (unseen by the client) is not applied.
        """
        tree = self.get_tree()
        self._late = tree.physics_frames - self._last_action_at > self.repeat_action
        self._late_actions += self._late
        self._last_action_at = tree.physics_frames
        if not self._ended_unseen:
            self._give_action(action)

    def _restore(self, data: Mapping[str, Any]) -> None:
        """Rebuild the state a snapshot describes: check everything, reset, replay."""
        snapshot = parse_snapshot(data)
        self._check_config(snapshot["config"])
        actions = []
        for index, event in enumerate(snapshot["events"]):
            if event[0] == "config":
                self._check_config(event[1])
            elif event[0] == "action":
                actions.append(self._check_action(event[1], fresh=True,
                                                  where=f"restore: events[{index}]: "))
        rng = generator_from_state(snapshot["rng"])
        self._replaying = True
        try:
            self._configure(snapshot["config"])
            self._np_random = rng
            self._begin_episode({"options": snapshot["options"]}, reseed=False)
            checked = iter(actions)
            for event in snapshot["events"]:
                if event[0] == "config":
                    self._configure(event[1])
                    continue
                if event[0] == "set":
                    self._inspect({"set": {"path": event[1], "property": event[2],
                                           "value": event[3]}})
                    continue
                if self._episode is _Episode.ENDED:
                    raise RuntimeError("the snapshot acts after its episode ended")
                self._act(next(checked), event[2])
        finally:
            self._replaying = False

    def _require_agent(self) -> RLAgent:
        if self.agent is None:
            raise RuntimeError(f"{self!r} has no agent: add an RLAgent child or set self.agent")
        return self.agent

    def _require_world(self) -> RLEnvWorld:
        if self.world is None:
            raise RuntimeError(f"{self!r} has no world: add an RLEnvWorld child or set self.world")
        return self.world


class Outcome(NamedTuple):
    """What an answer reports: the observation and what happened since the previous answer.

    The fields of a :class:`~rlenv.protocol.Response` after its id, in its order.
    """

    observation: dict[str, Any] | None
    reward: float
    terminated: bool
    truncated: bool
    info: dict[str, Any]
    frames: int
    agents: dict[str, dict[str, Any]] | None


class _Episode(Enum):
    """Where the episode stands, as far as requests are concerned."""

    NOT_STARTED = "not started"
    RUNNING = "running"
    ACTING = "acting"
    ENDED = "ended"


_IN_EPISODE = frozenset({_Episode.ACTING, _Episode.RUNNING})


def _observe(agent: RLAgent, request: Any, check: bool) -> Any:
    """``agent``'s observation, refused (if ``check``) when it holds NaN or infinity."""
    data = agent.get_data(request)
    if check:
        where = find_non_finite(data)
        if where is not None:
            raise non_finite_error(agent, data, where)
    return data


def non_finite_error(agent: RLAgent, data: Any, where: str) -> FloatingPointError:
    """The error for an observation of ``agent`` holding NaN or infinity at ``where``."""
    return FloatingPointError(
        f"the observation of {agent.get_path()} is not finite at {where or '()'}: {data!r:.200}"
    )


def _check_keys(part: Mapping[str, Any], allowed: frozenset[str], where: str) -> None:
    unknown = part.keys() - allowed
    if unknown:
        raise RequestError(
            ErrorCode.BAD_REQUEST,
            f"unknown key {sorted(map(str, unknown))[0]!r} in {where}; expected any of "
            + ", ".join(sorted(allowed)),
        )


def _check_render(size: Any) -> None:
    if not isinstance(size, Mapping):
        raise RequestError(ErrorCode.BAD_REQUEST, "observation.render must be a map")
    _check_keys(size, _RENDER_KEYS, "observation.render")
    for key, value in size.items():
        if type(value) is not int or not 1 <= value <= _MAX_RENDER_SIZE:
            raise RequestError(
                ErrorCode.BAD_REQUEST,
                f"observation.render.{key} must be an integer in [1, {_MAX_RENDER_SIZE}], "
                f"got {value!r:.40}",
            )


_VIDEO_SUFFIXES = frozenset({".mp4", ".webm", ".avi", ".mkv"})


def _check_recording(name: Any, record_dir: Path | None) -> None:
    if not isinstance(name, str):
        raise RequestError(ErrorCode.INVALID_CONFIG, "record must be a file name (or '' to stop)")
    if not name:
        return
    if record_dir is None:
        raise RequestError(ErrorCode.INVALID_CONFIG, "recording is disabled on this server; "
                           "start it with rlenv serve --record-dir DIR")
    if Path(name).name != name or name.startswith("."):
        raise RequestError(ErrorCode.INVALID_CONFIG, f"record must be a plain file name in the "
                           f"server's record directory, got {name!r:.60}")
    if Path(name).suffix not in _VIDEO_SUFFIXES:
        raise RequestError(ErrorCode.INVALID_CONFIG, f"record must end with one of "
                           f"{', '.join(sorted(_VIDEO_SUFFIXES))}, got {name!r:.60}")


def _check_repeat(value: Any) -> None:
    if type(value) is not int or value < 1:
        raise RequestError(
            ErrorCode.INVALID_CONFIG, f"repeat_action must be an integer >= 1, got {value!r:.40}"
        )

