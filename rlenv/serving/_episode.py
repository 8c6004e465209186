"""EpisodeRun: the episode under way in one instance's tree, from its reset to its end.

The instance (:mod:`rlenv.serving._instance`) serves requests; its run keeps the episode's
state, which the requests' parts read and move on:

- **not started** until the first reset; **running** between actions; **acting** while an
  action's ticks run; **ended** once every agent terminated or was truncated (a step is then
  refused until the next reset);
- an action (lockstep) hands the checked action to the environment's ``_step``, which unpauses
  the tree for ``repeat_action`` ticks. At the end of every tick, after pymunk stepped, the
  run calls each agent's ``_after_physics_tick`` (the tree's ``on_physics_tick_end``) and
  stops the action early when the episode ends;
- in real time the tree ticks by the clock between requests, an action applies at once, and an
  episode that ends between two requests pauses the tree until the next one learns of it.

The run also keeps the episode's log (what snapshots replay, handed to the recent episodes
when the next reset finishes it) and what ``inspect`` set during the episode, which the next
reset undoes; what each agent earned and how it ended is the roster's
(:mod:`rlenv.serving._roster`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from enum import Enum
from typing import TYPE_CHECKING, Any

from gymnasium.utils import seeding

from rlenv.environment import RLEnvironment, give_action
from rlenv.node import Node
from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.serving import _inspector as inspector
from rlenv.serving._observing import check_text_keys
from rlenv.serving._recent import RecentEpisodes
from rlenv.serving._roster import Roster, reward_total
from rlenv.serving._snapshots import EpisodeLog
from rlenv.serving._stats import EpisodeStats
from rlenv.tree import SceneTree

if TYPE_CHECKING:
    from rlenv.serving._settings import Settings

__all__ = ["Episode", "EpisodeRun"]

logger = logging.getLogger(__name__)


class Episode(Enum):
    """Where the episode stands, as far as requests are concerned."""

    NOT_STARTED = "not started"
    RUNNING = "running"
    ACTING = "acting"
    ENDED = "ended"


_ACTING, _RUNNING = Episode.ACTING, Episode.RUNNING  # read on every tick: a global is cheaper


class EpisodeRun:
    """The episodes of one environment in its tree, one after another (the module docstring).

    Args:
        environment: the instance's environment, ``tree`` its tree and ``roster`` its agents
            (:meth:`enter` follows a rebuilt one).
        settings: the instance's configuration (what a log begins with; the video recorder).
        stats: the statistics the episodes add to.
        recent: the finished episodes' logs, which the run hands each log to.
        broken: told of an exception in user code after which the environment is not to be
            trusted (the instance's ``mark_broken``: the next reset rebuilds it).

    Attributes:
        state: where the episode stands.
        log: the episode's log (:mod:`rlenv.serving._snapshots`).
        late: real time: whether the last action came more than ``repeat_action`` ticks after
            the one before it; ``late_actions`` counts those of the episode.
    """

    def __init__(
        self,
        environment: RLEnvironment,
        tree: SceneTree,
        roster: Roster,
        settings: Settings,
        stats: EpisodeStats,
        recent: RecentEpisodes,
        broken: Callable[[BaseException], None],
    ) -> None:
        self.settings, self.stats, self.recent = settings, stats, recent
        self._broken = broken
        self.log = EpisodeLog()
        self._no_episode = "no episode has started; reset first"  # why, when NOT_STARTED
        self._before_sets: dict[tuple[Node, str], Any] = {}  # what inspect sets replaced
        self._ticks = 0  # ticks the episode ran since the last answer
        self._ended_unseen = False  # real time: the episode ended between two requests
        self._last_action_at = 0
        self.late = False
        self.late_actions = 0
        self.enter(environment, tree, roster)

    def enter(self, environment: RLEnvironment, tree: SceneTree, roster: Roster) -> None:
        """Run the episodes of ``environment`` in ``tree`` (a rebuilt one): none runs yet.

        What ``inspect`` set on the environment it replaces is forgotten.
        """
        tree.on_physics_tick_end = self._end_tick
        self.environment, self.tree, self.roster = environment, tree, roster
        self._before_sets.clear()
        self.state = Episode.NOT_STARTED

    # --- from a reset to the end ------------------------------------------------------------

    def begin(self, seed: int | None, options: Mapping[str, Any]) -> None:
        """Reset: undo ``inspect`` sets, seed the generator (if given), start a new episode.

        The episode under way is finished: the recent episodes may keep its log. If the
        environment's reset refuses (a ``RequestError`` from user code, such as level data it
        cannot build), no episode runs and the next reset rebuilds the environment: the
        refusal may have come half way through.
        """
        environment = self.environment
        if self.log.started and self.recent.keeping:
            self._finish()
        for (node, name), value in reversed(self._before_sets.items()):
            setattr(node, name, value)
        self._before_sets.clear()
        if seed is not None:
            environment.np_random, _ = seeding.np_random(seed)
        self.log.begin(self.settings.capture(), environment.np_random, options)
        self.log.timed = self.tree.real_time
        self.stats.begin()
        self.roster.begin()
        tree = self.tree
        self._ended_unseen = False
        self.late_actions = 0
        self._last_action_at = tree.physics_frames
        self._ticks = 0
        tree.paused = not tree.real_time
        self.state = Episode.RUNNING
        try:
            environment._reset(options)
            self.roster.started()
        except RequestError as error:  # refused half way (level data, say): nothing is sure
            self._broken(error)
            self.abandon(f"the reset was refused ({error})")
            raise

    def _finish(self) -> None:
        """Hand the episode's log to the recent episodes (unless an error stopped it)."""
        if self.state is Episode.NOT_STARTED:  # an environment_error: its replay would fail
            return
        if self.recent.finished(self.log, *self.roster.joint_end()):  # as an answer reports
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

    def act(
        self,
        action: Any,
        frames: int,
        replaying: bool,
        decide: Callable[[], Any] | None = None,
        goes_on: bool = False,
    ) -> None:
        """Run a checked (joint) action for ``frames`` ticks (lockstep), or apply it now.

        While agents come and go, the roster says how many ticks the step runs
        (:meth:`Roster.ticks_for`), and when only agents the server drives are due after them,
        ``decide`` gives their action and the step goes on (each part is logged as an action
        of its own, ``goes_on``). An action ``replaying`` a log (a restore) runs the ticks
        logged, and leaves its answer no reward nor ticks.
        """
        tree = self.tree
        if tree.real_time:
            self._act_now(action)
            return
        self._ticks = 0
        self.state = _ACTING
        roster = self.roster
        if goes_on:  # a replayed part of a step that went on: driven agents decided
            roster.decided(action)
        else:
            roster.acted()
        while True:
            ticks = frames if replaying else roster.ticks_for(frames)
            self.log.acted(action, ticks, goes_on)
            self.environment._step(action, ticks)
            roster.boundary()
            if replaying or decide is None or roster.ended():
                break
            action = decide()
            if action is None:
                break
            goes_on = True
        tree.paused = True
        self.state = Episode.ENDED if self.roster.ended() else _RUNNING
        if replaying:  # the restore's answer reports none of the replay's ticks
            self._ticks = 0
            self.roster.replayed()

    def _act_now(self, action: Any) -> None:
        """Real time: give the action at once; the answer carries the latest state.

        An action arriving more than ``repeat_action`` ticks after the previous one is late; an
        action after the episode ended (unseen by the client) is not applied.
        """
        tree = self.tree
        self.late = tree.physics_frames - self._last_action_at > self.environment.repeat_action
        self.late_actions += self.late
        self._last_action_at = tree.physics_frames
        if not self._ended_unseen:
            give_action(self.roster.agents, action, self.roster.several)

    def _end_tick(self, delta: float) -> None:
        """The end of a tick (after pymunk stepped): rewards, flags, the end of the episode."""
        state = self.state
        if state is not _ACTING and not (
            state is _RUNNING and self.tree.real_time and not self._ended_unseen
        ):
            return
        self._ticks += 1
        roster = self.roster
        roster.after_tick(delta)
        recorder = self.settings.recorder
        if recorder is not None:
            environment = self.environment
            recorder.add(environment._render(*environment.render_size))
        if not roster.ended():
            return
        if state is _RUNNING:  # real time: stop, tell the next request
            self.tree.paused = True
            self._ended_unseen = True
        else:
            self.environment.physics_frames_timer.stop()

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
            self._broken(error)
            self.abandon(f"the episode was stopped: a tick raised {type(error).__name__}: {error}")

    def report(self, reports: bool, acted: bool) -> tuple[float, bool, bool, int, Any]:
        """What an answer reports: reward, flags, ticks, and each agent's with several.

        Only an answer that ``reports`` them (to the controller) counts the rewards and ticks
        since the previous such answer, and starts them again from zero.
        """
        reward, terminated, truncated, outcomes = self.roster.outcome(reports)
        frames = 0
        if reports:
            frames, self._ticks = self._ticks, 0
            if outcomes is None:
                self.stats.reported(reward, frames, acted)
            else:
                self.stats.reported_agents(
                    {name: reward_total(o["reward"]) for name, o in outcomes.items()}, frames, acted
                )
            if terminated or truncated:
                self.stats.end("terminated" if terminated else "truncated")
        if terminated or truncated:  # real time: the client now knows the episode ended
            self.state = Episode.ENDED
        return reward, terminated, truncated, frames, outcomes

    def info(self, acted: bool) -> dict[str, Any]:
        """The episode's part of an answer's ``info``.

        ``_get_info()`` while an episode exists, and real time's lateness after an action.
        """
        info: dict[str, Any] = {}
        if self.state is not Episode.NOT_STARTED:
            info = self.environment._get_info()
            if info:
                check_text_keys(info, "_get_info() returned")
        if acted and self.tree.real_time:
            info = {**info, "late": self.late, "late_actions": self.late_actions}
        return info

    def abandon(self, why: str) -> None:
        """Stop the episode where it is: the tree paused, the next action needs a reset.

        Refusals for want of an episode then say ``why``.
        """
        self.environment.physics_frames_timer.stop()
        self.tree.paused = True
        self.state = Episode.NOT_STARTED
        self._no_episode = f"{why}; reset first"
        self.stats.end("error")
        self._ticks = 0  # the failed request's ticks and rewards are no one's
        self.roster.clear_rewards()
        self.roster.close()

    def refuse_without_episode(self) -> None:
        """Refuse what needs an episode, saying why there is none.

        Raises:
            RequestError: ``reset_required``.
        """
        raise RequestError(ErrorCode.RESET_REQUIRED, self._no_episode)

    # --- what changes during it -------------------------------------------------------------

    def set_real_time(self, value: bool) -> None:
        """Switch the tree between real time (ticks follow the clock) and lockstep.

        The tree runs by the clock only while an episode runs that the client knows of.
        """
        tree = self.tree
        tree.real_time = value
        if value:
            self.log.timed = True
        tree.paused = not (value and self.state is Episode.RUNNING and not self._ended_unseen)

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

    def forget_set(self, node: Node, name: str) -> None:
        """A configuration now owns ``node``'s ``name``: a reset no longer undoes its set."""
        self._before_sets.pop((node, name), None)
