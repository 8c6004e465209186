"""A curriculum's level scores: finished episodes scored into the level buffer.

:class:`LevelScores` is what a :class:`~rlenv_client.curriculum.CurriculumVectorEnv` holds to
turn a finished :class:`~rlenv_client.curriculum.Episode` into a score of its level: a new
level is offered to the :class:`~rlenv_client.curriculum.LevelSampler` (after its trial, if it
is on one), a replayed level's score is updated. It keeps what the scores need between
episodes (each buffered level's outcomes for learnability, its best return for ``max_mc``),
and forgets it when the level leaves the buffer.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING

import numpy as np

from rlenv_client.curriculum._trials import Trials
from rlenv_client.curriculum.levels import Level
from rlenv_client.curriculum.sampler import LevelSampler
from rlenv_client.curriculum.scores import learnability, max_mc, positive_value_loss

if TYPE_CHECKING:
    from rlenv_client.curriculum.vector import Episode

__all__ = ["LevelScores"]


class LevelScores:
    """The scores of the levels that ``sampler`` buffers and ``trials`` has on trial.

    Args:
        sampler: the level buffer scores go to.
        trials: the levels on trial, scored over their rollouts.
        outcomes_kept: how many outcomes per level learnability counts (the latest).
    """

    def __init__(self, sampler: LevelSampler, trials: Trials, outcomes_kept: int) -> None:
        self._sampler = sampler
        self._trials = trials
        self._outcomes: dict[int, deque[float]] = {}
        self._outcomes_kept = outcomes_kept
        self._max_returns: dict[int, float] = {}

    def update(self, episode: Episode, score: float) -> int | None:
        """Score a finished episode's level (see ``CurriculumVectorEnv.update``)."""
        if episode.trial is not None:
            results = self._trials.done(episode.trial, float(score))
            return None if results is None else self._offer(episode.level, float(np.mean(results)))
        if episode.level_id is None:
            return self._offer(episode.level, score)
        try:
            self._sampler.update(episode.level_id, score)
        except KeyError:
            return None
        return episode.level_id

    def score_learnability(self, episode: Episode) -> None:
        """Score ``episode``'s level with learnability over its outcomes, this one's with them."""
        if episode.trial is not None:
            results = self._trials.done(episode.trial, float(episode.success))
            if results is not None:
                level_id = self._offer(episode.level, learnability(results))
                if level_id is not None:
                    self._outcomes[level_id] = deque(results, maxlen=self._outcomes_kept)
            return
        outcomes = self._outcomes.get(episode.level_id) if episode.level_id is not None else None
        if outcomes is None:
            outcomes = deque(maxlen=self._outcomes_kept)
        outcomes.append(float(episode.success))
        level_id = self.update(episode, learnability(outcomes))
        if level_id is not None:
            self._outcomes[level_id] = outcomes

    def score_rollout(
        self, episode: Episode, score: str, advantages: np.ndarray, values: np.ndarray
    ) -> None:
        """Score ``episode``'s level from the trainer's estimates of its steps in a rollout.

        Args:
            episode: a finished episode.
            score: ``"positive_value_loss"`` or ``"max_mc"``.
            advantages: the GAE advantages of its steps in the rollout.
            values: the value estimates of those steps.
        """
        if score == "positive_value_loss":
            self.update(episode, positive_value_loss(advantages))
            return
        best = (
            max(self._max_returns.get(episode.level_id, -np.inf), episode.reward)
            if episode.level_id is not None
            else episode.reward
        )
        level_id = self.update(episode, max_mc(best, values))
        if level_id is not None:
            self._max_returns[level_id] = best

    def _offer(self, level: Level, score: float) -> int | None:
        """Insert a new level; forget what is kept of a level it evicts."""
        level_id = self._sampler.insert(level, score)
        if level_id is not None and len(self._sampler) == self._sampler.capacity:
            self._forget_evicted()
        return level_id

    def _forget_evicted(self) -> None:
        """Drop what is kept of levels no longer in the buffer (one may just have left)."""
        buffered = self._sampler.weights()
        self._outcomes = {key: value for key, value in self._outcomes.items() if key in buffered}
        self._max_returns = {
            key: value for key, value in self._max_returns.items() if key in buffered
        }
