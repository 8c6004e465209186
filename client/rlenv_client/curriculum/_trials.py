"""New levels on trial (SFL): each played ``rollouts_per_level`` times before it is scored.

:class:`Trials` is the :class:`~rlenv_client.curriculum.CurriculumVectorEnv`'s book of the new
levels on trial: which one waits for a rollout (the oldest first), how many of its episodes are
under way, and its results until it has them all. With ``rollouts_per_level=1`` no level goes on
trial: one episode decides.
"""

from __future__ import annotations

from collections.abc import ItemsView

from rlenv_client.curriculum.levels import Level

__all__ = ["Trial", "Trials"]


class Trial:
    """A new level on trial: its results so far, and how many of its episodes are under way."""

    __slots__ = ("level", "results", "under_way")

    def __init__(self, level: Level) -> None:
        self.level = level
        self.results: list[float] = []
        self.under_way = 0  # episodes chosen or playing, not finished yet


class Trials:
    """The levels on trial by number, oldest first.

    Args:
        rollouts_per_level: how many episodes decide a new level's score.
    """

    def __init__(self, rollouts_per_level: int) -> None:
        self.rollouts_per_level = rollouts_per_level
        self._trials: dict[int, Trial] = {}
        self._count = 0

    def __len__(self) -> int:
        return len(self._trials)

    def items(self) -> ItemsView[int, Trial]:
        """``(number, trial)`` of each level on trial, oldest first."""
        return self._trials.items()

    def level(self, number: int) -> Level:
        """The level of trial ``number``."""
        return self._trials[number].level

    def start(self, level: Level) -> int | None:
        """The number of a new trial of ``level``; ``None`` when one rollout decides."""
        if self.rollouts_per_level == 1:
            return None
        self._count += 1
        self._trials[self._count] = Trial(level)
        return self._count

    def waiting(self) -> int | None:
        """The oldest level on trial that needs an episode more than are under way."""
        for number, trial in self._trials.items():
            if len(trial.results) + trial.under_way < self.rollouts_per_level:
                return number
        return None

    def chosen(self, number: int) -> None:
        """An episode of trial ``number`` is chosen: it is under way until it ends."""
        self._trials[number].under_way += 1

    def done(self, number: int, result: float) -> list[float] | None:
        """Add an episode's result; the trial's results once it has them all (it ends)."""
        trial = self._trials[number]
        trial.under_way -= 1
        trial.results.append(result)
        if len(trial.results) < self.rollouts_per_level:
            return None
        del self._trials[number]
        return trial.results

    def lost(self, number: int) -> None:
        """An episode of trial ``number`` ended without an outcome: the level needs another."""
        self._trials[number].under_way -= 1
