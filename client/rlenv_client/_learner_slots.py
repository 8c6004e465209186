"""The learners as sub-environments: :class:`~rlenv_client.agent_vector.AgentVectorEnv`'s.

With ``k`` learning agents (not a group: :mod:`rlenv_client._group_slots`), sub-environment
``i * k + j`` is learner ``j`` of instance ``i``. :class:`LearnerSlots` turns the joint answers
of the instances into the vector's rows, and keeps each slot's wait:

- a learner that ends while its instance plays on gives its final transition, then its slot
  waits (its last observation, reward 0, no flag, ``waiting``) until the instance resets; the
  step that resets it ends the wait as truncated, its final info saying ``waiting``;
- where agents come and go, ``is_active`` is whether the slot's agent is in its instance's
  answer, and a slot whose agent is not in play waits for it to join (no episode boundary).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, SupportsIndex

import numpy as np
from gymnasium import spaces
from gymnasium.vector.utils import create_empty_array

from rlenv_client._agents_in_play import slot_mask, with_column
from rlenv_client._group_slots import StepRows
from rlenv_client._rows import row, set_row

__all__ = ["LearnerSlots"]

Columns = tuple[np.ndarray, ...]
"""One agent's ``(reward, terminated, truncated)`` over the instances."""


class LearnerSlots:
    """The ``learners`` of ``instances`` instances, a slot each (see the module).

    Args:
        learners: the learning agents' names, in the environment's order.
        instances: how many instances.
        observation_space: one learner's observation space.
        come_and_go: whether the environment's agents come and go (its hello's
            ``possible_agents``).
        share: an agent's share of a joint value, ``share(joint, name)``.
        add_info: the vector's ``_add_info``, for a slot's final transition.
    """

    def __init__(
        self,
        learners: Sequence[str],
        instances: int,
        observation_space: spaces.Space,
        *,
        come_and_go: bool,
        share: Callable[[Any, str], Any],
        add_info: Callable[[dict[str, Any], dict[str, Any], int], dict[str, Any]],
    ) -> None:
        self.learners = tuple(learners)
        self.instances = instances
        self.num_envs = instances * len(self.learners)
        self.waiting = np.zeros(self.num_envs, np.bool_)
        """The slots that wait, after the last answer."""
        self._space = observation_space
        self._come_and_go = come_and_go
        self._share = share
        self._add_info = add_info
        self._last = create_empty_array(observation_space, self.num_envs)

    def start(
        self, joint: Any, due: Mapping[str, np.ndarray], out: dict[str, Any]
    ) -> tuple[Any, dict[str, Any]]:
        """A reset's observations and infos ``out``: agents not in play yet wait to join.

        ``due``: by agent, whether it is in each instance's answer (agents that come and go).
        """
        observations = self.rows(joint)
        self._last = observations
        self.waiting[:] = False
        if self._come_and_go:
            active = slot_mask(due, self.learners, self.num_envs)
            self.waiting[:] = ~active  # not in play yet: its slot waits for it to join
            out = with_column(out, "is_active", active, self.num_envs)
        return observations, self._with_waiting(out)

    def outcomes(
        self,
        joint_obs: Any,
        columns: Sequence[Columns],
        ended: np.ndarray,
        timed_out: np.ndarray,
        infos: Mapping[str, Any],
        due: Mapping[str, np.ndarray],
        out: dict[str, Any],
    ) -> StepRows:
        """One step's rows, from the joint answer; see the module.

        Args:
            joint_obs: the joint observations (the reset's for the instances that ``ended``).
            columns: each learner's outcome over the instances (its last step's where ended).
            ended: which instances' episodes ended (and were reset) in this step.
            timed_out: which instances reached ``max_episode_steps``.
            infos: the vector's batched infos (``final_obs``, ``final_info``).
            due: as :meth:`start`'s, after this step.
            out: the infos of the rows so far.
        """
        k = len(self.learners)
        rewards = np.zeros(self.num_envs, np.float64)
        terminated = np.zeros(self.num_envs, np.bool_)
        truncated = np.zeros(self.num_envs, np.bool_)
        observations = self.rows(joint_obs)
        instance_ended = np.repeat(ended, k)
        active = None
        if self._come_and_go:
            active = slot_mask(due, self.learners, self.num_envs)
            self.waiting[active & ~instance_ended] = False  # a waiting slot's agent joined
        # a waiting slot whose agent joined in the very step its instance ended: its one row
        waiting = self.waiting & ~self._joined_at_the_end(ended, infos)
        for j, (reward, done_t, done_c) in enumerate(columns):
            span = slice(j, self.num_envs, k)
            was_waiting = waiting[span].copy()
            rewards[span] = np.where(was_waiting, 0.0, reward)
            terminated[span] = done_t & ~was_waiting
            truncated[span] = ((done_c | timed_out | (ended & ~done_t)) & ~was_waiting) | (
                was_waiting & ended
            )
        finished = terminated | truncated
        for index in np.flatnonzero(finished):
            instance = index // k
            name = self.learners[index % k]
            if waiting[index]:
                final_obs, final_info = row(self._last, index), {"waiting": True}
            elif ended[instance]:
                final_obs = self._share(infos["final_obs"][instance], name)
                final_info = _final_info(infos["final_info"], instance, name)
            else:
                final_obs = row(observations, index)
                final_info = {}
            out = self._add_info(
                out,
                {
                    "final_obs": final_obs,
                    "final_info": {**final_info, "agent": name, "instance": int(instance)},
                },
                int(index),
            )
            if not self.waiting[index] and not ended[instance]:
                self.waiting[index] = True  # it waits for its instance to reset
        if active is None:
            self.waiting[instance_ended] = False
            carried = self.waiting & ~finished
        else:  # a new episode's slots wait for their agents, if they do not start
            self.waiting[instance_ended] = ~active[instance_ended]
            carried = (self.waiting | ~active) & ~finished & ~instance_ended
        for index in np.flatnonzero(carried):
            set_row(observations, index, row(self._last, index))
        out = self._with_waiting(out)
        out = with_column(out, "is_active", active, self.num_envs)  # Sample Factory's name
        self._last = observations
        return observations, rewards, terminated, truncated, out

    def rows(self, joint: Any) -> Any:
        """The learners' observations, instance by instance: row ``i * k + j``."""
        k = len(self.learners)
        out = create_empty_array(self._space, self.num_envs)
        for j, name in enumerate(self.learners):
            column = self._share(joint, name)
            for i in range(self.instances):
                set_row(out, i * k + j, row(column, i))
        return out

    # --- internals --------------------------------------------------------------------------

    def _with_waiting(self, out: dict[str, Any]) -> dict[str, Any]:
        """Infos ``out`` with ``waiting`` where a slot waits."""
        if not self.waiting.any():
            return out
        return {**out, "waiting": self.waiting.copy(), "_waiting": self.waiting.copy()}

    def _joined_at_the_end(self, ended: np.ndarray, infos: Mapping[str, Any]) -> np.ndarray:
        """Per slot, whether its agent is in the last answer of its instance's ended episode.

        Only agents that come and go can be there while their slot waits: they joined in that
        very step (its answer holds the agents due and the leavers alone).
        """
        joined = np.zeros(self.num_envs, np.bool_)
        if not (self._come_and_go and ended.any()):
            return joined
        outcomes = infos["final_info"].get("agents", {})
        k = len(self.learners)
        for j, name in enumerate(self.learners):
            present = outcomes.get(f"_{name}")
            if present is not None:
                joined[j::k] = present & ended
        return joined


def _final_info(
    final_info: Mapping[str, Any], instance: SupportsIndex, name: str
) -> dict[str, Any]:
    """The last info of agent ``name`` in ``instance``: the instance's, less the other agents."""
    info: dict[str, Any] = {}
    for key, value in final_info.items():
        if key.startswith("_") or key == "agents":
            continue
        mask = final_info.get(f"_{key}")
        if mask is None or mask[instance]:
            info[key] = value[instance]
    return info
