"""Instance: one environment in a scene tree of its own, serving its episodes' requests.

The host (:mod:`rlenv.serving._host`) hands an instance each request as a **plan**: a map from
each part of the request to its checked value, in the order they apply (:mod:`rlenv.serving._parts`
makes plans). One call serves a plan, whatever carried the request (a socket or this process,
alone, in a batch or in a column step): :meth:`Instance.serve`. It goes through the
environment's hooks, the Godot seed's: ``_on_got_connection(request)`` dispatches the parts
(``_configure``, ``_reset``, ``_step``), and ``_send_response`` gathers the answer; a hook that
is not overridden is not called at all (its default is what runs instead), so it costs nothing.
The parts use the primitives below (begin an episode, act, observe...); the episode's state
is its run's (:mod:`rlenv.serving._episode`), and the agents' rewards and ends their roster's
(:mod:`rlenv.serving._roster`).

Every answer reports what happened since the previous one: summed rewards, flags and ticks.
"""

from __future__ import annotations

import logging
import os
import time
import traceback
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from gymnasium import spaces

from rlenv.agent import RLAgent
from rlenv.environment import RLEnvironment
from rlenv.protocol import ErrorReply, Response
from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.serving._actions import ActionCheck
from rlenv.serving._answers import Answer, Answering
from rlenv.serving._claims import Claims, Requester
from rlenv.serving._entering import enter
from rlenv.serving._episode import Episode, EpisodeRun
from rlenv.serving._observing import Observer
from rlenv.serving._players import Players
from rlenv.serving._recent import KEEP_EPISODES, KEEP_EVENTS, RecentEpisodes
from rlenv.serving._recovery import Recovery
from rlenv.serving._roster import Roster
from rlenv.serving._settings import Settings
from rlenv.serving._snapshots import EpisodeLog
from rlenv.serving._stats import EpisodeStats
from rlenv.serving._target_hints import explain_target_error
from rlenv.serving.onnx_policy import PolicyError
from rlenv.serving.policy_driver import DrivenAgents
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
        raise ValueError(
            f"expected MODULE:CLASS, e.g. examples.cartpole:CartPoleEnvironment, got {target!r}"
        )
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
        roster: the environment's agents and how each fares (:mod:`rlenv.serving._roster`).
        episode: the episode under way and its log (:mod:`rlenv.serving._episode`), whose
            primitives the parts call on the instance: ``begin_episode``, ``check_can_act``,
            ``report``, ``abandon_episode``, ``refuse_without_episode``, ``set_property``,
            ``forget_set`` and ``catch_up`` are its
            :meth:`~rlenv.serving._episode.EpisodeRun.begin`, ``check_can_act``, ``report``,
            ``abandon``, ``refuse_without_episode``, ``set_property``, ``forget_set`` and
            ``catch_up``.
        recent: the last finished episodes' logs (:mod:`rlenv.serving._recent`).
        recovery: the rebuild of the environment after user code raised
            (:mod:`rlenv.serving._recovery`): ``mark_broken`` is its
            :meth:`~rlenv.serving._recovery.Recovery.mark_broken`.
        players: who acts for agents beside the controller (:mod:`rlenv.serving._players`):
            ``claim`` and ``release_claim`` are its :meth:`~rlenv.serving._players.Players.claim`
            and ``release``.
        requester: who sent the request being served (the host's, shared by its instances).
        real_time_changed: called after every switch of real time (:meth:`set_real_time`),
            whoever asked for it; the host knows by it which instances tick by the clock.

    Raises:
        TypeError: the environment's ``__init__`` did not call ``super().__init__()``.
        RuntimeError: the environment has no agent, no world, or an agent without spaces.
    """

    # Set by _enter (from __init__ on, and again by a rebuild).
    roster: Roster
    agents: list[RLAgent]
    multi_agent: bool
    action_space: spaces.Space
    observation_space: spaces.Space

    def __init__(
        self,
        environment: RLEnvironment | type[RLEnvironment] | str,
        dispatch: Dispatch,
        clock: Callable[[], float] = time.monotonic,
        record_dir: Path | None = None,
        keep_episodes: int | None = None,
        keep_events: int = KEEP_EVENTS,
    ) -> None:
        if isinstance(environment, str):
            environment = load_environment(environment)
        recovery = self.recovery = Recovery(environment)  # rebuilds from a class, if given one
        self.mark_broken = recovery.mark_broken
        if isinstance(environment, type):
            environment = environment()
        self._dispatch = dispatch
        self._clock = clock
        self.answer: Answer | None = None  # the answer to the request being served
        hooks = {
            name
            for name in _HOOKS
            if getattr(type(environment), name) is not getattr(RLEnvironment, name)
        }
        self.dispatches_itself = "_on_got_connection" in hooks
        self.configures_itself = "_configure" in hooks
        self.responds_itself = "_send_response" in hooks
        self.has_after_send = "_after_send_response" in hooks
        players = self.players = Players()  # who acts for agents beside the controller
        self._decide = lambda: players.decide(self.roster)  # made once: act is a hot path
        self.claim, self.release_claim = players.claim, players.release
        self.requester = Requester()  # who sent the request served (the host shares its own)
        self.real_time_changed: Callable[[], None] | None = None  # the host's, to follow it
        self._enter(environment)
        self.settings = Settings(self, record_dir)
        self.recent = RecentEpisodes(
            KEEP_EPISODES if keep_episodes is None else keep_episodes,
            keep_events,
            eager=keep_episodes is not None,
        )
        self.stats = EpisodeStats(
            [a.name for a in self.roster.actors()] if self.multi_agent else None
        )
        episode = self.episode = EpisodeRun(
            self.environment,
            self.tree,
            self.roster,
            self.settings,
            self.stats,
            self.recent,
            self.mark_broken,
        )
        self.begin_episode, self.check_can_act = episode.begin, episode.check_can_act
        self.report, self.abandon_episode = episode.report, episode.abandon
        self.refuse_without_episode = episode.refuse_without_episode
        self.set_property, self.forget_set = episode.set_property, episode.forget_set
        self.catch_up = episode.catch_up
        answering = self.answering = Answering(episode, players)  # what the answers say
        self.info = answering.info
        self.replaying = False  # restoring a snapshot: the episode moves on silently

    def _enter(self, environment: RLEnvironment, replacing: bool = False) -> SceneTree:
        """Make ``environment`` this instance's, in a new tree (its ``_ready`` runs); the tree.

        Nothing of the instance changes if this raises (see
        :func:`~rlenv.serving._entering.enter`). An environment ``replacing`` another (rebuilt)
        must have its spaces; its episodes run from then on.
        """
        held = (self.action_space, self.observation_space) if replacing else None
        tree, roster, action_space, observation_space = enter(environment, self, self._clock, held)
        self.environment, self.tree, self.roster = environment, tree, roster
        self.agents, self.multi_agent = roster.agents, roster.several
        self.action_space, self.observation_space = action_space, observation_space
        self.checked_action = ActionCheck.of(
            roster, action_space, self.driven.names if self.driven else frozenset()
        )
        self.observe = Observer(environment, roster).observe
        if replacing:
            self.episode.enter(environment, tree, roster)
        return tree

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
                raise RuntimeError(
                    f"{type(self.environment).__name__}._on_got_connection sent "
                    "no answer: call super()._on_got_connection(request)"
                )
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
        observation = (
            None
            if observation_request is None
            else self.observe(observation_request, answer.reports)
        )
        answer.reply = self.answering.response(answer, observation)

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
            self.abandon_episode(
                f"the episode was stopped: _after_send_response raised "
                f"{type(error).__name__}: {error}"
            )

    def time_to_next_tick(self) -> float | None:
        """Seconds until this instance's next tick is due (``None`` in lockstep)."""
        return self.tree.time_to_next_tick()

    @property
    def broken(self) -> str | None:
        """Why the next reset rebuilds the environment (:attr:`recovery`'s), or ``None``."""
        return self.recovery.broken

    def rebuild(self) -> str:
        """Build the environment again from its class, in a new tree; why it was rebuilt.

        See :meth:`rlenv.serving._recovery.Recovery.rebuild`.
        """
        return self.recovery.rebuild(
            self.environment,
            self.tree,
            self.settings,
            lambda environment: self._enter(environment, replacing=True),
        )

    def close(self) -> None:
        """Stop any recording and take the environment out of its tree."""
        self.settings.record("")
        if self.environment.parent is not None:
            self.tree.root.remove_child(self.environment)

    # --- configuration ----------------------------------------------------------------------

    def apply_config(self, config: Mapping[str, Any]) -> None:
        """Apply a checked ``config`` part to its nodes (what ``_configure`` does by default)."""
        self.settings.apply(config)

    def set_real_time(self, value: bool) -> None:
        """Switch between real time (ticks follow the clock) and lockstep.

        Whoever asks (a ``config``, an inspector's ``configure``, a ``batch``, a ``steps``
        request's ``reset_with``, a restore), the switch is made here alone, and
        :attr:`real_time_changed` (the host's) hears of it: the tree's ``real_time`` is the one
        place that says whether the instance runs by the clock.
        """
        self.episode.set_real_time(value)
        if self.real_time_changed is not None:
            self.real_time_changed()

    # --- episodes ---------------------------------------------------------------------------

    @property
    def state(self) -> Episode:
        """Where the episode stands (its run's: :class:`~rlenv.serving._episode.EpisodeRun`)."""
        return self.episode.state

    @property
    def log(self) -> EpisodeLog:
        """The episode's log (:mod:`rlenv.serving._snapshots`), which snapshots replay."""
        return self.episode.log

    @property
    def driven(self) -> DrivenAgents | None:
        """The agents policies drive (``rlenv serve --policy``), or ``None``."""
        return self.players.driven

    @property
    def claims(self) -> Claims | None:
        """The agents observers play (:mod:`rlenv.serving._claims`), or ``None``."""
        return self.players.claims

    def drive(self, driven: DrivenAgents) -> None:
        """Let policies act for the ``driven`` agents within every action (several agents)."""
        self.players.driven = driven
        self.checked_action = ActionCheck.of(self.roster, self.action_space, driven.names)

    def act(
        self,
        action: Any,
        frames: int,
        heuristic: frozenset[str] = frozenset(),
        goes_on: bool = False,
    ) -> None:
        """Run a checked action for ``frames`` ticks (lockstep), or apply it now (real time).

        With several agents, the driven agents' actions, the claimed agents' held actions
        (:mod:`rlenv.serving._claims`) and those of the agents named in ``heuristic`` (by their
        heuristic) are put in first, unless the action replays a log (a logged part of a step
        that ``goes_on``, too: see :meth:`EpisodeRun.act`).
        """
        players, roster = self.players, self.roster
        try:
            if self.multi_agent and not self.replaying:
                action = players.complete(action, heuristic, roster)
            self.episode.act(action, frames, self.replaying, self._decide, goes_on)
        except PolicyError as error:  # a failed episode; the environment is intact
            self.abandon_episode(f"the episode failed: {error}")
            raise RequestError(ErrorCode.ENVIRONMENT_ERROR, f"{error}; reset required") from None

    # --- answers ----------------------------------------------------------------------------

    def environment_error(self, reply_id: int, error: BaseException) -> ErrorReply:
        """The ``environment_error`` answer for an exception in user code (its traceback in it).

        The tree is paused and the next action needs a reset first (which rebuilds the
        environment, see :attr:`recovery`).
        """
        self.mark_broken(error)
        self.abandon_episode("the episode was stopped by an environment_error")
        return failure(reply_id, error, "reset required")


def failure(reply_id: int | None, error: BaseException, consequence: str) -> ErrorReply:
    """The ``environment_error`` answer for an exception in user code, with its traceback.

    Files under the server's working folder are named relative to it: a client learns where
    the error is in the environment's code, not how the server's machine is laid out.
    """
    logger.error("environment error", exc_info=error)
    detail = "".join(traceback.format_exception(error)).rstrip()
    detail = detail.replace(f'File "{os.getcwd()}{os.sep}', 'File "')
    return ErrorReply(reply_id, ErrorCode.ENVIRONMENT_ERROR, f"{error}; {consequence}\n{detail}")


_HOOKS = ("_on_got_connection", "_configure", "_send_response", "_after_send_response")
