"""The answer of a ``steps`` request: K instances' answers stacked in columns.

Observations are already packed (raw bytes for arrays), so a column of them is their
concatenation, in the packed form of gymnasium's ``batch_space`` of the observation space;
rewards, flags and tick counts become arrays. Neither end handles K maps per step.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector.utils import batch_space, create_empty_array, iterate

from rlenv.protocol import ErrorReply, Response, StepsResponse
from rlenv.protocol.spaces import codec_for

__all__ = ["Columns"]


class Columns:
    """Stacks the answers of a host's instances, in the order of the rows.

    While agents come and go (``some``), a row's answer holds some of the agents: the column
    holds every possible agent, zeros where one is not in the row's answer, and ``due`` says
    where each is.

    Args:
        observation_space: the (joint) observation space of one instance.
        some: whether an answer holds some of the agents of the ``Dict`` space.
    """

    def __init__(self, observation_space: spaces.Space, some: bool = False) -> None:
        self._codec = codec_for(observation_space)
        self._some = some
        # The packed observation of zeros, for the rows of instances that failed.
        zeros = next(
            iter(
                iterate(batch_space(observation_space, 1), create_empty_array(observation_space, 1))
            )
        )
        self._blank = self._codec.pack(zeros)

    def stack(self, reply_id: int, replies: list[Response | ErrorReply]) -> StepsResponse:
        """One steps answer from one answer per instance (an error fails its row alone)."""
        count = len(replies)
        observations: list[Any] = []
        reward = np.zeros(count, np.float64)
        terminated = np.zeros(count, np.bool_)
        truncated = np.zeros(count, np.bool_)
        frames = np.zeros(count, np.int64)
        info: list[dict[str, Any]] = []
        failed = False
        for row, reply in enumerate(replies):
            if reply.__class__ is ErrorReply:
                failed = True
                observations.append(self._blank)
                info.append({})
                continue
            assert isinstance(reply, Response) and reply.observation is not None
            observations.append(
                {**self._blank, **reply.observation["agent"]}
                if self._some
                else reply.observation["agent"]
            )
            reward[row], terminated[row], truncated[row], frames[row] = (
                reply.reward,
                reply.terminated,
                reply.truncated,
                reply.frames,
            )
            info.append(
                reply.info if reply.agents is None else {**reply.info, "agents": reply.agents}
            )
        errors = (
            tuple(reply if reply.__class__ is ErrorReply else None for reply in replies)
            if failed
            else None
        )
        due = None
        if self._some:
            due = {name: np.zeros(count, np.bool_) for name in self._blank}
            for row, reply in enumerate(replies):
                if reply.__class__ is Response:
                    for name in reply.observation["agent"]:  # type: ignore[index]
                        due[name][row] = True
        return StepsResponse(
            reply_id,
            self._codec.join(observations),
            reward,
            terminated,
            truncated,
            frames,
            tuple(info),
            errors,
            due,
        )
