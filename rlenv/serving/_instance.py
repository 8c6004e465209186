"""Instance: one environment in a scene tree of its own, and the state of its episode.

The host (:mod:`rlenv.serving._host`) hands an instance each request as a **plan**: a map from
each part of the request to its checked value, in the order they apply (:mod:`rlenv.serving._parts`
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

import logging
import os
import time
import traceback
from collections.abc import Callable, Mapping
from enum import Enum
from pathlib import Path
from typing import Any

from gymnasium import spaces
from gymnasium.utils import seeding

from rlenv.agent import RLAgent
from rlenv.environment import RLEnvironment, give_action
from rlenv.node import Node, check_initialised
from rlenv.protocol import ErrorReply, Response
from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.protocol.messages import joint_end
from rlenv.serving import _inspector as inspector
from rlenv.serving._actions import ActionCheck
from rlenv.serving._claims import Claims, Requester
from rlenv.serving._observing import Observer, check_text_keys
from rlenv.serving._recent import KEEP_EPISODES, KEEP_EVENTS, RecentEpisodes
from rlenv.serving._settings import Settings
from rlenv.serving._snapshots import EpisodeLog
from rlenv.serving._stats import EpisodeStats
from rlenv.serving._target_hints import explain_target_error
from rlenv.serving.onnx_policy import PolicyError
from rlenv.serving.policy_driver import HEURISTIC, DrivenAgents
from rlenv.targets import import_module
from rlenv.tree import SceneTree

__all__ = ["Answer", "Episode", "Instance", "Plan", "failure", "load_environment"]

logger = logging.getLogger(__name__)


def load_environment(target: str) -> type[RLEnvironment]:
    """Import the environment class named ``MODULE:CLASS``.

    A shipped example loads under its one name in this process, whichever of its two names
    ``target`` uses (``examples.X`` in a checkout, ``rlenv.examples.X`` installed:
    :mod:`rlenv.targets`).

    Raises:
        ValueError: ``target`` is not of the form ``MODULE:CLASS``.
        ImportError: the module cannot be imported, or has no such class (with a hint where
            one helps: :mod:`rlenv.serving._target_hints`).
        TypeError: the attribute is not an RLEnvironment subclass.
    """
    module_name, _, class_name = target.partition(":")
    if not module_name or not class_name:
        raise ValueError(f"expected MODULE:CLASS, e.g. examples.cartpole:CartPoleEnvironment, "
                         f"got {target!r}")
    try:
        module = import_module(module_name)
        if not hasattr(module, class_name):
            raise ImportError(f"module {module_name!r} has no attribute {class_name!r}")
    except ImportError as error:  # said with a hint where one helps (drop .py, did you mean)
        hint = explain_target_error(error, target)
        if hint is None:
            raise
        raise ImportError(hint) from None
    environment_class = getattr(module, class_name)
    if not (isinstance(environment_class, type) and issubclass(environment_class, RLEnvironment)):
        raise TypeError(f"{target} is not an RLEnvironment subclass")
    return environment_class


class Episode(Enum):
    """Where the episode stands, as far as requests are concerned."""

    NOT_STARTED = "not started"
    RUNNING = "running"
    ACTING = "acting"
    ENDED = "ended"


_ACTING, _RUNNING = Episode.ACTING, Episode.RUNNING  # read on every tick: a global is cheaper


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
"""Applies every part of a plan to an instance, in order (:func:`rlenv.serving._parts.dispatch`)."""


class Instance:
    """An environment in a tree of its own, answering the plans handed to it.

    Args:
        environment: an environment instance, its class, or ``MODULE:CLASS``.
        dispatch: applies a plan's parts in order (the host passes
            :func:`rlenv.serving._parts.dispatch`).
        clock: the tree's clock, for real-time mode (tests pass a manual one).
        record_dir: where clients may have the environment record videos (``None``: nowhere).
        keep_episodes: how many finished episodes to keep as recordings (:attr:`recent`), from
            the start; ``None``: :data:`~rlenv.serving._recent.KEEP_EPISODES`, once a client
            asks for them.
        keep_events: how many events those may hold in all.

    Attributes:
        recent: the last finished episodes' logs (:mod:`rlenv.serving._recent`).
        broken: why the next reset rebuilds the environment from its class (user code raised
            while serving the controller), or ``None``.
        claims: the agents observers play (:mod:`rlenv.serving._claims`), ``None`` while none
            is claimed.
        requester: who sent the request being served (the host's, shared by its instances).
        real_time_changed: called after every switch of real time (:meth:`set_real_time`),
            whoever asked for it; the host knows by it which instances tick by the clock.

    Raises:
        TypeError: the environment's ``__init__`` did not call ``super().__init__()``.
        RuntimeError: the environment has no agent, no world, or an agent without spaces.
    """

    # Set by _enter (from __init__ on, and again by a rebuild).
    agents: list[RLAgent]
    multi_agent: bool
    action_space: spaces.Space
    observation_space: spaces.Space

    def __init__(self, environment: RLEnvironment | type[RLEnvironment] | str,
                 dispatch: Dispatch, clock: Callable[[], float] = time.monotonic,
                 record_dir: Path | None = None, keep_episodes: int | None = None,
                 keep_events: int = KEEP_EVENTS) -> None:
        if isinstance(environment, str):
            environment = load_environment(environment)
        self._class: type[RLEnvironment] | None = None  # what a rebuild builds (or none)
        if isinstance(environment, type):
            self._class = environment if environment.rebuild_after_error else None
            environment = environment()
        self._dispatch = dispatch
        self._clock = clock
        self.answer: Answer | None = None  # the answer to the request being served
        hooks = {name for name in _HOOKS
                 if getattr(type(environment), name) is not getattr(RLEnvironment, name)}
        self.dispatches_itself = "_on_got_connection" in hooks
        self.configures_itself = "_configure" in hooks
        self.responds_itself = "_send_response" in hooks
        self.has_after_send = "_after_send_response" in hooks
        self.driven: DrivenAgents | None = None  # agents a policy drives (rlenv serve --policy)
        self._heuristic_agents: DrivenAgents | None = None  # see _heuristics
        self.claims: Claims | None = None  # agents observers play (none: no cost in act)
        self.requester = Requester()  # who sent the request served (the host shares its own)
        self.real_time_changed: Callable[[], None] | None = None  # the host's, to follow it
        self._enter(environment)
        self.broken: str | None = None  # why the next reset rebuilds the environment
        self.settings = Settings(self, record_dir)
        self.state = Episode.NOT_STARTED
        self._no_episode = "no episode has started; reset first"  # why, when NOT_STARTED
        self.log = EpisodeLog()
        self.recent = RecentEpisodes(KEEP_EPISODES if keep_episodes is None else keep_episodes,
                                     keep_events, eager=keep_episodes is not None)
        self.stats = EpisodeStats([a.name for a in self.agents] if self.multi_agent else None)
        self._before_sets: dict[tuple[Node, str], Any] = {}  # what inspect sets replaced
        self.replaying = False  # restoring a snapshot: the episode moves on silently
        self._ticks = 0  # ticks the episode ran since the last answer
        self._ended_unseen = False  # real time: the episode ended between two requests
        self._last_action_at = 0
        self._late = False
        self._late_actions = 0

    def _enter(self, environment: RLEnvironment, replacing: bool = False) -> None:
        """Make ``environment`` this instance's, in a new tree (its ``_ready`` runs).

        Nothing of the instance changes if this raises. An environment ``replacing`` another
        (rebuilt) must have its spaces.

        Raises:
            TypeError: the environment's ``__init__`` did not call ``super().__init__()``.
            RuntimeError: the environment has no agent, no world, or an agent without spaces,
                or (rebuilt) spaces other than those of the environment it replaces.
        """
        check_initialised(environment)
        environment.communication.bind(self)
        tree = SceneTree(environment.physics_ticks_per_second, clock=self._clock)
        tree.root.add_child(environment)
        tree.paused = True
        agents = _agents_of(environment)
        action_space = _joint_space(agents, "action_space")
        observation_space = _joint_space(agents, "observation_space")
        if replacing and (action_space, observation_space) != (
                self.action_space, self.observation_space):
            raise RuntimeError(f"the rebuilt {type(environment).__name__} has other spaces "
                               "than the one it replaces; clients hold the first ones")
        tree.on_physics_tick_end = self._end_tick
        self.environment, self.tree, self.agents = environment, tree, agents
        self.multi_agent = len(agents) > 1
        self.action_space, self.observation_space = action_space, observation_space
        self.checked_action = ActionCheck(agents, action_space,
                                          self.driven.names if self.driven else frozenset())
        self.observe = Observer(environment, agents).observe

    # --- one way in -------------------------------------------------------------------------

    def serve(self, request: Plan, reply_id: int, reports: bool = True) -> Response | ErrorReply:
        """Serve a checked request (see :mod:`rlenv.serving._parts`) and return its answer.

        The request goes to the environment's ``_on_got_connection``. An exception in user code
        becomes an ``environment_error`` answer (the next action then needs a reset); a refusal
        found while applying becomes its error answer; either way a configuration the request
        applied is undone. Unless it ``reports`` (an answer to a client that does not control
        the environment), the answer carries no reward nor ticks and leaves them for the
        controller's next answer, and a failure of user code it met (a ``_draw`` of an
        inspector's, say) leaves the episode to its controller.

        After user code raised (:attr:`broken`), a request that starts an episode (``reset``,
        ``restore``) first rebuilds the environment (:meth:`rebuild`); its answer's ``info``
        says so under ``"rebuilt"``.
        """
        answer = self.answer = Answer(reply_id, reports)
        try:
            if self.broken is not None and ("reset" in request or "restore" in request):
                answer.info = {"rebuilt": self.rebuild()}
            if self.dispatches_itself:
                self.environment._on_got_connection(dict(request))
            else:
                self.dispatch(request)
            if answer.reply is None:
                raise RuntimeError(f"{type(self.environment).__name__}._on_got_connection sent "
                                   "no answer: call super()._on_got_connection(request)")
            return answer.reply
        except RequestError as error:
            self.settings.undo(answer)
            return ErrorReply(reply_id, error.code, str(error))
        except Exception as error:  # user code raised: report it, keep serving
            self.settings.undo(answer)
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
            self.mark_broken(error)
            self.abandon_episode(f"the episode was stopped: _after_send_response raised "
                                 f"{type(error).__name__}: {error}")

    def catch_up(self) -> None:
        """In real time, run the ticks that came due by the clock (and a frame).

        An exception in user code during those ticks is logged and ends the episode (the next
        action is refused with ``reset_required``, saying why); the server serves on.
        """
        if not self.tree.real_time:
            return
        try:
            self.tree.iteration()
        except Exception as error:  # user code raised between two requests: nobody to tell
            logger.error("a tick in real time raised", exc_info=error)
            self.mark_broken(error)
            self.abandon_episode(f"the episode was stopped: a tick raised "
                                 f"{type(error).__name__}: {error}")

    def time_to_next_tick(self) -> float | None:
        """Seconds until this instance's next tick is due (``None`` in lockstep)."""
        return self.tree.time_to_next_tick()

    def mark_broken(self, error: BaseException | str) -> None:
        """User code raised ``error`` (or stopped half way, ``why``): the next reset rebuilds.

        Nothing happens if the environment opted out (``rebuild_after_error = False``) or was
        given as an object rather than its class (there is nothing to build it again from).
        """
        if self._class is not None and self.broken is None:
            why = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
            self.broken = why[:_MAX_WHY]

    def rebuild(self) -> str:
        """Build the environment again from its class, in a new tree; why it was rebuilt.

        The new environment is constructed, enters its tree and is ready, as at the start; it
        takes over the configuration, the random generator and real time of the one it
        replaces (as a reset keeps them), and no episode runs. If building raises, the
        instance keeps the environment it had (and stays :attr:`broken`).

        Raises:
            RuntimeError: the instance has no class to rebuild from.
        """
        if self._class is None:
            raise RuntimeError("this instance was given an environment object: it has no "
                               "class to rebuild it from")
        why = self.broken or "asked"
        old, old_tree = self.environment, self.tree
        config = self.settings.state()
        generator = old.np_random
        self._enter(self._class(), replacing=True)
        self._before_sets.clear()
        self.environment.np_random = generator
        self.tree.real_time = old_tree.real_time
        self.settings.carry(config)
        self.broken = None
        self.state = Episode.NOT_STARTED
        try:
            old_tree.root.remove_child(old)
        except Exception as error:  # the broken environment's _exit_tree: its own business
            logger.warning("the replaced %s raised leaving its tree", type(old).__name__,
                           exc_info=error)
        logger.warning("%s rebuilt from its class after %s", type(old).__name__, why)
        return why

    def close(self) -> None:
        """Stop any recording and take the environment out of its tree."""
        self.settings.record("")
        if self.environment.parent is not None:
            self.tree.root.remove_child(self.environment)

    # --- configuration ----------------------------------------------------------------------

    def apply_config(self, config: Mapping[str, Any]) -> None:
        """Apply a checked ``config`` part to its nodes (what ``_configure`` does by default)."""
        self.settings.apply(config)

    def forget_set(self, node: Node, name: str) -> None:
        """A configuration now owns ``node``'s ``name``: a reset no longer undoes its set."""
        self._before_sets.pop((node, name), None)

    def set_real_time(self, value: bool) -> None:
        """Switch between real time (ticks follow the clock) and lockstep.

        Whoever asks (a ``config``, an inspector's ``configure``, a ``batch``, a ``steps``
        request's ``reset_with``, a restore), the switch is made here alone, and
        :attr:`real_time_changed` (the host's) hears of it: the tree's ``real_time`` is the one
        place that says whether the instance runs by the clock.
        """
        self.tree.real_time = value
        if value:
            self.log.timed = True
        self.tree.paused = not (value and self.state is Episode.RUNNING and
                                not self._ended_unseen)
        if self.real_time_changed is not None:
            self.real_time_changed()

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

    def _heuristics(self) -> DrivenAgents:
        """Every agent that has a heuristic, driven by it (for a request's ``heuristic``)."""
        if self._heuristic_agents is None:
            self._heuristic_agents = DrivenAgents(
                {a.name: HEURISTIC for a in self.agents if a.has_heuristic()}, self.agents)
        return self._heuristic_agents

    def drive(self, driven: DrivenAgents) -> None:
        """Let policies act for the ``driven`` agents within every action (several agents)."""
        self.driven = driven
        self.checked_action = ActionCheck(self.agents, self.action_space, driven.names)

    def begin_episode(self, seed: int | None, options: Mapping[str, Any]) -> None:
        """Reset: undo ``inspect`` sets, seed the generator (if given), start a new episode.

        The episode under way is finished: :attr:`recent` may keep its log. If the
        environment's reset refuses (a ``RequestError`` from user code, such as level data it
        cannot build), no episode runs and the next reset rebuilds the environment: the
        refusal may have come half way through.
        """
        environment = self.environment
        if self.log.started and self.recent.keeping:
            self._finish_episode()
        for (node, name), value in reversed(self._before_sets.items()):
            setattr(node, name, value)
        self._before_sets.clear()
        if seed is not None:
            environment.np_random, _ = seeding.np_random(seed)
        self.log.begin(self.settings.capture(), environment.np_random, options)
        self.log.timed = self.tree.real_time
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
        try:
            environment._reset(options)
        except RequestError as error:  # refused half way (level data, say): nothing is sure
            self.mark_broken(error)
            self.abandon_episode(f"the reset was refused ({error})")
            raise

    def _finish_episode(self) -> None:
        """Hand the episode's log to :attr:`recent` (unless an error stopped the episode)."""
        if self.state is Episode.NOT_STARTED:  # an environment_error: its replay would fail
            return
        agents = self.agents
        if self.multi_agent:  # as an answer reports them
            terminated, truncated = joint_end([(agent.terminated, agent.truncated)
                                                for agent in agents])
        else:
            terminated, truncated = agents[0].terminated, agents[0].truncated
        if self.recent.finished(self.log, bool(terminated), bool(truncated)):
            self.log = EpisodeLog()

    def check_can_act(self) -> None:
        """Refuse a step before the first reset or after the episode ended.

        Raises:
            RequestError: ``reset_required``.
        """
        if self.state is Episode.NOT_STARTED:
            self.refuse_without_episode()
        if self.state is Episode.ENDED:
            raise RequestError(ErrorCode.RESET_REQUIRED, "the episode has ended; reset first")

    def act(self, action: Any, frames: int, heuristic: frozenset[str] = frozenset()) -> None:
        """Run a checked action for ``frames`` ticks (lockstep), or apply it now (real time).

        With several agents, the driven agents' actions, the claimed agents' held actions
        (:mod:`rlenv.serving._claims`) and those of the agents named in ``heuristic`` (by their
        heuristic) are put in first, unless the action replays a log.
        """
        tree = self.tree
        if self.multi_agent and not self.replaying:
            try:
                if self.driven is not None:
                    action = self.driven.complete(action, self.agents)
                if self.claims is not None:
                    action, heuristic = self.claims.complete(action, heuristic)
                if heuristic:
                    action = {**action, **self._heuristics().actions(self.agents, heuristic)}
            except PolicyError as error:  # a failed episode; the environment is intact
                self.abandon_episode(f"the episode failed: {error}")
                raise RequestError(ErrorCode.ENVIRONMENT_ERROR, f"{error}; reset required") \
                    from None
        if tree.real_time:
            self._act_now(action)
            return
        self._ticks = 0
        self.state = _ACTING
        self.log.acted(action, frames)
        self.environment._step(action, frames)
        tree.paused = True
        self.state = _RUNNING
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
        if not self._ended_unseen:
            give_action(self.agents, action)

    def _end_tick(self, delta: float) -> None:
        """The end of a tick (after pymunk stepped): rewards, flags, the end of the episode."""
        state = self.state
        if state is not _ACTING and not (
                state is _RUNNING and self.tree.real_time and not self._ended_unseen):
            return
        self._ticks += 1
        agents = self.agents
        for agent in agents:
            agent._after_physics_tick(delta)
        recorder = self.settings.recorder
        if recorder is not None:
            environment = self.environment
            recorder.add(environment._render(*environment.render_size))
        for agent in agents:
            if not (agent.terminated or agent.truncated):
                return
        if state is _RUNNING:  # real time: stop, tell the next request
            self.tree.paused = True
            self._ended_unseen = True
        else:
            self.environment.physics_frames_timer.stop()

    # --- answers ----------------------------------------------------------------------------

    def _response(self, answer: Answer, observation: dict[str, Any] | None) -> Response:
        """The answer: what was observed, the flags, and the rewards and ticks since the last."""
        reward, terminated, truncated, frames, outcomes = self.report(answer.reports,
                                                                      answer.acted)
        return Response(answer.reply_id, observation, reward, terminated, truncated,
                        self.info(answer.acted, answer.info), frames, outcomes)

    def report(self, reports: bool, acted: bool) -> tuple[float, bool, bool, int, Any]:
        """What an answer reports: reward, flags, ticks, and each agent's with several.

        Only an answer that ``reports`` them (to the controller) counts the rewards and ticks
        since the previous such answer, and starts them again from zero.
        """
        reward, terminated, truncated, outcomes = _outcome(self.agents, self.multi_agent,
                                                           reports)
        frames = 0
        if reports:
            frames, self._ticks = self._ticks, 0
            if outcomes is None:
                self.stats.reported(reward, frames, acted)
            else:
                self.stats.reported_agents({name: o["reward"] for name, o in outcomes.items()},
                                           frames, acted)
            if terminated or truncated:
                self.stats.end("terminated" if terminated else "truncated")
        if terminated or truncated:  # real time: the client now knows the episode ended
            self.state = Episode.ENDED
        return reward, terminated, truncated, frames, outcomes

    def info(self, acted: bool, extra: dict[str, Any] | None) -> dict[str, Any]:
        """An answer's ``info``: ``_get_info()`` while an episode exists, real time's, ``extra``.

        While observers claim agents (:mod:`rlenv.serving._claims`), ``"claimed"`` lists them.
        """
        info: dict[str, Any] = {}
        if self.state is not Episode.NOT_STARTED:
            info = self.environment._get_info()
            if info:
                check_text_keys(info, "_get_info() returned")
        if acted and self.tree.real_time:
            info = {**info, "late": self._late, "late_actions": self._late_actions}
        if extra:
            check_text_keys(extra, "the answer holds")
            info = {**info, **extra}
        if self.claims is not None:
            info = {**info, "claimed": [a.name for a in self.agents if a.name in
                                        self.claims.owners]}
        return info

    def claim(self, owner: object, name: str, action: Any) -> None:
        """``owner`` (an observer's connection) plays agent ``name`` with ``action`` (checked)."""
        if self.claims is None:
            self.claims = Claims()
        self.claims.hold(owner, name, action)

    def release_claim(self, owner: object) -> None:
        """End ``owner``'s claim, if it holds one (its agent goes back to the controller)."""
        if self.claims is not None and not self.claims.release(owner):
            self.claims = None

    def environment_error(self, reply_id: int, error: BaseException) -> ErrorReply:
        """The ``environment_error`` answer for an exception in user code (its traceback in it).

        The tree is paused and the next action needs a reset first (which rebuilds the
        environment, see :meth:`mark_broken`).
        """
        self.mark_broken(error)
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
    """The ``environment_error`` answer for an exception in user code, with its traceback.

    Files under the server's working folder are named relative to it: a client learns where
    the error is in the environment's code, not how the server's machine is laid out.
    """
    logger.error("environment error", exc_info=error)
    detail = "".join(traceback.format_exception(error)).rstrip()
    detail = detail.replace(f'File "{os.getcwd()}{os.sep}', 'File "')
    return ErrorReply(reply_id, ErrorCode.ENVIRONMENT_ERROR, f"{error}; {consequence}\n{detail}")


def _outcome(agents: list[RLAgent], several: bool,
             reports: bool) -> tuple[float, bool, bool, dict[str, dict[str, Any]] | None]:
    """The agents' reward (reset to zero if it ``reports`` it) and flags, and each one's."""
    if not several:
        agent = agents[0]
        reward = float(agent.reward) if reports else 0.0
        if reports:
            agent.reward = 0.0
        return reward, bool(agent.terminated), bool(agent.truncated), None
    outcomes: dict[str, dict[str, Any]] = {
        each.name: {"reward": float(each.reward) if reports else 0.0,
                    "terminated": bool(each.terminated), "truncated": bool(each.truncated)}
        for each in agents}
    terminated, truncated = joint_end([(o["terminated"], o["truncated"])
                                        for o in outcomes.values()])
    if reports:
        for each in agents:
            each.reward = 0.0
    return sum(o["reward"] for o in outcomes.values()), terminated, truncated, outcomes


def _joint_space(agents: list[RLAgent], which: str) -> spaces.Space:
    """The agents' ``which`` space: the agent's own, or a ``Dict`` keyed by agent name."""
    if len(agents) == 1:
        return getattr(agents[0], which)
    return spaces.Dict({agent.name: getattr(agent, which) for agent in agents})


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


_MAX_WHY = 500  # characters of an error kept to say why an environment was rebuilt

_HOOKS = ("_on_got_connection", "_configure", "_send_response", "_after_send_response")
