"""Roster: the agents of one instance's environment, and how each fares through an episode.

An environment's agents are checked once it is ready (each has its spaces; the environment
has a world), and their spaces make the instance's: the one agent's own, or a ``Dict`` keyed
by agent name with several. Through an episode the roster keeps what each agent earned and
how it ended: it clears them at a reset, runs each agent's end of tick, says when every agent
ended, and gives what an answer reports (each agent's reward since the previous answer, its
flags, and the joint end: :func:`rlenv.protocol.messages.joint_end`).

A group of agents (:class:`~rlenv.agent_group.RLAgentGroup`) is one agent here, whose
outcome is arrays over its members (``reward``, ``terminated``, ``truncated``, ``active``,
``joined``); its members' bookkeeping is its own, which the roster runs at a reset, at the end
of each tick and at each answer. An environment with a group has keyed spaces and outcomes.
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np
from gymnasium import spaces

from rlenv._group_members import GroupMembers
from rlenv.agent import RLAgent
from rlenv.agent_group import RLAgentGroup
from rlenv.environment import RLEnvironment
from rlenv.protocol.messages import joint_end

__all__ = ["Outcome", "Roster", "reward_total"]

Outcome = tuple[float, bool, bool, dict[str, dict[str, Any]] | None]
"""What an answer reports of the agents: the reward, the flags, and each agent's with several
(its ``reward``, ``terminated`` and ``truncated``; a group's as arrays, with ``active`` and
``joined``; ``None`` with one agent)."""


def reward_total(reward: Any) -> float:
    """An agent's reward in an answer as one number: a group's rows summed; 0 for ``None``."""
    if reward.__class__ is np.ndarray:
        return float(reward.sum())
    return 0.0 if reward is None else reward


class Roster:
    """The agents of an environment (:meth:`of` checks them) and their episode's bookkeeping.

    Attributes:
        agents: the environment's agents, in its order.
        several: whether there are several, or a group (spaces and outcomes keyed by name).
        groups: the members of the environment's groups (each group's bookkeeping).
    """

    __slots__ = ("_open", "agents", "environment", "groups", "several")

    def __init__(self, environment: RLEnvironment) -> None:
        self.environment = environment
        self.agents = list(environment.agents)
        self.groups: list[GroupMembers] = [
            agent._members for agent in self.agents if isinstance(agent, RLAgentGroup)
        ]
        self.several = len(self.agents) > 1 or bool(self.groups)
        self._open = False  # an episode runs: the tree may not change its agents
        environment._agent_watch = self

    @classmethod
    def of(cls, environment: RLEnvironment) -> Roster:
        """The environment's agents, each with its spaces; and it must have a world.

        An ``_ready`` that sets only ``self.agent`` (the seed's way) has that one agent.

        Raises:
            RuntimeError: the environment has no agent, no world, or an agent without spaces.
        """
        if not environment.agents and environment.agent is not None:
            environment.agents = [environment.agent]
        if not environment.agents:
            raise RuntimeError(
                f"{environment!r} has no agent: add an RLAgent child or set self.agent"
            )
        if environment.world is None:
            raise RuntimeError(
                f"{environment!r} has no world: add an RLEnvWorld child or set self.world"
            )
        for agent in environment.agents:
            for attribute in ("action_space", "observation_space"):
                if not isinstance(getattr(agent, attribute, None), spaces.Space):
                    raise RuntimeError(f"{agent!r} must set {attribute} to a gymnasium space")
        return cls(environment)

    def space(self, which: str) -> spaces.Space:
        """The agents' ``which`` space: the agent's own, or a ``Dict`` keyed by agent name."""
        agents = self.agents
        if not self.several:
            return getattr(agents[0], which)
        return spaces.Dict({agent.name: getattr(agent, which) for agent in agents})

    def actors(self) -> list[Any]:
        """Every agent that may act: each with its ``name`` and ``action_space``."""
        return self.agents

    def deciding(self) -> list[RLAgent]:
        """The agents that decide at this answer: every agent."""
        return self.agents

    def begin(self) -> None:
        """A new episode: no agent has earned anything or ended; the reset may change the tree."""
        self._open = False
        for agent in self.agents:
            agent.reward = 0.0
            agent.terminated = agent.truncated = False
        for members in self.groups:
            members.begin()

    def started(self) -> None:
        """The reset's hooks ran: until the next reset, the tree may not change its agents."""
        self._open = True
        for members in self.groups:
            members.start()

    def close(self) -> None:
        """No episode runs (after an error): the tree may change freely."""
        self._open = False

    # --- the tree's changes (rlenv.environment.AgentWatch): refused in an episode ----------

    def joining(self, agent: RLAgent) -> None:
        """Refuse an agent added during an episode: this environment's agents are fixed."""
        if self._open:
            self._refuse(f"add agent {agent.name!r} to", "join")

    def joined(self, agent: RLAgent) -> None:
        """Nothing: an agent joins only environments that declare who may."""

    def leaving(self, agent: RLAgent) -> None:
        """Refuse an agent of this episode's removed during it: its agents are fixed."""
        if self._open and agent in self.agents:
            self._refuse(f"remove agent {agent.name!r} from", "leave")

    def _refuse(self, what: str, verb: str) -> None:
        environment = self.environment
        raise ValueError(
            f"cannot {what} {environment.name} during an episode: "
            f"{type(environment).__name__} declares no possible_agents (declare "
            "RLEnvironment.possible_agents, a map from each name that may appear to its "
            f"RLAgent class, to let agents {verb}; or end an agent's episode with "
            "set_terminated())"
        )

    def ticks_for(self, repeat_action: int) -> int:
        """The ticks a step runs: ``repeat_action`` (every agent decides at every answer)."""
        return repeat_action

    def boundary(self) -> None:
        """A step's ticks ran (the agents that decide at every answer are due now)."""

    def replayed(self) -> None:
        """A restore replayed the log: its answer reports nothing the replay earned."""
        self.clear_rewards()

    def acted(self) -> None:
        """An action applies (every agent decides at every answer: nothing to keep)."""

    def decided(self, names: Any) -> None:
        """The agents ``names`` decided in the server (every agent decides at every answer)."""

    def after_tick(self, delta: float) -> None:
        """The end of a tick (after pymunk stepped): each agent's ``_after_physics_tick``."""
        for agent in self.agents:
            agent._after_physics_tick(delta)
        for members in self.groups:
            members.ticked()

    def ended(self) -> bool:
        """Whether every agent terminated or was truncated (the episode is over)."""
        for agent in self.agents:
            if not (agent.terminated or agent.truncated):
                return False
        return True

    def joint_end(self) -> tuple[bool, bool]:
        """The episode's flags (terminated, truncated), as an answer reports them."""
        if self.several:
            terminated, truncated = joint_end(
                [(agent.terminated, agent.truncated) for agent in self.agents]
            )
            return bool(terminated), bool(truncated)
        agent = self.agents[0]
        return bool(agent.terminated), bool(agent.truncated)

    def clear_rewards(self) -> None:
        """Forget what the agents earned since the last answer (no one is to report it)."""
        for agent in self.agents:
            agent.reward = 0.0
        for members in self.groups:
            members.clear()

    def outcome(self, reports: bool) -> Outcome:
        """The agents' reward (cleared if it ``reports`` it) and flags, and each one's."""
        agents = self.agents
        if not self.several:
            agent = agents[0]
            reward = float(agent.reward) if reports else 0.0
            if reports:
                agent.reward = 0.0
            return reward, bool(agent.terminated), bool(agent.truncated), None
        outcomes: dict[str, dict[str, Any]] = {}
        total = 0.0
        for each in agents:
            if each._IS_GROUP:
                outcomes[each.name], reward = cast(RLAgentGroup, each)._members.outcome(reports)
            else:
                reward = float(each.reward) if reports else 0.0
                outcomes[each.name] = {
                    "reward": reward,
                    "terminated": bool(each.terminated),
                    "truncated": bool(each.truncated),
                }
            total += reward
        terminated, truncated = self.joint_end()
        if reports:
            self.clear_rewards()
        return total, terminated, truncated, outcomes
