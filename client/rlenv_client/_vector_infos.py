"""A vector's infos batched as gymnasium batches them, in columns where it can.

:class:`BatchedInfos` merges the sub-environments' infos of a
:class:`~rlenv_client.vector.RemoteVectorEnv`'s step or reset into gymnasium's batched form
(each key an array, with its ``_key`` mask), ``frames`` included, without a loop over the
sub-environments in the common cases: no info, and several agents' outcomes alone.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["BatchedInfos"]

AddInfo = Callable[[dict[str, Any], dict[str, Any], int], dict[str, Any]]
"""gymnasium's ``VectorEnv._add_info``: one sub-environment's info added to the batch."""


class BatchedInfos:
    """The batched infos of ``num_envs`` sub-environments (see the module docstring).

    Args:
        add_info: the vector's ``_add_info``, for the infos of other forms.
        num_envs: how many sub-environments.
    """

    def __init__(self, add_info: AddInfo, num_envs: int) -> None:
        self._add_info = add_info
        self._all_envs = np.ones(num_envs, dtype=np.bool_)

    def merge(
        self, infos: dict[str, Any], env_infos: list[dict[str, Any]], frames: np.ndarray
    ) -> dict:
        """Gymnasium's batched infos, ``frames`` included; without a loop in the common cases.

        Those are: no info, and several agents' outcomes alone (``agents``, built in columns).
        """
        if not infos and not any(env_infos):
            return {"frames": frames, "_frames": self._all_envs.copy()}
        if not infos and all(info.keys() == {"agents"} for info in env_infos):
            return {
                "agents": self._agent_columns(env_infos),
                "_agents": self._all_envs.copy(),
                "frames": frames,
                "_frames": self._all_envs.copy(),
            }
        for index, info in enumerate(env_infos):
            infos = self._add_info(infos, {**info, "frames": int(frames[index])}, index)
        return infos

    def _agent_columns(self, env_infos: list[dict[str, Any]]) -> dict[str, Any]:
        """``agents`` batched as gymnasium's ``_add_info`` batches it, a column per outcome.

        When agents come and go, a row holds the agents of its answer only: an agent's columns
        hold 0.0 and false where it is absent, and its masks say where it is present; a joined
        agent's first reward (``None``) is 0.0.
        """
        every = self._all_envs
        first = env_infos[0]["agents"].keys()
        if all(info["agents"].keys() == first for info in env_infos):
            names, present = list(first), None
        else:
            names = list(dict.fromkeys(name for info in env_infos for name in info["agents"]))
            present = {
                name: np.array([name in info["agents"] for info in env_infos], np.bool_)
                for name in names
            }
        columns: dict[str, Any] = {}
        for name in names:
            mask = every if present is None else present[name]
            outcomes = [info["agents"].get(name) for info in env_infos]
            sample = next(outcome for outcome in outcomes if outcome is not None)
            if "joined" in sample:  # a group's: one row per member (protocol 2.7)
                columns[name] = _group_columns(outcomes, sample, mask)
                columns[f"_{name}"] = mask.copy()
                continue
            outcomes = [_ABSENT if outcome is None else outcome for outcome in outcomes]
            columns[name] = {
                "reward": np.array([o["reward"] or 0.0 for o in outcomes], np.float64),
                "_reward": mask.copy(),
                "terminated": np.array([o["terminated"] for o in outcomes], np.bool_),
                "_terminated": mask.copy(),
                "truncated": np.array([o["truncated"] for o in outcomes], np.bool_),
                "_truncated": mask.copy(),
            }
            columns[f"_{name}"] = mask.copy()
        return columns


_ABSENT = {"reward": 0.0, "terminated": False, "truncated": False}
"""The outcome of an agent absent from a row's answer (agents that come and go)."""


def _group_columns(
    outcomes: list[dict[str, Any] | None], sample: dict[str, Any], mask: np.ndarray
) -> dict[str, Any]:
    """A group's outcomes over the rows, each array stacked: ``(rows, members)``.

    A row whose answer does not hold the group has zeros and falses.
    """
    columns: dict[str, Any] = {}
    for key, value in sample.items():
        absent = np.zeros_like(value)
        columns[key] = np.stack([absent if o is None else o[key] for o in outcomes])
        columns[f"_{key}"] = mask.copy()
    return columns
