"""One step of a vector, in columns: what its servers' ``steps`` answers fill in.

:class:`StepColumns` holds a :class:`~rlenv_client.vector.RemoteVectorEnv` step's observations,
rewards, flags, ticks and infos, a row per sub-environment. Each server's answer fills its
sub-environments' rows (:meth:`StepColumns.fill`); the episodes of a lost server, or of every
sub-environment after an interrupted step, end as truncated with their last observation
(:meth:`StepColumns.cut_short`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from rlenv.protocol import StepsResponse
from rlenv.protocol.errors import RemoteError
from rlenv_client._rows import row, set_row, set_rows

__all__ = ["StepColumns"]


class StepColumns:
    """A step's results over ``num_envs`` sub-environments, its rewards and flags 0 until filled.

    Iterating gives ``(observations, rewards, terminations, truncations, frames, env_infos)``.

    Args:
        observations: the batch the observations are written into (every row is, by
            :meth:`fill` or :meth:`cut_short`).
        num_envs: how many sub-environments.
        due: while agents come and go, each possible agent's column of whether it is in the
            row's answer (false until filled); ``None`` otherwise.
    """

    __slots__ = (
        "due",
        "env_infos",
        "frames",
        "observations",
        "rewards",
        "terminations",
        "truncations",
    )

    def __init__(self, observations: Any, num_envs: int, due: Sequence[str] | None = None) -> None:
        self.observations = observations
        self.due: dict[str, np.ndarray] | None = (
            None if due is None else {name: np.zeros(num_envs, np.bool_) for name in due}
        )
        self.rewards = np.zeros(num_envs, np.float64)
        self.terminations = np.zeros(num_envs, np.bool_)
        self.truncations = np.zeros(num_envs, np.bool_)
        self.frames = np.zeros(num_envs, np.int64)
        self.env_infos: list[dict[str, Any]] = [{}] * num_envs

    def __iter__(self) -> Iterator[Any]:
        return iter(
            (
                self.observations,
                self.rewards,
                self.terminations,
                self.truncations,
                self.frames,
                self.env_infos,
            )
        )

    def fill(self, group: range, answer: StepsResponse) -> RemoteError | None:
        """Write a server's answer in the rows of its sub-environments, ``group``.

        Returns:
            The first refusal among its instances' (in ``errors``), or ``None``.
        """
        span = slice(group.start, group.stop)
        set_rows(self.observations, group.start, answer.observation)
        self.rewards[span], self.terminations[span] = answer.reward, answer.terminated
        self.truncations[span], self.frames[span] = answer.truncated, answer.frames
        self.env_infos[span] = answer.info
        if self.due is not None and answer.due is not None:
            for name, column in self.due.items():
                column[span] = answer.due[name]
        for refused in answer.errors or ():
            if refused is not None:
                return RemoteError(refused.code, refused.message, refused.fatal)
        return None

    def cut_short(self, indices: Iterable[int], last: Any, info: Mapping[str, Any]) -> None:
        """End the episodes of ``indices`` as truncated, with their row of ``last`` and ``info``."""
        for index in indices:
            set_row(self.observations, index, row(last, index))
            self.truncations[index] = True
            self.env_infos[index] = dict(info)
            for column in (self.due or {}).values():
                column[index] = False
