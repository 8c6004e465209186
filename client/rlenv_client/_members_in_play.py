"""The members of an environment's groups as named agents, for PettingZoo and RLlib.

A group of agents (:class:`~rlenv.agent_group.RLAgentGroup`, protocol 2.7) is one agent on the
wire whose observation, action and outcome are arrays over its members. PettingZoo and RLlib
key everything by agent name, so :class:`MembersInPlay` names member ``i`` of group ``G``
``f"{G}_{i}"`` (PettingZoo's ``pursuer_0`` convention) and follows the trainer's agents, the
members and the other agents alike, through the answers, giving each as a
:class:`~rlenv_client._agents_in_play.Turn`, as :class:`~rlenv_client._agents_in_play.AgentsInPlay`
does where agents come and go:

- a member is in an answer where its group's ``active`` row is set (in play, or ending now with
  its final transition); it plays from the answer it first shows up in (the reset's, or the one
  where it joined, with reward 0) until the answer that ends it, once, and never again in the
  episode (its slot is not reused);
- another agent is in an answer where the observation has its entry, until it ends;
- an agent in play that is not in an answer (its group does not decide now) keeps its last
  observation, with reward 0 and both flags false;
- an action holds the entries of the agents that decide now; a group's is one array, with
  zeros in the rows of its members that are not given (the server ignores rows out of play).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv.protocol import GroupSpec, Hello
from rlenv_client._agents_in_play import AgentsInPlay, Turn
from rlenv_client.trainer_view import TrainerView

__all__ = ["MembersInPlay", "in_play", "member_names"]


def in_play(view: TrainerView, hello: Hello) -> AgentsInPlay | MembersInPlay | None:
    """What follows the trainer's agents through the answers, for agents keyed by name.

    :class:`MembersInPlay` where one of them is a group, :class:`AgentsInPlay` where agents
    come and go (the hello's ``possible_agents``), and ``None`` where every agent is in every
    answer.
    """
    if any(name in hello.groups for name in view.agents):
        return MembersInPlay(view, hello.groups)
    return AgentsInPlay(view) if hello.possible_agents is not None else None


def member_names(group: str, count: int) -> list[str]:
    """The names of a group's members as agents: ``f"{group}_{i}"``."""
    return [f"{group}_{index}" for index in range(count)]


class MembersInPlay:
    """The trainer's agents with each group's members named, through one episode after another.

    Args:
        view: the agents the trainer acts for, and their spaces.
        groups: the hello's groups (only those the trainer acts for count).

    Attributes:
        names: every agent the trainer may see, in the hello's order, each group's members in
            its place (PettingZoo's and RLlib's ``possible_agents``).
        members: each group's members' names, by group.
        agents: the agents in play after the last answer.
        due: the agents that decide at the last answer.
    """

    def __init__(self, view: TrainerView, groups: Mapping[str, GroupSpec]) -> None:
        self._groups = {name: groups[name] for name in view.agents if name in groups}
        self.members = {
            name: member_names(name, group.instance_count) for name, group in self._groups.items()
        }
        self._others = tuple(name for name in view.agents if name not in self._groups)
        actions, observations = view.agent_spaces()
        self._action_spaces: dict[str, spaces.Space] = {}
        self._observation_spaces: dict[str, spaces.Space] = {}
        for name in view.agents:
            group = self._groups.get(name)
            for each in self.members[name] if group is not None else (name,):
                self._action_spaces[each] = actions[name] if group is None else group.action_space
                self._observation_spaces[each] = (
                    observations[name] if group is None else group.observation_space
                )
        self.names = tuple(self._action_spaces)
        self._order = {name: index for index, name in enumerate(self.names)}
        self.agents: tuple[str, ...] = ()
        self.due: tuple[str, ...] = ()
        self._playing: set[str] = set()
        self._gone: set[str] = set()  # ended in this episode: never in play again
        self._last: dict[str, Any] = {}

    def agent_spaces(self) -> tuple[dict[str, spaces.Space], dict[str, spaces.Space]]:
        """Each agent's action and observation space, by name (members: one member's)."""
        return dict(self._action_spaces), dict(self._observation_spaces)

    def start(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> Turn:
        """The reset's answer: the agents in it start (each due)."""
        self.agents, self.due = (), ()
        self._playing, self._gone, self._last = set(), set(), {}
        return self.answer(observation, info)

    def answer(
        self, observation: Mapping[str, Any], info: Mapping[str, Any], *, ended: bool = False
    ) -> Turn:
        """Take one step's answer; ``ended``: the episode ended (every agent left is cut)."""
        reported = self._entries(observation, info.get("agents") or {})
        playing = self._playing | reported.keys()
        agents = tuple(sorted(playing, key=self._order.__getitem__))
        rewards, terminated, truncated = {}, {}, {}
        for name in agents:
            entry = reported.get(name)
            if entry is None:
                rewards[name], terminated[name], truncated[name] = 0.0, False, ended
                continue
            self._last[name], rewards[name], terminated[name], cut = entry
            truncated[name] = cut or (ended and not terminated[name])
        left = tuple(name for name in agents if terminated[name] or truncated[name])
        self._gone.update(left)
        self._playing = playing.difference(left)
        self.agents = tuple(name for name in agents if name in self._playing)
        self.due = tuple(name for name in self.agents if name in reported)
        observations = {name: self._last[name] for name in agents}
        return Turn(agents, self.due, left, observations, rewards, terminated, truncated)

    def action(self, actions: Mapping[str, Any]) -> dict[str, Any]:
        """The joint action of the agents due: each group's members' entries in one array."""
        due = set(self.due)
        joint = {name: actions[name] for name in self._others if name in due and name in actions}
        for group, names in self.members.items():
            given = [index for index, name in enumerate(names) if name in due and name in actions]
            if not given:
                continue
            space = self._groups[group].action_space
            column = np.zeros((len(names), *(space.shape or ())), space.dtype)
            for index in given:
                column[index] = actions[names[index]]
            joint[group] = column
        return joint

    def _entries(
        self, observation: Mapping[str, Any], outcomes: Mapping[str, Any]
    ) -> dict[str, tuple[Any, float, bool, bool]]:
        """``(observation, reward, terminated, truncated)`` of each agent in the answer."""
        entries: dict[str, tuple[Any, float, bool, bool]] = {}
        for name in self._others:
            if name in observation and name not in self._gone:
                outcome = outcomes.get(name) or {}
                reward = outcome.get("reward")
                entries[name] = (
                    observation[name],
                    0.0 if reward is None else float(reward),
                    bool(outcome.get("terminated", False)),
                    bool(outcome.get("truncated", False)),
                )
        for group, names in self.members.items():
            outcome = outcomes.get(group)
            if outcome is None or group not in observation:
                continue  # the group does not decide now
            rows = observation[group]
            reward, terminated, truncated = (
                outcome["reward"].tolist(),
                outcome["terminated"].tolist(),
                outcome["truncated"].tolist(),
            )
            for index in np.flatnonzero(outcome["active"]).tolist():
                name = names[index]
                if name not in self._gone:
                    entries[name] = (
                        rows[index].copy(),
                        reward[index],
                        terminated[index],
                        truncated[index],
                    )
        return entries
