"""Each agent's life in a replayed episode where agents come and go: its own transitions.

Where agents come and go or decide at their own pace, an answer holds the agents due and those
that left (:mod:`rlenv_client.replay`'s :class:`~rlenv_client.replay.Trajectory` keeps each
answer's observation and ``info["agents"]``). :func:`agent_lives` follows each agent from its
first observation (the reset's answer, or the one it joined in) to its final transition (the
answer it left in), one step per decision: the observation it decided on, the action it took
(its entry in the next step's action), the reward it earned until it next appeared, and its
flags. :func:`member_lives` does the same for the members of a group of agents
(``rlenv.RLAgentGroup``), from the group's arrays (a row per member). :mod:`rlenv_tools.datasets`
makes a Minari episode of each.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rlenv_client.replay import Trajectory

__all__ = ["AgentLife", "agent_lives", "member_lives"]


@dataclass
class AgentLife:
    """One agent's transitions in one episode: ``observations`` has one more than the rest."""

    name: str
    observations: list[Any] = field(default_factory=list)
    actions: list[Any] = field(default_factory=list)
    rewards: list[float] = field(default_factory=list)
    ends: tuple[bool, bool] = (False, False)
    """``(terminated, truncated)`` at its last step."""


def agent_lives(trajectory: Trajectory, groups: frozenset[str] = frozenset()) -> list[AgentLife]:
    """Each agent's life in ``trajectory``, in the order they first appeared.

    An agent in no observation (one the server drove: the recording left it out) has none; nor
    has one that left in the answer it first appeared in (no step). An agent still in play
    where the recording ended (a client's time limit cut it) is cut at its last appearance:
    ``truncated``. The ``groups`` (groups of agents, by name) are left out: see
    :func:`member_lives`.
    """
    lives: dict[str, AgentLife] = {}
    in_play: dict[str, AgentLife] = {}
    for name, observation in _agents(trajectory.observations[0]).items():
        if name not in groups:
            lives[name] = in_play[name] = AgentLife(name, [observation])
    steps = zip(trajectory.actions, trajectory.agents, trajectory.observations[1:], strict=True)
    for action, outcomes, observations in steps:
        for name, life in in_play.items():
            if len(life.actions) < len(life.observations):  # it appeared last: it decides now
                life.actions.append(action[name])
        seen = _agents(observations)
        for name, outcome in (outcomes or {}).items():
            if name not in seen or name in groups:
                continue  # driven (not recorded), or a group
            left = bool(outcome["terminated"] or outcome["truncated"])
            if name not in in_play:
                if not (left or name in lives):  # else gone in its first answer (no step)
                    lives[name] = in_play[name] = AgentLife(name, [seen[name]])
                continue
            life = in_play[name]
            life.observations.append(seen[name])
            life.rewards.append(float(outcome["reward"] or 0.0))
            if left:
                life.ends = (bool(outcome["terminated"]), bool(outcome["truncated"]))
                del in_play[name]
    for life in in_play.values():  # still in play where the recording ended
        del life.actions[len(life.observations) - 1 :]
        life.ends = (False, True)
    return [life for life in lives.values() if life.actions]


def _agents(observation: Any) -> Mapping[str, Any]:
    """An answer's observation by agent name (agents come and go: always a map)."""
    return observation if isinstance(observation, Mapping) else {}


def member_lives(trajectory: Trajectory, group: str) -> list[AgentLife]:
    """Each member's life in ``trajectory`` of the group ``group``, member by member.

    Member ``i`` is named ``f"{group}_{i}"`` (PettingZoo's ``pursuer_0``). A member whose first
    reported row is not ``joined`` started at the reset (its first observation is the reset's
    row); one that joined starts at the row it joined in. Then one step per answer that reports
    it (its decisions), to the row it ended in (or, still in play where the recording ended,
    ``truncated`` at its last). The group's arrays are stacked once; each member is a slice.
    """
    answers = [o[group] for o in trajectory.observations if group in _agents(o)]
    if len(answers) != len(trajectory.observations):
        return []  # the server drove the group: the recording left it out
    observations = np.stack(answers)
    idle = np.zeros_like(np.asarray(trajectory.actions[0][group]))  # once it ended: no action
    actions = np.stack([np.asarray(action.get(group, idle)) for action in trajectory.actions])
    count = observations.shape[1]
    absent = {  # an answer without the group (it ended): no row
        "active": np.zeros(count, np.bool_),
        "joined": np.zeros(count, np.bool_),
        "reward": np.zeros(count),
        "terminated": np.zeros(count, np.bool_),
        "truncated": np.zeros(count, np.bool_),
    }
    outcomes = [(agents or {}).get(group, absent) for agents in trajectory.agents]
    active, joined, rewards, ended = (
        np.stack([np.asarray(o[key]) for o in outcomes])
        for key in ("active", "joined", "reward", "terminated")
    )
    truncated = np.stack([np.asarray(o["truncated"], np.bool_) for o in outcomes])
    ended = ended.astype(np.bool_) | truncated
    lives = []
    for i in range(count):
        rows = np.flatnonzero(active[:, i]) + 1  # the answers (1: the first step's) it is in
        if rows.size == 0:
            continue
        started = not joined[rows[0] - 1, i]
        appearances = np.concatenate([[0], rows]) if started else rows
        gone = np.flatnonzero(ended[appearances[1:] - 1, i])
        if gone.size:
            appearances = appearances[: gone[0] + 2]
        if appearances.size < 2:
            continue  # no step
        last = appearances[-1] - 1
        life = AgentLife(
            f"{group}_{i}",
            list(observations[appearances, i]),
            list(actions[appearances[:-1], i]),
            [float(reward) for reward in rewards[appearances[1:] - 1, i]],
            (bool(ended[last, i] and not truncated[last, i]), bool(truncated[last, i]))
            if ended[last, i]
            else (False, True),
        )
        lives.append(life)
    return lives
