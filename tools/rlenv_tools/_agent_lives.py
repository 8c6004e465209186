"""Each agent's life in a replayed episode where agents come and go: its own transitions.

Where agents come and go or decide at their own pace, an answer holds the agents due and those
that left (:mod:`rlenv_client.replay`'s :class:`~rlenv_client.replay.Trajectory` keeps each
answer's observation and ``info["agents"]``). :func:`agent_lives` follows each agent from its
first observation (the reset's answer, or the one it joined in) to its final transition (the
answer it left in), one step per decision: the observation it decided on, the action it took
(its entry in the next step's action), the reward it earned until it next appeared, and its
flags. :mod:`rlenv_tools.datasets` makes a Minari episode of each.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from rlenv_client.replay import Trajectory

__all__ = ["AgentLife", "agent_lives"]


@dataclass
class AgentLife:
    """One agent's transitions in one episode: ``observations`` has one more than the rest."""

    name: str
    observations: list[Any] = field(default_factory=list)
    actions: list[Any] = field(default_factory=list)
    rewards: list[float] = field(default_factory=list)
    ends: tuple[bool, bool] = (False, False)
    """``(terminated, truncated)`` at its last step."""


def agent_lives(trajectory: Trajectory) -> list[AgentLife]:
    """Each agent's life in ``trajectory``, in the order they first appeared.

    An agent in no observation (one the server drove: the recording left it out) has none; nor
    has one that left in the answer it first appeared in (no step). An agent still in play
    where the recording ended (a client's time limit cut it) is cut at its last appearance:
    ``truncated``.
    """
    lives: dict[str, AgentLife] = {}
    in_play: dict[str, AgentLife] = {}
    for name, observation in _agents(trajectory.observations[0]).items():
        lives[name] = in_play[name] = AgentLife(name, [observation])
    steps = zip(trajectory.actions, trajectory.agents, trajectory.observations[1:], strict=True)
    for action, outcomes, observations in steps:
        for name, life in in_play.items():
            if len(life.actions) < len(life.observations):  # it appeared last: it decides now
                life.actions.append(action[name])
        seen = _agents(observations)
        for name, outcome in (outcomes or {}).items():
            if name not in seen:
                continue  # driven: not recorded
            left = bool(outcome["terminated"] or outcome["truncated"])
            life = in_play.get(name)
            if life is None:
                if left or name in lives:
                    continue  # gone in its first answer (no step)
                lives[name] = in_play[name] = AgentLife(name, [seen[name]])
                continue
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
