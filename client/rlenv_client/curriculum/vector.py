"""A vector wrapper that picks each sub-environment's next level: prioritized level replay.

:class:`CurriculumVectorEnv` wraps a :class:`~rlenv_client.vector.RemoteVectorEnv`. At each
sub-environment's reset it plays a new level (an int seed drawn from its own generator: domain
randomisation) or replays one of its :class:`~rlenv_client.curriculum.LevelSampler`'s buffer,
as the sampler decides; it scores the episodes played and keeps the buffer. An int level is
played with ``reset(seed=level)``, a data level with ``reset(options={"level": data})``; a
sub-environment's autoreset inside a step carries them in the ``steps`` request (protocol 2.4).

At each reset, a sub-environment's ``info`` holds ``"replayed"`` (whether its new episode
replays a buffered level) and ``"level"`` (the replayed level's id; ``None`` for a new level),
each with gymnasium's mask (``info["_replayed"]``, ``info["_level"]``).

Scores (the ``score`` argument):

- ``"learnability"`` (the default, SFL): ``p * (1 - p)`` over the outcomes of the level's
  episodes seen so far (at most ``outcomes_kept``): for a new level, its first episode's, or
  its ``rollouts_per_level`` episodes' on trial (below). An episode succeeds when its last step's
  info says ``info["success"]`` is true; without a ``success`` in that info, when it
  terminated (not truncated) with a return above 0. Nothing is needed from the trainer.
- a callable: ``score(episode)`` gives each finished :class:`Episode`'s score.
- ``"external"``: the trainer scores finished episodes from its value estimates, with
  :meth:`CurriculumVectorEnv.score_rollout` (CleanRL-style loops) or
  :class:`rlenv_client.sb3.CurriculumCallback` (Stable-Baselines3); or with
  :meth:`CurriculumVectorEnv.update` from its own code.

A new level enters the buffer with its score (:meth:`LevelSampler.insert`); a replayed one has
its score updated. With ``rollouts_per_level=n`` (SFL: learnability needs several outcomes, one
outcome's is 0), a new level is first **on trial**: it is played ``n`` times, and only then
scored over those ``n`` episodes and offered to the buffer. Each time the sampler decides
against a replay, a sub-environment plays the next rollout of a level on trial if one waits for
it (the oldest first), else a new level, which goes on trial; so trial episodes take the place
of new levels and ``replay_prob`` keeps its meaning. A level on trial is not in the buffer: its
episodes report ``"replayed"`` False and ``"level"`` ``None``, and Robust PLR does not learn from
them. No more levels are on trial than the sub-environments have episodes under way or chosen
(two each). With ``edit_levels=n`` (ACCEL), when a sub-environment's replay ends, its
next episode plays that level with ``n`` random edits (the environment's, through
:meth:`~rlenv_client.base.BaseClient.edit_level`) as a new level, scored and offered to the
buffer like any other (on trial too, once no level on trial waits for a rollout): the
curriculum grows by small changes to the levels it replays.
With ``sampler.robust`` (Robust PLR) the trainer learns only from replayed
levels: :attr:`CurriculumVectorEnv.train_mask` says which of the last step's transitions to
learn from.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper
from numpy.typing import ArrayLike

from rlenv_client.curriculum._scoring import LevelScores
from rlenv_client.curriculum._trials import Trials
from rlenv_client.curriculum.levels import Level
from rlenv_client.curriculum.parameters import (
    EnvironmentParameters,
    configurable_keys,
    configure_arguments,
)
from rlenv_client.curriculum.sampler import LevelSampler

__all__ = ["DEFAULT_CAPACITY", "CurriculumVectorEnv", "Episode"]

logger = logging.getLogger(__name__)

DEFAULT_CAPACITY = 1000
"""The buffer size of the :class:`LevelSampler` a :class:`CurriculumVectorEnv` makes itself."""

_SEEDS = 2**31  # new levels are seeds in [0, 2**31)
_ROLLOUT_SCORES = ("positive_value_loss", "max_mc")


class Episode:
    """A finished episode, as a score sees it.

    Attributes:
        env: the sub-environment that played it.
        level: its level (an int seed or data).
        level_id: the buffered level's id if it was a replay, else ``None``.
        replayed: whether it replayed a buffered level.
        first_step: the index (counted over the wrapper's steps from 0) of its first step.
        last_step: the index of its last step (that ended it).
        reward: its return (the sum of its rewards).
        success: whether it succeeded (see the module docstring).
        rewards: each step's reward, for a callable score (else empty).
        trial: the number of the trial its level is on (``rollouts_per_level`` > 1), else
            ``None``.
    """

    __slots__ = (
        "env",
        "first_step",
        "last_step",
        "level",
        "level_id",
        "replayed",
        "reward",
        "rewards",
        "success",
        "trial",
    )

    def __init__(
        self,
        env: int,
        level: Level,
        level_id: int | None,
        first_step: int,
        trial: int | None = None,
    ) -> None:
        self.env, self.level, self.level_id, self.trial = env, level, level_id, trial
        self.replayed = level_id is not None
        self.first_step, self.last_step = first_step, first_step - 1
        self.reward, self.success = 0.0, False
        self.rewards: list[float] = []

    def __repr__(self) -> str:
        return (
            f"Episode(env={self.env}, level_id={self.level_id}, trial={self.trial}, "
            f"steps={self.first_step}..{self.last_step}, reward={self.reward:.3g}, "
            f"success={self.success})"
        )


class CurriculumVectorEnv(VectorWrapper):
    """Prioritized level replay over a vector's sub-environments (see the module docstring).

    Args:
        envs: a :class:`~rlenv_client.vector.RemoteVectorEnv` (or a wrapper of one whose
            ``unwrapped`` is), with ``NEXT_STEP`` or ``SAME_STEP`` autoreset.
        sampler: the level buffer; ``None`` makes ``LevelSampler(DEFAULT_CAPACITY)`` (seeded
            with ``seed``).
        parameters: ML-Agents' environment parameters: a draw of
            :meth:`~EnvironmentParameters.sample` is configured at every reset, and every
            finished episode's return goes to :meth:`~EnvironmentParameters.add_episode`
            (with :attr:`progress`).
        score: ``"learnability"``, a callable taking an :class:`Episode`, or ``"external"``.
        seed: seeds the generator of new levels (``reset(seed=...)`` seeds it again).
        outcomes_kept: how many outcomes per level learnability counts (the latest).
        edit_levels: ACCEL: after a replay, the sub-environment plays that level with this many
            edits (the environment's ``_edit_level``) as a new level; 0 (the default) never.
        rollouts_per_level: how many episodes a new level is played (on trial) before it is
            scored and offered to the buffer: with ``"learnability"``, ``p * (1 - p)`` over
            their outcomes; with a callable, the mean of its scores. 1 (the default, PLR and
            ACCEL) offers a level after its first episode; SFL needs more (4, say), since the
            learnability of one outcome is 0 and a full buffer refuses a score of 0.

    Raises:
        TypeError: ``envs`` is not over a ``RemoteVectorEnv``.
        ValueError: an unknown ``score``, an autoreset mode other than the two above,
            ``edit_levels`` not an int >= 0, or ``rollouts_per_level`` not an int >= 1 (or
            above 1 with ``score="external"``).
    """

    def __init__(
        self,
        envs: VectorEnv,
        sampler: LevelSampler | None = None,
        parameters: EnvironmentParameters | None = None,
        score: str | Callable[[Episode], float] = "learnability",
        *,
        seed: int | None = None,
        outcomes_kept: int = 32,
        edit_levels: int = 0,
        rollouts_per_level: int = 1,
    ) -> None:
        super().__init__(envs)
        remote: Any = envs.unwrapped  # a RemoteVectorEnv (checked next)
        if not hasattr(remote, "set_next_reset"):
            raise TypeError(
                f"CurriculumVectorEnv needs a RemoteVectorEnv, got {type(remote).__name__}"
            )
        if not (callable(score) or score in ("learnability", "external")):
            raise ValueError(
                f"score must be 'learnability', 'external' or a callable, not {score!r}"
            )
        mode = AutoresetMode(envs.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP))
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(
                f"CurriculumVectorEnv needs NEXT_STEP or SAME_STEP autoreset, not {mode}"
            )
        self._remote: Any = remote
        self._same_step = mode is AutoresetMode.SAME_STEP
        self.sampler = sampler if sampler is not None else LevelSampler(DEFAULT_CAPACITY, seed=seed)
        self.parameters = parameters
        if parameters is not None:
            parameters.bind(configurable_keys(self._remote.clients[0].tree()))
        self.score = score
        self.progress: float | None = None
        """The fraction of training done, for parameters whose lessons measure progress."""
        self.finished: list[Episode] = []
        """With ``score="external"``: the finished episodes not scored yet, oldest first."""
        self.train_mask = np.zeros(self.num_envs, np.bool_)
        """Whether to learn from each sub-environment's transition of the last step: it
        belongs to an episode (not a ``NEXT_STEP`` autoreset), on a replayed level if
        ``sampler.robust``."""
        self.steps = 0
        """How many steps this wrapper made (the index of the next one)."""
        self._rng = np.random.default_rng(seed)
        self._keep_rewards = callable(score)
        self._playing: list[Episode | None] = [None] * self.num_envs
        self._next: list[tuple[Level, int | None, int | None] | None] = [None] * self.num_envs
        self._autoreset = np.zeros(self.num_envs, np.bool_)
        if not isinstance(edit_levels, int) or isinstance(edit_levels, bool) or edit_levels < 0:
            raise ValueError(f"edit_levels must be an int >= 0, got {edit_levels!r}")
        self.edit_levels = edit_levels
        """ACCEL: how many edits make the level played after a replay (0: none)."""
        self._edited: list[Level | None] = [None] * self.num_envs
        if (
            not isinstance(rollouts_per_level, int)
            or isinstance(rollouts_per_level, bool)
            or rollouts_per_level < 1
        ):
            raise ValueError(f"rollouts_per_level must be an int >= 1, got {rollouts_per_level!r}")
        if rollouts_per_level > 1 and score == "external":
            raise ValueError(
                "rollouts_per_level > 1 needs a score the wrapper computes "
                "('learnability' or a callable), not 'external'"
            )
        self._trials = Trials(rollouts_per_level)
        self._scores = LevelScores(self.sampler, self._trials, outcomes_kept)

    @property
    def rollouts_per_level(self) -> int:
        """How many episodes a new level plays on trial before it is offered to the buffer."""
        return self._trials.rollouts_per_level

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: Mapping[str, Any] | None = None,
    ) -> tuple[Any, dict[str, Any]]:
        """Start every sub-environment on its next level (each new or replayed).

        Episodes under way are cut short: they give no outcome, and a level on trial is played
        once more for each.

        Args:
            seed: an int seeds the generator of new levels (the levels' seeds decide the
                episodes, so it is not passed on).
            options: passed on to the vector (each level's options replace them).

        Returns:
            ``(observations, infos)``, the infos with ``replayed`` and ``level``.
        """
        if isinstance(seed, int):
            self._rng = np.random.default_rng(seed)
        for index, episode in enumerate(self._playing):  # cut short: not an outcome
            self._playing[index] = None
            if episode is not None:
                self._lost(episode)
        for index in range(self.num_envs):
            if self._next[index] is None:
                self._choose(index)
        observations, infos = self.env.reset(options=None if options is None else dict(options))
        self._autoreset[:] = False
        return observations, self._begin(np.ones(self.num_envs, np.bool_), infos)

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        """Step every sub-environment; score the episodes that end; choose their next levels.

        Returns:
            gymnasium's ``(observations, rewards, terminations, truncations, infos)``; a
            sub-environment that reset in this step has ``replayed`` and ``level`` in infos.
        """
        observations, rewards, terminations, truncations, infos = self.env.step(actions)
        step = self.steps
        self.steps += 1
        ended = np.asarray(terminations) | np.asarray(truncations)
        started = self._autoreset if not self._same_step else np.zeros_like(ended)
        robust = self.sampler.robust
        for index, episode in enumerate(self._playing):
            if started[index] or episode is None:
                self.train_mask[index] = False
                continue
            self.train_mask[index] = episode.replayed or not robust
            reward = float(rewards[index])
            episode.reward += reward
            episode.last_step = step
            if self._keep_rewards:
                episode.rewards.append(reward)
        if self._same_step:
            last_infos = infos.get("final_info", {})
        else:
            last_infos = infos
            if started.any():
                infos = self._begin(started, infos)
        for done in np.flatnonzero(ended):
            self._finish(int(done), bool(terminations[done]), last_infos)
            if not self._same_step:
                self._choose(int(done))
        if self._same_step and ended.any():
            infos = self._begin(ended, infos)
        self._autoreset = ended
        return observations, rewards, terminations, truncations, infos

    def update(self, episode: Episode, score: float) -> int | None:
        """Score a finished episode's level: insert a new level, update a replayed one.

        An episode of a level on trial adds its score to the level's; after the last of its
        ``rollouts_per_level`` episodes, the level is offered with the mean of their scores.

        Returns:
            The level's id in the buffer; ``None`` if a new level was refused (the buffer is
            full of higher scores) or is still on trial, or a replayed one has left the buffer
            since.
        """
        return self._scores.update(episode, score)

    def score_rollout(
        self, advantages: ArrayLike, values: ArrayLike, score: str = "positive_value_loss"
    ) -> list[Episode]:
        """Score the episodes that ended in the last rollout, from the trainer's estimates.

        For a loop that steps this wrapper ``T`` times, then computes GAE: row ``t`` of the
        arrays is the wrapper's step ``steps - T + t`` (the transition it returned), column
        ``i`` sub-environment ``i``. Each finished episode that ended within those ``T``
        steps is scored on its steps among them and leaves :attr:`finished`; episodes that
        ended before are dropped unscored.

        Args:
            advantages: ``(T, num_envs)`` GAE advantages.
            values: ``(T, num_envs)`` value estimates ``V(s)``.
            score: ``"positive_value_loss"`` or ``"max_mc"`` (regret against the level's best
                return seen, :func:`~rlenv_client.curriculum.max_mc`).

        Returns:
            The episodes scored.

        Raises:
            ValueError: an unknown ``score``, or arrays of another shape.
        """
        if score not in _ROLLOUT_SCORES:
            raise ValueError(f"score must be one of {_ROLLOUT_SCORES}, not {score!r}")
        advantages = np.asarray(advantages, np.float64)
        values = np.asarray(values, np.float64)
        if (
            advantages.ndim != 2
            or advantages.shape[1] != self.num_envs
            or values.shape != advantages.shape
        ):
            raise ValueError(
                f"advantages and values must both be (T, {self.num_envs}), got "
                f"{advantages.shape} and {values.shape}"
            )
        first = self.steps - len(advantages)
        scored = []
        for episode in self.finished:
            if episode.last_step < first:
                continue
            rows = slice(max(episode.first_step, first) - first, episode.last_step - first + 1)
            self._scores.score_rollout(
                episode, score, advantages[rows, episode.env], values[rows, episode.env]
            )
            scored.append(episode)
        self.finished = []
        return scored

    # --- internals --------------------------------------------------------------------------

    def _choose(self, index: int) -> None:
        """Decide sub-environment ``index``'s next level and give it to the vector's reset."""
        sampler = self.sampler
        edited = self._edited[index]
        level: Level
        level_id = trial = None
        if edited is None and sampler.sample_replay_decision():
            level_id, level = sampler.sample_replay_level()
        elif (trial := self._trials.waiting()) is not None:  # the next rollout of one on trial
            level = self._trials.level(trial)
        elif edited is not None:  # ACCEL: the last replay's level, edited, as a new level
            self._edited[index] = None
            level = edited
            trial = self._trials.start(level)
        else:
            level = int(self._rng.integers(_SEEDS))
            trial = self._trials.start(level)
        if trial is not None:
            self._trials.chosen(trial)
        self._next[index] = (level, level_id, trial)
        config = None
        if self.parameters is not None:
            config = configure_arguments(self.parameters.sample())
        if isinstance(level, int):
            self._remote.set_next_reset(index, seed=level, config=config)
        else:
            self._remote.set_next_reset(index, options={"level": level}, config=config)

    def _begin(self, started: np.ndarray, infos: dict[str, Any]) -> dict[str, Any]:
        """Episodes start where ``started`` says: note their levels, in ``infos`` too."""
        indices = np.flatnonzero(started)
        replayed = infos.get("replayed", np.zeros(self.num_envs, np.bool_))
        levels = infos.get("level", np.full(self.num_envs, None, object))
        replayed_mask = infos.get("_replayed", np.zeros(self.num_envs, np.bool_))
        level_mask = infos.get("_level", np.zeros(self.num_envs, np.bool_))
        for index in indices:
            chosen = self._next[index]
            assert chosen is not None
            level, level_id, trial = chosen
            self._next[index] = None
            self._playing[index] = Episode(int(index), level, level_id, self.steps, trial)
            replayed[index], levels[index] = level_id is not None, level_id
            replayed_mask[index] = level_mask[index] = True
            if self._same_step:  # its reset comes within the step its episode ends in
                self._choose(int(index))
        return {
            **infos,
            "replayed": replayed,
            "_replayed": replayed_mask,
            "level": levels,
            "_level": level_mask,
        }

    def _finish(self, index: int, terminated: bool, last_infos: Mapping[str, Any]) -> None:
        """Sub-environment ``index``'s episode ended: score it, or keep it to be scored."""
        episode = self._playing[index]
        self._playing[index] = None
        if episode is None:
            return
        if (
            _row(last_infos, "server_restarted", index) is not None
            or _row(last_infos, "interrupted", index) is not None
        ):
            self._lost(episode)
            return  # not an outcome of the level
        if self.edit_levels and episode.level_id is not None:
            self._edited[index] = self._remote.clients[0].edit_level(
                episode.level, int(self._rng.integers(_SEEDS)), self.edit_levels
            )
        success = _row(last_infos, "success", index)
        episode.success = (
            bool(success) if success is not None else terminated and episode.reward > 0
        )
        if self.parameters is not None:
            self.parameters.add_episode(episode.reward, progress=self.progress)
        if self.score == "external":
            self.finished.append(episode)
        elif self.score == "learnability":
            self._scores.score_learnability(episode)
        else:
            assert callable(self.score)
            self.update(episode, self.score(episode))

    def _lost(self, episode: Episode) -> None:
        """An episode ended without an outcome: its level on trial, if any, needs another."""
        if episode.trial is not None:
            self._trials.lost(episode.trial)


def _row(infos: Mapping[str, Any], key: str, index: int) -> Any:
    """Sub-environment ``index``'s ``key`` in gymnasium's batched infos, or ``None``."""
    values = infos.get(key)
    if values is None:
        return None
    mask = infos.get(f"_{key}")
    if mask is not None and not mask[index]:
        return None
    return values[index]
