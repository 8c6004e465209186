"""The trainer's agents in play, for environments whose agents come and go (issue 42).

An answer of such an environment (the hello's ``possible_agents`` is not ``None``) holds only
the agents due at it, and those that left in the step it answers, once; a joined agent's first
reward is ``None``. :class:`AgentsInPlay` follows the trainer's agents (a
:class:`~rlenv_client.trainer_view.TrainerView`'s) through the answers and turns each into a
:class:`Turn`: entries for every agent in play, the agents not in the answer keeping their
last observation with reward 0 and flags false. The PettingZoo, RLlib and gymnasium adaptors
each read the part their convention needs.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector.utils import create_empty_array, iterate

from rlenv_client.trainer_view import TrainerView

__all__ = [
    "AgentSlots",
    "AgentsInPlay",
    "Turn",
    "answer_reward",
    "as_one",
    "due_columns",
    "slot_mask",
    "with_column",
]


@dataclass(frozen=True)
class Turn:
    """What one answer says of the trainer's agents, in the hello's order.

    Attributes:
        agents: the agents in play before the answer, and those that joined in it.
        due: the agents that decide now (in the answer and still in play).
        left: the agents whose episode ended in this answer (theirs, a time limit's, or the
            episode's end).
        observations: each of ``agents``' latest observation.
        rewards: each of ``agents``' reward in this answer (0.0 when not in it, or joined).
        terminated: each of ``agents``' flag.
        truncated: each of ``agents``' flag.
    """

    agents: tuple[str, ...]
    due: tuple[str, ...]
    left: tuple[str, ...]
    observations: dict[str, Any]
    rewards: dict[str, float]
    terminated: dict[str, bool]
    truncated: dict[str, bool]


class AgentSlots:
    """A fixed slot per trainer agent: an observation with an entry for each, zeros if absent.

    Args:
        view: the agents the trainer acts for, and their spaces.
    """

    def __init__(self, view: TrainerView) -> None:
        self.names = view.agents
        self._zeros = {name: _zeros(space) for name, space in view.agent_spaces()[1].items()}

    def fill(self, observation: Mapping[str, Any]) -> dict[str, Any]:
        """Every trainer agent's entry of ``observation``, zeros where it has none."""
        return {
            name: observation[name] if name in observation else copy.deepcopy(zeros)
            for name, zeros in self._zeros.items()
        }


class AgentsInPlay:
    """The trainer's agents in play, through the answers of one episode after another.

    Args:
        view: the agents the trainer acts for, and their spaces.

    Attributes:
        agents: the agents in play after the last answer, in the hello's order.
        due: the agents that decide at the last answer: an action needs entries for them only.
    """

    def __init__(self, view: TrainerView) -> None:
        self._view = view
        self._names = view.agents
        self._slots = AgentSlots(view)
        self.agents: tuple[str, ...] = ()
        self.due: tuple[str, ...] = ()
        self._last: dict[str, Any] = {}

    @property
    def names(self) -> tuple[str, ...]:
        """Every agent the trainer may see (PettingZoo's and RLlib's ``possible_agents``)."""
        return self._names

    def agent_spaces(self) -> tuple[dict[str, spaces.Space], dict[str, spaces.Space]]:
        """Each agent's action and observation space, by name."""
        return self._view.agent_spaces()

    def start(self, observation: Mapping[str, Any], info: Mapping[str, Any] | None = None) -> Turn:
        """The reset's answer (and its ``info``): its agents start (each due)."""
        self.agents, self.due, self._last = (), (), {}
        return self.answer(observation, info or {})

    def answer(
        self, observation: Mapping[str, Any], info: Mapping[str, Any], *, ended: bool = False
    ) -> Turn:
        """Take one step's answer; ``ended``: the episode ended (every agent left is cut).

        ``info["agents"]`` gives the answer's rewards and flags (a reset's has none).
        """
        outcomes = info.get("agents") or {}
        agents = tuple(name for name in self._names if name in self.agents or name in observation)
        rewards, terminated, truncated = {}, {}, {}
        for name in agents:
            outcome = outcomes.get(name, {}) if name in observation else {}
            if "joined" in outcome:  # a group's, here one agent (members: MembersInPlay)
                outcome = dict(
                    zip(("reward", "terminated", "truncated"), as_one(outcome), strict=True)
                )
            reward = outcome.get("reward")
            rewards[name] = 0.0 if reward is None else float(reward)
            terminated[name] = bool(outcome.get("terminated", False))
            truncated[name] = bool(outcome.get("truncated", False)) or (
                ended and not terminated[name]
            )
            if name in observation:
                self._last[name] = observation[name]
        left = tuple(name for name in agents if terminated[name] or truncated[name])
        self.agents = tuple(name for name in agents if name not in left)
        self.due = tuple(name for name in self.agents if name in observation)
        return Turn(
            agents, self.due, left, {name: self._last[name] for name in agents}, rewards,
            terminated, truncated,
        )  # fmt: skip

    def action(self, actions: Mapping[str, Any]) -> dict[str, Any]:
        """The entries of ``actions`` for the agents due: the others are never sent."""
        return {name: actions[name] for name in self.due if name in actions}

    def full_observation(self, observation: Mapping[str, Any]) -> dict[str, Any]:
        """Every trainer agent's entry of ``observation``, zeros where it has none."""
        return self._slots.fill(observation)


def answer_reward(info: Mapping[str, Any], names: tuple[str, ...]) -> float:
    """The sum of ``names``' rewards in the answer's ``info["agents"]`` (``None``: 0).

    A group's reward is an array over its members (protocol 2.7): its sum counts.
    """
    outcomes = info.get("agents") or {}
    rewards = (outcomes[name]["reward"] for name in names if name in outcomes)
    return float(sum(0.0 if reward is None else np.sum(reward) for reward in rewards))


def as_one(outcome: Mapping[str, Any]) -> tuple[Any, Any, Any]:
    """A group's outcome (arrays over its members, last axis) as one agent's.

    Its members' rewards summed; ended where no member is left in play, terminated if one
    of those ending now terminated (the server's joint end counts the group as one agent).
    """
    ending = outcome["terminated"] | outcome["truncated"]
    over = ~(outcome["active"] & ~ending).any(axis=-1)
    terminated = over & outcome["terminated"].any(axis=-1)
    return outcome["reward"].sum(axis=-1), terminated, over & ~terminated


def due_columns(slots: AgentSlots | None, count: int) -> dict[str, np.ndarray] | None:
    """Per slot, a column of ``count`` falses: whether its agent is in each row's answer.

    ``None`` without slots (no agents come and go).
    """
    if slots is None:
        return None
    return {name: np.zeros(count, np.bool_) for name in slots.names}


def slot_mask(due: Mapping[str, np.ndarray], learners: Sequence[str], count: int) -> np.ndarray:
    """Whether each of ``count`` sub-environments' agent is in its answer.

    Row ``i * k + j`` is learner ``j`` of instance ``i``; ``due`` has a column over the
    instances per agent.
    """
    k = len(learners)
    active = np.zeros(count, np.bool_)
    for j, name in enumerate(learners):
        active[j::k] = due[name]
    return active


def with_column(infos: dict[str, Any], key: str, value: Any, count: int) -> dict[str, Any]:
    """Batched ``infos`` with ``key`` set in every one of ``count`` rows (``None``: unchanged)."""
    if value is None:
        return infos
    return {**infos, key: value, f"_{key}": np.ones(count, np.bool_)}


def _zeros(space: spaces.Space) -> Any:
    """A member of ``space``'s shape and dtype, all zeros."""
    return next(iter(iterate(space, create_empty_array(space, 1, fn=np.zeros))))
