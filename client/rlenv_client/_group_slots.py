"""A group's members as sub-environments: :class:`~rlenv_client.agent_vector.AgentVectorEnv`'s.

With ``agents=GROUP`` (an :class:`~rlenv.agent_group.RLAgentGroup`, protocol 2.7), each member
of each of the ``K`` instances is one sub-environment: sub-environment ``i * N + m`` is member
``m`` of instance ``i``. :class:`GroupSlots` turns the group's arrays into the vector's rows
with numpy alone (reshapes and masks, no loop over members):

- the actions ``(K * N, *act)`` are the group's column ``(K, N, *act)``, reshaped;
- a member in play observes its row; a member that ends gives its slot's final transition
  (``terminated`` or ``truncated``, its row as ``final_obs``) once, then its slot is out of
  play: zeros, reward 0, no flag, ``is_active`` false, ``waiting``, until its instance resets;
- a member that joins turns its slot active with its first observation (reward 0), with no
  episode boundary;
- when the instance's episode ends, every member in its last answer ends too (truncated unless
  it terminated), and every waiting slot's wait ends as truncated, its final info saying
  ``waiting`` (no episode to count); the reset starts them all at once;
- where the group does not decide (its decision period), its slots keep their observation.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv_client._rows import repeat_rows

__all__ = ["GroupSlots", "StepRows"]

StepRows = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]
"""A vector step's ``(observations, rewards, terminated, truncated, infos)``."""

_FLAGS = ("reward", "terminated", "truncated", "active")


class GroupSlots:
    """The members of group ``name`` of ``instances`` instances, a slot each.

    Args:
        name: the group's agent name.
        instances: how many instances (``K``).
        count: the group's ``instance_count`` (``N``).
        observation_space: one member's observation space.
    """

    def __init__(
        self, name: str, instances: int, count: int, observation_space: spaces.Space
    ) -> None:
        self.name, self.instances, self.count = name, instances, count
        self.num_envs = instances * count
        self._shape = tuple(observation_space.shape or ())
        self._in_play = np.zeros(self.num_envs, np.bool_)  # after the last answer
        self._last = np.zeros((self.num_envs, *self._shape), observation_space.dtype)
        self._instance = np.repeat(np.arange(instances), count)
        self._member = np.tile(np.arange(count), instances)

    def action(self, actions: Any, column: np.ndarray) -> np.ndarray:
        """The group's column of a joint action: ``actions`` reshaped, as ``column``'s dtype."""
        return np.asarray(actions, column.dtype).reshape(column.shape)

    def start(self, joint: Mapping[str, Any], infos: Mapping[str, Any]) -> tuple[np.ndarray, ...]:
        """A reset's ``(observations, is_active)``: the members that start are in play."""
        observations = self._rows(joint)
        starting = self._starting_rows(infos, np.ones(self.instances, np.bool_))
        self._in_play = starting.copy()
        self._last = observations
        return observations, starting

    def outcomes(
        self, joint: Mapping[str, Any], ended: np.ndarray, infos: Mapping[str, Any]
    ) -> tuple[StepRows, np.ndarray]:
        """One step's rows and ``is_active``, from the joint answer; see the module.

        Args:
            joint: the joint observations (the reset's for the instances that ``ended``).
            ended: which instances' episodes ended (and were reset) in this step.
            infos: the vector's batched infos (``agents``, ``final_obs``, ``final_info``).
        """
        count, in_play = self.count, self._in_play
        reward, terminated, truncated, active = self._outcome(ended, infos)
        over = np.repeat(ended, count)
        decided = np.repeat(self._decided(infos), count) | over
        terminated &= active
        truncated = active & (truncated | (over & ~terminated))
        waited = over & ~active & ~in_play  # slots out of play: their wait ends
        cut = over & ~active & in_play  # in play, not deciding at the end: cut there
        truncated |= waited | cut
        finished = terminated | truncated
        observations = self._rows(joint)
        out: dict[str, Any] = {}
        if finished.any():  # before the rows of those that left are zeroed
            final_rows = self._final_rows(observations, ended, infos, waited | cut)
            out = self._finals(final_rows, finished, waited, ended, infos)
        left = finished & ~over
        if left.any():
            observations[left] = 0  # out of play until the instance resets
        kept = ~decided & in_play
        if kept.any():
            observations[kept] = self._last[kept]
        starting = self._starting_rows(infos, ended)
        self._in_play = np.where(over, starting, np.where(decided, active & ~finished, in_play))
        self._last = observations
        is_active = np.where(over, starting, active)
        rows = (observations, np.where(active, reward, 0.0), terminated, truncated, out)
        return rows, is_active

    @property
    def waiting(self) -> np.ndarray:
        """The slots whose member is out of play after the last answer."""
        return ~self._in_play

    # --- internals --------------------------------------------------------------------------

    def _rows(self, joint: Mapping[str, Any]) -> np.ndarray:
        """The group's observations ``(K, N, *obs)`` as the vector's rows ``(K * N, *obs)``."""
        return np.asarray(joint[self.name]).reshape(self.num_envs, *self._shape)

    def _outcome(self, ended: np.ndarray, infos: Mapping[str, Any]) -> list[np.ndarray]:
        """The group's ``reward``, ``terminated``, ``truncated`` and ``active`` per slot.

        Those of the last answer of the instances that ended (their ``final_info``).
        """
        step = (infos.get("agents") or {}).get(self.name)
        final = (infos.get("final_info", {}).get("agents") or {}).get(self.name)
        shape = (self.instances, self.count)
        columns: list[np.ndarray] = []
        for key in _FLAGS:
            now = step[key] if step is not None else np.zeros(shape)
            if final is not None and ended.any():
                now = np.where(ended[:, None], final[key], now)
            columns.append(np.asarray(now, np.float64 if key == "reward" else np.bool_))
        return [column.reshape(-1) for column in columns]

    def _decided(self, infos: Mapping[str, Any]) -> np.ndarray:
        """Per instance, whether the group is in its answer (it decides now)."""
        due = (infos.get("due") or {}).get(self.name)
        return np.ones(self.instances, np.bool_) if due is None else np.asarray(due, np.bool_)

    def _starting_rows(self, infos: Mapping[str, Any], starts: np.ndarray) -> np.ndarray:
        """Per slot, whether its member is in play at its instance's reset (``starts``' rows).

        The reset's answer says it (its group outcome's ``active``); where it does not, every
        member starts.
        """
        rows = np.repeat(starts, self.count)
        agents = infos.get("agents") or {}
        outcome, said = agents.get(self.name), agents.get(f"_{self.name}")
        if outcome is None or said is None:
            return rows
        active = np.asarray(outcome["active"], np.bool_).reshape(-1)
        return rows & np.where(np.repeat(said, self.count), active, True)

    def _final_rows(
        self,
        observations: np.ndarray,
        ended: np.ndarray,
        infos: Mapping[str, Any],
        last: np.ndarray,
    ) -> np.ndarray:
        """Each slot's final observation, should it end now.

        The answer's row; the episode's last, of an instance that ended; or the slot's last
        observation, where ``last`` (its member is not in that answer).
        """
        final = observations.copy()
        if ended.any():
            shaped = final.reshape(self.instances, self.count, *self._shape)
            for instance in np.flatnonzero(ended):
                shaped[instance] = infos["final_obs"][instance][self.name]
        if last.any():
            final[last] = self._last[last]
        return final

    def _finals(
        self,
        final_rows: np.ndarray,
        finished: np.ndarray,
        waited: np.ndarray,
        ended: np.ndarray,
        infos: Mapping[str, Any],
    ) -> dict[str, Any]:
        """``final_obs`` and ``final_info`` of the slots that end, as gymnasium batches them."""
        final_obs = np.full(self.num_envs, None, dtype=object)
        for index in np.flatnonzero(finished):
            final_obs[index] = final_rows[index]
        agent = np.full(self.num_envs, None, dtype=object)
        agent[finished] = self.name
        final_info: dict[str, Any] = {
            "agent": agent,
            "_agent": finished.copy(),
            "instance": self._instance.copy(),
            "_instance": finished.copy(),
            "member": self._member.copy(),
            "_member": finished.copy(),
        }
        if waited.any():
            final_info["waiting"], final_info["_waiting"] = waited.copy(), waited.copy()
        if ended.any():  # the instance's last info, to the slots of its members
            episode = infos["final_info"]
            reported = finished & ~waited
            for key, value in episode.items():
                if key.startswith("_") or key == "agents":
                    continue
                mask = np.repeat(np.asarray(episode[f"_{key}"], np.bool_), self.count)
                final_info[key] = repeat_rows(value, self.count)
                final_info[f"_{key}"] = mask & reported
        return {
            "final_obs": final_obs,
            "_final_obs": finished.copy(),
            "final_info": final_info,
            "_final_info": finished.copy(),
        }
