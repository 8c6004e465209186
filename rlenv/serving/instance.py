"""Instance: one environment in a scene tree of its own, and the state of its episode.

The host (:mod:`rlenv.serving.host`) hands an instance each request as a **plan**: a map from
each part of the request to its checked value, in the order they apply (:mod:`rlenv.serving.parts`
makes plans). One call serves a plan, whatever carried the request (a socket or this process,
alone, in a batch or in a column step): :meth:`Instance.serve`. It goes through the
environment's hooks, the Godot seed's: ``_on_got_connection(request)`` dispatches the parts
(``_configure``, ``_reset``, ``_step``), and ``_send_response`` gathers the answer; a hook that
is not overridden is not called at all (its default is what runs instead), so it costs nothing.
The parts use the primitives below (begin an episode, act, observe...), which keep the
episode's state:

- **not started** until the first reset; **running** between actions; **acting** while an
  action's ticks run; **ended** once every agent terminated or was truncated (a step is then
  refused until the next reset);
- an action (lockstep) hands the checked action to the environment's ``_step``, which unpauses
  the tree for ``repeat_action`` ticks. At the end of every tick, after pymunk stepped, the
  instance calls each agent's ``_after_physics_tick`` (the tree's ``on_physics_tick_end``) and
  stops the action early when the episode ends;
- in real time the tree ticks by the clock between requests, an action applies at once, and an
  episode that ends between two requests pauses the tree until the next one learns of it.

Every answer reports what happened since the previous one: summed rewards, flags and ticks.
"""

from __future__ import annotations

import importlib
import logging
import time
import traceback
from collections.abc import Callable, Mapping
from enum import Enum
from pathlib import Path
from typing import Any

from gymnasium import spaces
from gymnasium.utils import seeding

from rlenv.agent import RLAgent
from rlenv.environment import RLEnvironment
from rlenv.node import Node
from rlenv.protocol import ErrorReply, Response
from rlenv.protocol.codec import find_non_text_key
from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.protocol.spaces import Codec, SpaceMismatch, codec_for, compile_check, find_non_finite
from rlenv.scene2d.recording import VideoRecorder
from rlenv.serving import inspector
from rlenv.serving.snapshots import EpisodeLog
from rlenv.serving.stats import EpisodeStats
from rlenv.tree import SceneTree

__all__ = ["Episode", "Instance", "check_keys", "check_text_keys", "failure", "load_environment",
           "packed_observation"]

logger = logging.getLogger(__name__)

_VIDEO_SUFFIXES = frozenset({".mp4", ".webm", ".avi", ".mkv"})


def load_environment(target: str) -> type[RLEnvironment]:
    """Import the environment class named ``MODULE:CLASS``.

    Raises:
        ValueError: ``target`` is not of the form ``MODULE:CLASS``.
        ImportError: the module cannot be imported.
        TypeError: the attribute is not an RLEnvironment subclass.
    """
    module_name, _, class_name = target.partition(":")
    if not module_name or not class_name:
        raise ValueError(f"expected MODULE:CLASS, e.g. examples.cartpole:CartPoleEnvironment, "
                         f"got {target!r}")
    module = importlib.import_module(module_name)
    try:
        environment_class = getattr(module, class_name)
    except AttributeError:
        raise ImportError(f"module {module_name!r} has no attribute {class_name!r}") from None
    if not (isinstance(environment_class, type) and issubclass(environment_class, RLEnvironment)):
        raise TypeError(f"{target} is not an RLEnvironment subclass")
    return environment_class


class Episode(Enum):
    """Where the episode stands, as far as requests are concerned."""

    NOT_STARTED = "not started"
    RUNNING = "running"
    ACTING = "acting"
    ENDED = "ended"


class Answer:
    """The answer to the request being served, as its parts and hooks build it."""

    __slots__ = ("acted", "config_before", "info", "reply", "reply_id", "reports")

    def __init__(self, reply_id: int, reports: bool) -> None:
        self.reply_id = reply_id
        self.reports = reports  # it goes to the controller: rewards and ticks are its
        self.info: dict[str, Any] | None = None  # entries beside the environment's own
        self.acted = False
        self.config_before: dict[str, dict[str, Any]] | None = None  # to undo on failure
        self.reply: Response | None = None


Plan = Mapping[str, Any]
"""A checked request to one instance: each part's name and checked value, in the order they
apply (what ``RLEnvironment._on_got_connection`` receives)."""

Dispatch = Callable[["Instance", Plan], None]
"""Applies every part of a plan to an instance, in order (:func:`rlenv.serving.parts.dispatch`)."""


class Instance:
    """An environment in a tree of its own, answering the plans handed to it.

    Args:
        environment: an environment instance, its class, or ``MODULE:CLASS``.
        dispatch: applies a plan's parts in order (the host passes
            :func:`rlenv.serving.parts.dispatch`).
        clock: the tree's clock, for real-time mode (tests pass a manual one).
        record_dir: where clients may have the environment record videos (``None``: nowhere).

    Raises:
        RuntimeError: the environment has no agent, no world, or an agent without spaces.
    """

    def __init__(self, environment: RLEnvironment | type[RLEnvironment] | str,
                 dispatch: Dispatch, clock: Callable[[], float] = time.monotonic,
                 record_dir: Path | None = None) -> None:
        if isinstance(environment, str):
            environment = load_environment(environment)
        if isinstance(environment, type):
            environment = environment()
        self.environment = environment
        self._dispatch = dispatch
        self.answer: Answer | None = None  # the answer to the request being served
        hooks = {name for name in _HOOKS
                 if getattr(type(environment), name) is not getattr(RLEnvironment, name)}
        self.dispatches_itself = "_on_got_connection" in hooks
        self.configures_itself = "_configure" in hooks
        self.responds_itself = "_send_response" in hooks
        self.has_after_send = "_after_send_response" in hooks
        environment.communication.bind(self)
        self.tree = SceneTree(environment.physics_ticks_per_second, clock=clock)
        self.tree.root.add_child(environment)
        self.tree.paused = True
        self.tree.on_physics_tick_end = self._end_tick
        self.agents: list[RLAgent] = _agents_of(environment)
        self.multi_agent = len(self.agents) > 1
        if self.multi_agent:  # the joint spaces, keyed by agent name
            self.action_space: spaces.Space = spaces.Dict(
                {a.name: a.action_space for a in self.agents})
            self.observation_space: spaces.Space = spaces.Dict(
                {a.name: a.observation_space for a in self.agents})
        else:
            self.action_space = self.agents[0].action_space
            self.observation_space = self.agents[0].observation_space
        self._check_actions = {a.name: compile_check(a.action_space, f"action[{a.name!r}]")
                               for a in self.agents}
        self._check_action = compile_check(self.action_space, "action")
        self._observers: list[tuple[RLAgent, Codec]] = [
            (agent, codec_for(agent.observation_space)) for agent in self.agents]
        self.record_dir = record_dir
        self.state = Episode.NOT_STARTED
        self._no_episode = "no episode has started; reset first"  # why, when NOT_STARTED
        self.log = EpisodeLog()
        self.stats = EpisodeStats([a.name for a in self.agents] if self.multi_agent else None)
        self._before_sets: dict[tuple[Node, str], Any] = {}  # what inspect sets replaced
        self.replaying = False  # restoring a snapshot: the episode moves on silently
        self._recorder: VideoRecorder | None = None
        self._ticks = 0  # ticks the episode ran since the last answer
        self._ended_unseen = False  # real time: the episode ended between two requests
        self._last_action_at = 0
        self._late = False
        self._late_actions = 0

    # --- one way in -------------------------------------------------------------------------

    def serve(self, request: Plan, reply_id: int, reports: bool = True) -> Response | ErrorReply:
        """Serve a checked request (see :mod:`rlenv.serving.parts`) and return its answer.

        The request goes to the environment's ``_on_got_connection``. An exception in user code
        becomes an ``environment_error`` answer (the next action then needs a reset); a refusal
        found while applying becomes its error answer; either way a configuration the request
        applied is undone. Unless it ``reports`` (an answer to a client that does not control
        the environment), the answer carries no reward nor ticks and leaves them for the
        controller's next answer, and a failure of user code it met (a ``_draw`` of an
        inspector's, say) leaves the episode to its controller.
        """
        answer = self.answer = Answer(reply_id, reports)
        try:
            if self.dispatches_itself:
                self.environment._on_got_connection(dict(request))
            else:
                self.dispatch(request)
            if answer.reply is None:
                raise RuntimeError(f"{type(self.environment).__name__}._on_got_connection sent "
                                   "no answer: call super()._on_got_connection(request)")
            return answer.reply
        except RequestError as error:
            self._undo_configuration(answer)
            return ErrorReply(reply_id, error.code, str(error))
        except Exception as error:  # user code raised: report it, keep serving
            self._undo_configuration(answer)
            if not reports:
                return failure(reply_id, error, "the episode goes on (its controller's)")
            return self.environment_error(reply_id, error)
        finally:
            self.answer = None

    def dispatch(self, request: Plan) -> None:
        """Apply every part of ``request`` in order, then answer it if no part did.

        What ``RLEnvironment._on_got_connection`` does by default.
        """
        self._dispatch(self, request)
        if "observation" not in request:
            self.send_response(None)

    def send_response(self, observation_request: Mapping[str, Any] | None) -> None:
        """The environment's ``_send_response`` (the answer, with what is asked observed)."""
        if self.responds_itself:
            self.environment._send_response(observation_request)
        else:
            self.respond(observation_request)

    def respond(self, observation_request: Mapping[str, Any] | None) -> None:
        """Build the answer to the request being served (what ``_send_response`` does).

        Raises:
            RuntimeError: no request is being served, or it was answered already.
        """
        answer = self.answer
        if answer is None:
            raise RuntimeError("an answer can only be sent while a request is served")
        if answer.reply is not None:
            raise RuntimeError("a request gets one answer: _send_response ran twice")
        observation = None if observation_request is None else self.observe(observation_request)
        answer.reply = self._response(answer, observation)

    def after_send(self) -> None:
        """The answer went out: the environment's ``_after_send_response``.

        An exception in it is logged and ends the episode (the next action is refused with
        ``reset_required``, saying why).
        """
        if not self.has_after_send:
            return
        try:
            self.environment._after_send_response()
        except Exception as error:
            logger.error("_after_send_response raised", exc_info=error)
            self.abandon_episode(f"the episode was stopped: _after_send_response raised "
                                 f"{type(error).__name__}: {error}")

    def catch_up(self) -> None:
        """In real time, run the ticks that came due by the clock (and a frame)."""
        if self.tree.real_time:
            self.tree.iteration()

    def time_to_next_tick(self) -> float | None:
        """Seconds until this instance's next tick is due (``None`` in lockstep)."""
        return self.tree.time_to_next_tick()

    def close(self) -> None:
        """Stop any recording and take the environment out of its tree."""
        self._set_recording("")
        if self.environment.parent is not None:
            self.tree.root.remove_child(self.environment)

    # --- configuration ----------------------------------------------------------------------

    def check_config(self, config: Mapping[str, Any]) -> None:
        """Check a ``config`` part (every node it applies to) without applying it.

        Raises:
            RequestError: ``bad_request`` (its shape) or ``invalid_config`` naming the key.
        """
        check_keys(config, _CONFIG_PARTS, "config")
        for part, nodes in self._configured_nodes().items():
            if part not in config:
                continue
            settings = config[part]
            if not isinstance(settings, Mapping):
                raise RequestError(ErrorCode.BAD_REQUEST, f"config.{part} must be a map")
            if part == "environment":
                settings = self._check_environment_settings(settings)
            for node in nodes:
                node.check_config(settings)

    def configure(self, config: Mapping[str, Any]) -> None:
        """Apply a checked ``config`` part through the environment's ``_configure``.

        The configuration it replaces is kept until the request is answered (a request that
        fails changes no setting); once applied it is logged for snapshots during an episode.
        """
        answer = self.answer
        if answer is not None and answer.config_before is None:
            answer.config_before = self.config_state()
        if self.configures_itself:
            self.environment._configure(config)
        else:
            self.apply_config(config)
        self.log.configured(config)

    def apply_config(self, config: Mapping[str, Any]) -> None:
        """Apply a checked ``config`` part to its nodes (what ``_configure`` does by default).

        A configured property is the configuration's from then on: a reset keeps it, even if
        ``inspect`` set it earlier in the episode.
        """
        for part, nodes in self._configured_nodes().items():
            if part not in config:
                continue
            settings = config[part]
            if part == "environment":
                settings = self._apply_environment_settings(settings)
            for node in nodes:
                node.configure(settings)
                for key in settings:
                    self._before_sets.pop((node, key), None)

    def _undo_configuration(self, answer: Answer) -> None:
        """Put back the settings a failed request changed (as they were before it)."""
        if answer.config_before is None:
            return
        for part, nodes in self._configured_nodes().items():
            for node in nodes:
                try:
                    node.configure(answer.config_before[part])
                except Exception as error:  # user code: what it keeps is its own
                    logger.error("could not undo the configuration of %s", node.get_path(),
                                 exc_info=error)

    def config_state(self) -> dict[str, dict[str, Any]]:
        """The current value of everything a client may configure (for snapshots)."""
        return {part: {key: getattr(nodes[0], key) for key in nodes[0].configurable}
                for part, nodes in self._configured_nodes().items()}

    def _configured_nodes(self) -> dict[str, list[Any]]:
        world = self.environment.world
        parts: dict[str, list[Any]] = {"environment": [self.environment], "agent": self.agents}
        if world is not None:
            parts["world"] = [world]
        return parts

    def _check_environment_settings(self, settings: Mapping[str, Any]) -> dict[str, Any]:
        """Check what the server handles itself (real_time, record); the rest is the node's."""
        rest = dict(settings)
        if "real_time" in rest and type(rest.pop("real_time")) is not bool:
            raise RequestError(ErrorCode.INVALID_CONFIG, "real_time must be a bool")
        if "record" in rest:
            _check_recording(rest.pop("record"), self.record_dir)
        if "repeat_action" in rest:
            repeat = rest["repeat_action"]
            if type(repeat) is not int or repeat < 1:
                raise RequestError(ErrorCode.INVALID_CONFIG, f"repeat_action must be an "
                                   f"integer >= 1, got {repeat!r:.40}")
        return rest

    def _apply_environment_settings(self, settings: Mapping[str, Any]) -> dict[str, Any]:
        rest = dict(settings)
        if "real_time" in rest:
            self.set_real_time(rest.pop("real_time"))
        if "record" in rest:
            self._set_recording(rest.pop("record"))
        return rest

    def set_real_time(self, value: bool) -> None:
        """Switch between real time (ticks follow the clock) and lockstep."""
        self.tree.real_time = value
        self.tree.paused = not (value and self.state is Episode.RUNNING and
                                not self._ended_unseen)

    def _set_recording(self, name: str) -> None:
        if self._recorder is not None:
            self._recorder.close()
            self._recorder = None
        if name:
            assert self.record_dir is not None
            self._recorder = VideoRecorder(self.record_dir / name,
                                           self.tree.physics_ticks_per_second)

    # --- episodes ---------------------------------------------------------------------------

    def set_property(self, path: str, name: str, value: Any) -> None:
        """Set an exported property (``inspect`` ``set``), for this episode.

        During an episode the change is logged, so that snapshots replay it; the next reset
        gives the property back the value it had before it was first set, so that the same
        seed gives the same episode whatever was set before.
        """
        node, name, previous = inspector.set_property(self.environment, path, name, value)
        self._before_sets.setdefault((node, name), previous)
        if self.log.started:
            self.log.record(["set", path, name, value])

    def begin_episode(self, seed: int | None, options: Mapping[str, Any]) -> None:
        """Reset: undo ``inspect`` sets, seed the generator (if given), start a new episode."""
        environment = self.environment
        for (node, name), value in reversed(self._before_sets.items()):
            setattr(node, name, value)
        self._before_sets.clear()
        if seed is not None:
            environment.np_random, _ = seeding.np_random(seed)
        self.log.begin(self.config_state(), environment.np_random, options)
        self.stats.begin()
        for agent in self.agents:
            agent.reward = 0.0
            agent.terminated = agent.truncated = False
        tree = self.tree
        self._ended_unseen = False
        self._late_actions = 0
        self._last_action_at = tree.physics_frames
        self._ticks = 0
        tree.paused = not tree.real_time
        self.state = Episode.RUNNING
        environment._reset(options)

    def check_can_act(self) -> None:
        """Refuse a step before the first reset or after the episode ended.

        Raises:
            RequestError: ``reset_required``.
        """
        if self.state is Episode.NOT_STARTED:
            self.refuse_without_episode()
        if self.state is Episode.ENDED:
            raise RequestError(ErrorCode.RESET_REQUIRED, "the episode has ended; reset first")

    def checked_action(self, action: Any, fresh: bool, where: str = "",
                       replayed: bool = False) -> Any:
        """``action`` in its space's native form.

        With several agents, the action is a map from agent name to action for every agent
        still in the episode (every agent when ``fresh``: a reset comes first); actions for
        agents whose episode ended are ignored, so that a client holding the joint ``Dict``
        action space may keep sending them (PettingZoo's convention). A ``replayed`` action
        (from a snapshot's log) holds the agents that were still in the episode: any of them.

        Raises:
            RequestError: ``invalid_action``, the message prefixed with ``where``.
        """
        try:
            if not self.multi_agent:
                return self._check_action(action)
            if not isinstance(action, Mapping):
                raise SpaceMismatch(f"action must be a map from agent name to action, one per "
                                    f"agent in the episode: {[a.name for a in self.agents]}")
            unknown = sorted(map(str, action.keys() - self._check_actions.keys()))
            if unknown:
                raise SpaceMismatch(f"action for unknown agent {unknown[0]!r}")
            if replayed:
                live = [a.name for a in self.agents if a.name in action]
            else:
                live = [a.name for a in self.agents if fresh or not (a.terminated or a.truncated)]
            missing = sorted(set(live) - action.keys())
            if missing:
                raise SpaceMismatch(f"no action for agent {missing[0]!r}")
            return {name: self._check_actions[name](action[name]) for name in live}
        except SpaceMismatch as error:
            raise RequestError(ErrorCode.INVALID_ACTION, f"{where}{error}") from None

    def act(self, action: Any, frames: int) -> None:
        """Run a checked action for ``frames`` ticks (lockstep), or apply it now (real time)."""
        tree = self.tree
        if tree.real_time:
            self._act_now(action)
            return
        self._ticks = 0
        self.state = Episode.ACTING
        self.log.acted(action, frames)
        self.environment._step(action, frames)
        tree.paused = True
        self.state = Episode.RUNNING
        for agent in self.agents:
            if not (agent.terminated or agent.truncated):
                break
        else:
            self.state = Episode.ENDED
        if self.replaying:  # the restore's answer reports none of the replay's ticks
            self._ticks = 0
            for agent in self.agents:
                agent.reward = 0.0

    def _act_now(self, action: Any) -> None:
        """Real time: give the action at once; the answer carries the latest state.

        An action arriving more than ``repeat_action`` ticks after the previous one is late; an
        action after the episode ended (unseen by the client) is not applied.
        """
        tree = self.tree
        self._late = tree.physics_frames - self._last_action_at > self.environment.repeat_action
        self._late_actions += self._late
        self._last_action_at = tree.physics_frames
        if self._ended_unseen:
            return
        if self.multi_agent:
            for agent in self.agents:
                if agent.name in action:
                    agent.set_action(action[agent.name])
        else:
            self.agents[0].set_action(action)

    def _end_tick(self, delta: float) -> None:
        """The end of a tick (after pymunk stepped): rewards, flags, the end of the episode."""
        state = self.state
        if state is not Episode.ACTING and not (
                state is Episode.RUNNING and self.tree.real_time and not self._ended_unseen):
            return
        self._ticks += 1
        agents = self.agents
        for agent in agents:
            agent._after_physics_tick(delta)
        if self._recorder is not None:
            environment = self.environment
            self._recorder.add(environment._render(*environment.render_size))
        for agent in agents:
            if not (agent.terminated or agent.truncated):
                return
        if state is Episode.RUNNING:  # real time: stop, tell the next request
            self.tree.paused = True
            self._ended_unseen = True
        else:
            self.environment.physics_frames_timer.stop()

    # --- answers ----------------------------------------------------------------------------

    def observe(self, request: Mapping[str, Any]) -> dict[str, Any]:
        """The parts of the state an ``observation`` part asks for.

        The agent observation is in its space's packed form (keyed by agent name with several
        agents).

        Raises:
            ValueError: an agent's observation does not fit its space or is not finite (the
                environment's fault: answered as ``environment_error``).
        """
        observation = {}
        if "agent" in request:
            asked = request["agent"]
            if self.multi_agent:
                observation["agent"] = {agent.name: packed_observation(agent, codec, asked)
                                        for agent, codec in self._observers}
            else:
                agent, codec = self._observers[0]
                observation["agent"] = packed_observation(agent, codec, asked)
        if "world" in request:
            world = self.environment.world
            assert world is not None
            data = observation["world"] = world.get_data(request["world"])
            check_text_keys(data, f"{type(world).__name__}.get_data() returned")
        if "render" in request:
            size = request["render"]
            width, height = self.environment.render_size
            observation["render"] = self.environment._render(size.get("width", width),
                                                             size.get("height", height))
        if "draw" in request:
            drawn = observation["draw"] = self.environment._draw()
            check_text_keys(drawn, "_draw() returned")
        return observation

    def _response(self, answer: Answer, observation: dict[str, Any] | None) -> Response:
        """The answer: what was observed, the flags, and the rewards and ticks since the last.

        Only an answer that ``reports`` them counts them, and starts them again from zero.
        ``info`` holds the environment's ``_get_info()`` while an episode exists.
        """
        reports = answer.reports
        agents = self.agents
        outcomes = None
        if self.multi_agent:
            outcomes = {each.name: {"reward": float(each.reward) if reports else 0.0,
                                    "terminated": bool(each.terminated),
                                    "truncated": bool(each.truncated)} for each in agents}
            ended = all(o["terminated"] or o["truncated"] for o in outcomes.values())
            terminated = ended and any(o["terminated"] for o in outcomes.values())
            truncated = ended and not terminated
            reward = sum(o["reward"] for o in outcomes.values())
            if reports:
                for each in agents:
                    each.reward = 0.0
        else:
            agent = agents[0]
            reward = float(agent.reward) if reports else 0.0
            terminated, truncated = bool(agent.terminated), bool(agent.truncated)
            if reports:
                agent.reward = 0.0
        frames = 0
        if reports:
            frames = self.take_ticks()
            if outcomes is None:
                self.stats.reported(reward, frames, answer.acted)
            else:
                self.stats.reported_agents({name: o["reward"] for name, o in outcomes.items()},
                                           frames, answer.acted)
            if terminated or truncated:
                self.stats.end("terminated" if terminated else "truncated")
        if terminated or truncated:  # real time: the client now knows the episode ended
            self.state = Episode.ENDED
        info: dict[str, Any] = {}
        if self.state is not Episode.NOT_STARTED:
            info = self.environment._get_info()
            if info:
                check_text_keys(info, "_get_info() returned")
        if answer.acted and self.tree.real_time:
            info = {**info, "late": self._late, "late_actions": self._late_actions}
        if answer.info:
            check_text_keys(answer.info, "the answer holds")
            info = {**info, **answer.info}
        return Response(answer.reply_id, observation, reward, terminated, truncated, info,
                        frames, outcomes)

    def take_ticks(self) -> int:
        """The ticks run since the last answer that reported them; counting starts again."""
        ticks, self._ticks = self._ticks, 0
        return ticks

    def environment_error(self, reply_id: int, error: BaseException) -> ErrorReply:
        """The ``environment_error`` answer for an exception in user code (its traceback in it).

        The tree is paused and the next action needs a reset first.
        """
        self.abandon_episode("the episode was stopped by an environment_error")
        return failure(reply_id, error, "reset required")

    def abandon_episode(self, why: str) -> None:
        """Stop the episode where it is: the tree paused, the next action needs a reset.

        Refusals for want of an episode then say ``why``.
        """
        self.environment.physics_frames_timer.stop()
        self.tree.paused = True
        self.state = Episode.NOT_STARTED
        self._no_episode = f"{why}; reset first"
        self.stats.end("error")
        self._ticks = 0  # the failed request's ticks and rewards are no one's
        for agent in self.agents:
            agent.reward = 0.0

    def refuse_without_episode(self) -> None:
        """Refuse what needs an episode, saying why there is none.

        Raises:
            RequestError: ``reset_required``.
        """
        raise RequestError(ErrorCode.RESET_REQUIRED, self._no_episode)


def failure(reply_id: int | None, error: BaseException, consequence: str) -> ErrorReply:
    """The ``environment_error`` answer for an exception in user code, with its traceback."""
    logger.error("environment error", exc_info=error)
    detail = "".join(traceback.format_exception(error)).rstrip()
    return ErrorReply(reply_id, ErrorCode.ENVIRONMENT_ERROR, f"{error}; {consequence}\n{detail}")


def check_text_keys(value: Any, what: str) -> None:
    """Refuse data whose maps have a key that is not a str (clients refuse such a frame).

    Raises:
        ValueError: naming ``what`` and the key (the environment's fault: an
            ``environment_error``).
    """
    problem = find_non_text_key(value)
    if problem is not None:
        raise ValueError(f"{what} data that cannot travel: {problem}")


def _agents_of(environment: RLEnvironment) -> list[RLAgent]:
    """The environment's agents, each with its spaces; and it must have a world.

    An ``_ready`` that sets only ``self.agent`` (the seed's way) has that one agent.
    """
    if not environment.agents and environment.agent is not None:
        environment.agents = [environment.agent]
    if not environment.agents:
        raise RuntimeError(f"{environment!r} has no agent: add an RLAgent child or set "
                           "self.agent")
    if environment.world is None:
        raise RuntimeError(f"{environment!r} has no world: add an RLEnvWorld child or set "
                           "self.world")
    for agent in environment.agents:
        for attribute in ("action_space", "observation_space"):
            if not isinstance(getattr(agent, attribute, None), spaces.Space):
                raise RuntimeError(f"{agent!r} must set {attribute} to a gymnasium space")
    return list(environment.agents)


def packed_observation(agent: RLAgent, codec: Codec, request: Any) -> Any:
    """The agent's observation (``get_data(request)``) packed by ``codec``.

    Raises:
        FloatingPointError: it holds NaN or infinity (saying where).
        ValueError: it does not fit the agent's observation space.
    """
    data = agent.get_data(request)
    try:
        return codec.pack(data)
    except SpaceMismatch as error:
        where = find_non_finite(data)
        if where is not None:
            raise FloatingPointError(f"the observation of {agent.get_path()} is not finite at "
                                     f"{where or '()'}: {data!r:.200}") from None
        raise ValueError(f"the observation of {agent.get_path()} does not fit its space "
                         f"{agent.observation_space}: it {error}") from None


_CONFIG_PARTS = frozenset({"environment", "agent", "world"})
_HOOKS = ("_on_got_connection", "_configure", "_send_response", "_after_send_response")


def check_keys(part: Mapping[str, Any], allowed: frozenset[str], where: str) -> None:
    """Refuse (``bad_request``) a key of ``part`` that is not ``allowed``, naming them all."""
    unknown = part.keys() - allowed
    if unknown:
        raise RequestError(
            ErrorCode.BAD_REQUEST,
            f"unknown key {sorted(map(str, unknown))[0]!r} in {where}; expected any of "
            + ", ".join(sorted(allowed)),
        )


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
