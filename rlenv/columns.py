"""A multi-instance server's vector step in columns (see :class:`rlenv.protocol.Steps`).

One ``steps`` request carries every instance's action stacked in one array (gymnasium's
``batch_space`` layout); every instance resets or steps, in its own tree; the answer stacks the
observations and gathers rewards, flags and tick counts into arrays. Neither end builds K
requests or K responses per vector step, and the action batch is checked in one go against
the batched action space.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array, iterate

from rlenv.environment import Outcome, non_finite_error
from rlenv.errors import ErrorCode, RequestError
from rlenv.instance import Instance
from rlenv.protocol import ErrorReply, Request, StepsResponse
from rlenv.spaces import SpaceMismatch, check, find_non_finite

__all__ = ["ColumnStepper"]


class ColumnStepper:
    """Answers ``steps`` requests for a fixed list of instances of one environment class.

    Args:
        instances: the instances, in the order of the rows.
    """

    def __init__(self, instances: list[Instance]) -> None:
        self.instances = instances
        hello = instances[0].hello
        self.count = len(instances)
        self.observation_space = hello.observation_space
        self.batched_actions = batch_space(hello.action_space, self.count)
        # One observation of zeros, for the rows of instances that failed.
        self._blank = next(iter(iterate(batch_space(hello.observation_space, 1),
                                        create_empty_array(hello.observation_space, 1))))
        # A float Box observation is checked for NaN and infinity once for all instances.
        self._float_box = isinstance(hello.observation_space, spaces.Box) and \
            hello.observation_space.dtype.kind == "f"

    def answer(self, request: Request) -> StepsResponse | ErrorReply:
        """Check the whole request, then reset or step every instance; answer in columns.

        A refused request (a reset mask of the wrong length, an action outside the space, an
        instance whose episode has not started or has ended) changes nothing. An exception in
        user code fails that instance alone (its entry in ``errors``).
        """
        steps = request.steps
        assert steps is not None
        for instance in self.instances:
            if instance.tree.real_time:  # the ticks due by the clock first, as for a request
                instance.tree.iteration()
        reset = np.zeros(self.count, np.bool_) if steps.reset is None else steps.reset
        if len(reset) != self.count:
            return ErrorReply(request.id, ErrorCode.BAD_REQUEST, f"steps.reset has "
                              f"{len(reset)} flags for {self.count} instances")
        try:
            actions = self._check(steps.action, reset)
        except RequestError as error:
            return ErrorReply(request.id, error.code, str(error))
        replies = [instance.environment.answer_part(request, action, bool(resets),
                                                    check_observation=not self._float_box)
                   for instance, action, resets in zip(self.instances, actions, reset,
                                                       strict=True)]
        return self._columns(request.id, replies)

    def _check(self, action: Any, reset: np.ndarray) -> list[Any]:
        """One action per instance, all checked at once (resetting instances' too, ignored).

        The batched space fixes the shape of every leaf, so no row can be missing or ragged.
        """
        for index, instance in enumerate(self.instances):
            if not reset[index]:
                try:
                    instance.environment.check_can_act()
                except RequestError as error:
                    raise RequestError(error.code, f"steps: instance {index}: {error}") from None
        try:  # the batched space fixes every leaf's shape, so rows cannot be ragged
            checked = check(self.batched_actions, action, "steps.action")
        except SpaceMismatch as error:
            raise RequestError(ErrorCode.INVALID_ACTION, str(error)) from None
        return list(checked) if isinstance(checked, np.ndarray) else \
            list(iterate(self.batched_actions, checked))

    def _columns(self, request_id: int, replies: list[Outcome | ErrorReply]) -> StepsResponse:
        answered = [_FAILED if reply.__class__ is ErrorReply else reply for reply in replies]
        observations = [self._blank if reply is _FAILED else reply.observation["agent"]
                        for reply in answered]
        stacked = concatenate(self.observation_space, observations,
                              create_empty_array(self.observation_space, self.count))
        if self._float_box and not np.isfinite(stacked.sum(dtype=np.float64)):
            for index in np.flatnonzero(~np.isfinite(stacked.reshape(self.count, -1)).all(1)):
                environment = self.instances[index].environment
                row = stacked[index]  # in the space's dtype, as it would travel
                assert environment.agent is not None
                replies[index] = environment.environment_error(request_id, non_finite_error(
                    environment.agent, row, find_non_finite(row) or ""))
                answered[index] = _FAILED
                stacked[index] = self._blank
        failed = sum(reply is _FAILED for reply in answered)
        return StepsResponse(
            id=request_id,
            observation=stacked,
            reward=np.array([reply.reward for reply in answered], np.float64),
            terminated=np.array([reply.terminated for reply in answered], np.bool_),
            truncated=np.array([reply.truncated for reply in answered], np.bool_),
            frames=np.array([reply.frames for reply in answered], np.int64),
            info=tuple(_info(reply) for reply in answered),
            errors=tuple(reply if reply.__class__ is ErrorReply else None for reply in replies)
            if failed else None,
        )


_FAILED = Outcome(None, 0.0, False, False, {}, 0, None)


def _info(outcome: Outcome) -> dict[str, Any]:
    if outcome.agents is None:
        return outcome.info
    return {**outcome.info, "agents": outcome.agents}
