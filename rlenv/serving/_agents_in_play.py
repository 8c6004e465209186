"""The agents of one episode while they come and go, and when each of them decides.

An environment plays *by answers of the agents due* when it declares
:attr:`~rlenv.environment.RLEnvironment.possible_agents` or one of its agents has a
:attr:`~rlenv.agent.RLAgent.decision_period`. Then, within an episode:

- an RLAgent added under the environment joins: it is checked before the tree adds it (its
  name unused in this episode, declared, of the declared class), and its first observation
  comes in the next answer, with no reward;
- an agent leaves when its episode ends (``set_terminated``, ``set_truncated``) or when it is
  removed from the tree (``queue_free``, ``remove_child``: terminated, unless it was truncated
  already). Its last observation is taken then, while it is still in the tree, and goes out
  with its reward and flags in the answer of that step, once; it is never stepped or observed
  again;
- an answer holds the agents due to decide and those that left; a step runs until one that
  the client acts for is due (docs/protocol.md, "Agents that come and go").

An environment without either plays every agent at every answer, as before: :class:`Roster`
is then not made at all (no cost).
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass
from typing import Any

from gymnasium import spaces

from rlenv.agent import RLAgent
from rlenv.environment import RLEnvironment
from rlenv.protocol.messages import MAX_REPEAT_ACTION

__all__ = ["MAX_POSSIBLE_AGENTS", "Departure", "Roster", "plays_by_decisions", "possible_agents"]

MAX_POSSIBLE_AGENTS = 1024
"""The most agents an environment may declare (each is in the hello, with its spaces)."""


def plays_by_decisions(environment: RLEnvironment, agents: Collection[RLAgent]) -> bool:
    """Whether ``environment`` answers with the agents due (come and go, decision periods)."""
    return (
        environment.possible_agents is not None
        or any(agent.decision_period is not None for agent in agents)
        or any(
            cls.decision_period is not None for cls in (environment.possible_agents or {}).values()
        )
    )


def possible_agents(
    environment: RLEnvironment, agents: Collection[RLAgent]
) -> dict[str, tuple[type[RLAgent], spaces.Space, spaces.Space]]:
    """Each possible agent's class, action space and observation space, by name.

    The declaration (:attr:`~rlenv.environment.RLEnvironment.possible_agents`), or the agents
    present once ``_ready`` ran. An agent present takes its spaces from itself; one that may
    join later, from its class.

    Raises:
        TypeError: a declaration that is not a map from names to RLAgent classes, an agent
            present that it does not declare (or declares of another class), a class without
            its spaces, or a decision period that is not a number of ticks.
    """
    declared = environment.possible_agents
    present = {agent.name: agent for agent in agents}
    where = f"{type(environment).__name__}.possible_agents"
    if declared is None:
        found = {name: (type(agent), agent) for name, agent in present.items()}
    else:
        if not isinstance(declared, Mapping) or not declared:
            raise TypeError(
                f"{where} must be a non-empty map from agent name to RLAgent class, "
                f"got {declared!r:.80}"
            )
        if len(declared) > MAX_POSSIBLE_AGENTS:
            raise TypeError(
                f"{where} declares {len(declared)} agents; at most {MAX_POSSIBLE_AGENTS}"
            )
        for name, cls in declared.items():
            if not (isinstance(name, str) and name and "/" not in name and "@" not in name):
                raise TypeError(
                    f"{where}: {name!r:.40} is not an agent name (a non-empty "
                    "str without '/' or '@')"
                )
            if not (isinstance(cls, type) and issubclass(cls, RLAgent)):
                raise TypeError(f"{where}[{name!r}] must be an RLAgent class, got {cls!r:.60}")
        for name, agent in present.items():
            if name not in declared:
                raise TypeError(f"agent {name!r} is in the tree, but {where} does not name it")
            if not isinstance(agent, declared[name]):
                raise TypeError(
                    f"agent {name!r} is a {type(agent).__name__}, but {where} "
                    f"declares it a {declared[name].__name__}"
                )
        found = {name: (cls, present.get(name)) for name, cls in declared.items()}
    result = {}
    for name, (cls, agent) in found.items():
        holder: Any = agent if agent is not None else cls
        for which in ("action_space", "observation_space"):
            if not isinstance(getattr(holder, which, None), spaces.Space):
                raise TypeError(
                    f"{cls.__name__} (possible agent {name!r}) must set {which} as "
                    "a class attribute: the hello lists it before the agent joins"
                )
        _check_period(holder, name)
        result[name] = (cls, holder.action_space, holder.observation_space)
    return result


def _check_period(agent: Any, name: str) -> None:
    period, offset = agent.decision_period, agent.decision_offset
    if period is None:
        return
    if type(period) is not int or not 1 <= period <= MAX_REPEAT_ACTION:
        raise TypeError(
            f"agent {name!r}: decision_period must be None or an integer in "
            f"1..{MAX_REPEAT_ACTION} ticks, got {period!r:.40}"
        )
    if type(offset) is not int or not 0 <= offset < period:
        raise TypeError(
            f"agent {name!r}: decision_offset must be an integer in "
            f"0..{period - 1} (within its period), got {offset!r:.40}"
        )


@dataclass
class Departure:
    """An agent's last transition, taken when it left, for the next answer."""

    observation: Any
    """Its packed observation (``None`` when the step asked for none)."""
    reward: float
    terminated: bool
    truncated: bool


class Roster:
    """The agents in play in one environment's episode, their arrivals, departures, decisions.

    It keeps the environment's :attr:`~rlenv.environment.RLEnvironment.agents` list: the
    agents in play, in the order they came.

    Args:
        environment: the environment (its tree tells of agents added and removed).
        possible: each possible agent's class, by name (:func:`possible_agents`).
        observe: packs one agent's observation for the request being served.
    """

    def __init__(
        self,
        environment: RLEnvironment,
        possible: Mapping[str, type[RLAgent]],
        observe: Callable[[RLAgent], Any],
    ) -> None:
        self.environment = environment
        self.possible = dict(possible)
        self._observe = observe
        self.tick = 0
        self.used: set[str] = set()
        self.departed: dict[str, Departure] = {}
        self.due: set[str] = set()
        self.new: set[str] = set()  # joined since the last answer: no reward in their first
        self._last_decision: dict[str, int] = {}
        self._open = False

    # --- the episode ----------------------------------------------------------------------

    def begin(self) -> None:
        """A new episode: the agents the reset left in the tree start it, and all decide."""
        environment = self.environment
        agents = [
            node
            for node in environment.get_children()
            if isinstance(node, RLAgent) and not node.is_queued_for_deletion()
        ]
        for agent in agents:
            self._check_declared(agent)
        environment.agents[:] = agents
        environment.agent = agents[0] if agents else None
        self.tick = 0
        self.used = {agent.name for agent in agents}
        self.departed = {}
        self.new = set()
        self.due = set(self.used)
        self._last_decision = dict.fromkeys(self.used, 0)
        self._open = True

    def close(self) -> None:
        """No episode runs (before a reset, after an error): the tree may change freely."""
        self._open = False

    @property
    def in_play(self) -> list[RLAgent]:
        """The agents still in the episode."""
        return self.environment.agents

    def is_over(self) -> bool:
        """Whether no agent is left in play (the episode ends)."""
        return not self.environment.agents

    # --- the tree's changes (rlenv.environment.AgentWatch) --------------------------------

    def joining(self, agent: RLAgent) -> None:
        """Refuse ``agent`` unless it may join this episode (raises ``ValueError``)."""
        if not self._open:
            return
        name = agent.name
        if name in self.used:
            raise ValueError(
                f"cannot add agent {name!r} to {self.environment.name}: the name "
                "was used already in this episode (an agent's name is never used "
                "twice in one episode)"
            )
        self._check_declared(agent)

    def joined(self, agent: RLAgent) -> None:
        """``agent`` is in the tree: it is in play, and decides at the next answer."""
        if not self._open or agent.name in self.used:
            return
        name = agent.name
        self.used.add(name)
        self.environment.agents.append(agent)
        self.new.add(name)
        self.due.add(name)
        self._last_decision[name] = self.tick

    def leaving(self, agent: RLAgent) -> None:
        """``agent`` leaves the tree: its last transition is taken now (terminated, unless
        truncated already)."""
        if self._open and agent in self.environment.agents:
            self._depart(agent, terminated=not agent.truncated or agent.terminated)

    def end_tick(self) -> None:
        """After a tick: the agents whose episode ended leave, their last transition taken."""
        for agent in [a for a in self.environment.agents if a.terminated or a.truncated]:
            self._depart(agent, terminated=agent.terminated)

    def _depart(self, agent: RLAgent, terminated: bool) -> None:
        name = agent.name
        observation = self._observe(agent)
        reward = float(agent.reward)
        agent.reward = 0.0
        self.departed[name] = Departure(
            observation, 0.0 if name in self.new else reward, bool(terminated), not terminated
        )
        self.environment.agents.remove(agent)
        environment = self.environment
        environment.agent = environment.agents[0] if environment.agents else None
        self.due.discard(name)
        self._last_decision.pop(name, None)

    def _check_declared(self, agent: RLAgent) -> None:
        name, declared = agent.name, self.possible.get(agent.name)
        where = f"{type(self.environment).__name__}.possible_agents"
        if declared is None:
            if self.environment.possible_agents is None:
                raise ValueError(
                    f"cannot add agent {name!r} to {self.environment.name} during an episode: "
                    f"{type(self.environment).__name__} declares no possible_agents (declare "
                    "RLEnvironment.possible_agents, a map from each name that may appear to "
                    "its RLAgent class, to let agents join)"
                )
            raise ValueError(
                f"cannot add agent {name!r} to {self.environment.name}: {where} "
                f"does not name it (it names {', '.join(self.possible)})"
            )
        if not isinstance(agent, declared):
            raise ValueError(
                f"cannot add agent {name!r} to {self.environment.name}: it is a "
                f"{type(agent).__name__}, and {where} declares it a "
                f"{declared.__name__}"
            )

    # --- decisions ------------------------------------------------------------------------

    def ticks_to_next_decision(self, repeat_action: int, acting: Collection[str]) -> int:
        """Ticks from now to the first tick at which an agent of ``acting`` is due (≥ 1).

        An agent with a ``decision_period`` is due at the episode's ticks ``t`` with
        ``(t - decision_offset) % decision_period == 0``; one without, ``repeat_action``
        ticks after its last decision. With none of ``acting`` in play, ``repeat_action``.
        """
        best = None
        for agent in self.environment.agents:
            if agent.name in acting:
                due = self._next_due(agent, repeat_action)
                best = due if best is None else min(best, due)
        return max(1, (best if best is not None else self.tick + repeat_action) - self.tick)

    def _next_due(self, agent: RLAgent, repeat_action: int) -> int:
        period = agent.decision_period
        if period is None:
            return max(
                self._last_decision.get(agent.name, self.tick) + repeat_action, self.tick + 1
            )
        offset = agent.decision_offset
        ahead = (offset - (self.tick + 1)) % period
        return self.tick + 1 + ahead

    def ticked(self, repeat_action: int) -> None:
        """One tick ran: the agents due at its end decide."""
        self.tick += 1
        for agent in self.environment.agents:
            if self._next_due_now(agent, repeat_action):
                self.due.add(agent.name)
                self._last_decision[agent.name] = self.tick

    def _next_due_now(self, agent: RLAgent, repeat_action: int) -> bool:
        period = agent.decision_period
        if period is None:
            return self.tick - self._last_decision.get(agent.name, self.tick) >= repeat_action
        return (self.tick - agent.decision_offset) % period == 0

    def answered(self) -> None:
        """An answer to the controller went out: its due agents and departures are told."""
        self.due = set()
        self.departed = {}
        self.new = set()
