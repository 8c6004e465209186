"""The lean path of a ``steps`` request: K instances stepped straight into columns.

The general path serves each instance's share of a ``steps`` request as any request (its plan
through the environment's hooks, an answer of its own), then :class:`~rlenv.serving._columns.
Columns` stacks the K answers. When nothing can tell the difference, :class:`LeanSteps` does the
same work without the K answers: each instance acts (or resets) through the same primitives,
its agent's observation is written into one preallocated column, the column is checked for NaN
and infinity once, and rewards, flags and tick counts go straight into their arrays.

It serves a host when every instance has one agent whose observation space packs as raw bytes
(Box, MultiDiscrete, MultiBinary) and whose environment overrides neither
``_on_got_connection`` nor ``_send_response`` (the hooks the general path calls per request),
and while no instance runs in real time. Everything an instance does is as on the general path,
and so is every answer (``tests/test_lean_steps.py`` compares them bit for bit, failures
included).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from gymnasium import spaces

from rlenv.environment import RLEnvironment
from rlenv.protocol import ErrorReply, StepsResponse
from rlenv.protocol.spaces import codec_for
from rlenv.serving._instance import Instance
from rlenv.serving._observing import non_finite_observation, packed_observation

if TYPE_CHECKING:
    from rlenv.serving._parts import StepsPlan

__all__ = ["LeanSteps"]

_AGENT_ONLY: Mapping[str, Any] = {"agent": {}}
_EMPTY: dict[str, Any] = {}
_PACKED_AS_BYTES = (spaces.Box, spaces.MultiDiscrete, spaces.MultiBinary)


class LeanSteps:
    """Steps a host's instances in columns (see the module docstring).

    Args:
        instances: the host's instances, in the order of the rows.
    """

    def __init__(self, instances: Sequence[Instance]) -> None:
        self.instances = list(instances)
        space = instances[0].observation_space
        # A space packed as raw bytes (the module docstring): its shape and dtype are fixed.
        self.shape = cast(tuple[int, ...], space.shape)
        self.dtype = cast(np.dtype, space.dtype)
        self._codec = codec_for(space)
        self._column = np.zeros((len(instances), *self.shape), self.dtype)
        self._floats = self.dtype.kind in "fc"
        self._narrow = self.dtype.kind == "f" and self.dtype.itemsize <= 4
        self._infos = [
            type(i.environment)._get_info is not RLEnvironment._get_info for i in instances
        ]

    @staticmethod
    def serves(instances: Sequence[Instance]) -> bool:
        """Whether the lean path can serve these instances (in lockstep)."""
        return all(
            not instance.multi_agent
            and not instance.dispatches_itself
            and not instance.responds_itself
            and isinstance(instance.observation_space, _PACKED_AS_BYTES)
            for instance in instances
        )

    def run(self, reply_id: int, plan: StepsPlan) -> StepsResponse:
        """Serve every instance its row of the checked plan (an action, or a reset); the answer."""
        count = len(plan.resets)
        column, dtype, shape = self._column, self.dtype, self.shape
        data: list[Any] = [None] * count
        acted = [False] * count
        errors: list[ErrorReply | None] | None = None
        rebuilt: list[dict[str, Any] | None] | None = None  # rows rebuilt before their reset
        repeat = plan.repeat
        for row, (instance, action, resets) in enumerate(
            zip(self.instances, plan.actions, plan.resets, strict=True)
        ):
            try:
                if resets:
                    if instance.broken is not None:
                        rebuilt = rebuilt or [None] * count
                        rebuilt[row] = {"rebuilt": instance.rebuild()}
                    instance.begin_episode(None, {})  # its own: user code may keep it
                else:
                    instance.act(action, repeat or instance.environment.repeat_action)
                    acted[row] = True
                agent = instance.agents[0]
                value = data[row] = agent.get_data(_AGENT_ONLY)
                if (
                    value.__class__ is np.ndarray
                    and (value.dtype is dtype or value.dtype == dtype)
                    and value.shape == shape
                ):
                    column[row] = value
                else:  # the general path's conversion and refusals
                    packed = packed_observation(agent, self._codec, _AGENT_ONLY)
                    column[row] = np.frombuffer(packed, dtype).reshape(shape)
            except Exception as error:  # user code raised: this row fails alone
                errors = errors or [None] * count
                errors[row] = instance.environment_error(reply_id, error)
                column[row] = 0
        if self._floats:
            errors = self._refuse_non_finite(reply_id, column, data, errors)
        reward = [0.0] * count
        terminated = [False] * count
        truncated = [False] * count
        frames = [0] * count
        infos: list[dict[str, Any]] = [_EMPTY] * count
        for row, (instance, has_info) in enumerate(zip(self.instances, self._infos, strict=True)):
            if errors is not None and errors[row] is not None:
                continue
            try:
                reward[row], terminated[row], truncated[row], frames[row], _ = instance.report(
                    True, acted[row]
                )
                extra = None if rebuilt is None else rebuilt[row]
                if has_info or extra is not None:
                    infos[row] = instance.info(acted[row], extra)
            except Exception as error:  # _get_info raised, or holds what cannot travel
                errors = errors or [None] * count
                errors[row] = instance.environment_error(reply_id, error)
                column[row] = 0
                reward[row], terminated[row], truncated[row], frames[row] = 0.0, False, False, 0
        return StepsResponse(
            reply_id,
            column.tobytes(),
            np.array(reward, np.float64),
            np.array(terminated, np.bool_),
            np.array(truncated, np.bool_),
            np.array(frames, np.int64),
            tuple(infos),
            None if errors is None else tuple(errors),
        )

    def _refuse_non_finite(
        self,
        reply_id: int,
        column: np.ndarray,
        data: list[Any],
        errors: list[ErrorReply | None] | None,
    ) -> list[ErrorReply | None] | None:
        """Fail the rows whose observation holds NaN or infinity, as the general path does."""
        total = column.sum(dtype=np.float64) if self._narrow else None
        if total is not None and np.isfinite(total):
            return errors
        rows = np.isfinite(column.reshape(len(column), -1)).all(axis=1)
        for row in np.flatnonzero(~rows):
            instance = self.instances[row]
            if errors is not None and errors[row] is not None:
                continue
            agent = instance.agents[0]
            # Where, in what get_data gave; in the row as written if that is finite by now (an
            # array the environment reuses, changed by a later row's get_data).
            error = (
                non_finite_observation(agent, data[row])
                or non_finite_observation(agent, column[row].copy())
                or FloatingPointError(f"the observation of {agent.get_path()} is not finite")
            )
            errors = errors or [None] * len(column)
            errors[row] = instance.environment_error(reply_id, error)
            column[row] = 0
        return errors
