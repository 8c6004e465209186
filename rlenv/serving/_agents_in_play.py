"""The agents of an episode while they come and go, and when each of them decides.

An environment plays *by decisions* when it declares
:attr:`~rlenv.environment.RLEnvironment.possible_agents` or one of its agents has a
:attr:`~rlenv.agent.RLAgent.decision_period`. :class:`AgentsInPlay` is then its instance's
roster (:class:`~rlenv.serving._roster.Roster` otherwise: every agent in every answer, at no
cost). Within an episode:

- an RLAgent added under the environment joins: it is checked before the tree adds it (its
  name unused in this episode, declared, of the declared class), and is in the next answer,
  with no reward;
- an agent leaves when its episode ends (``set_terminated``, ``set_truncated``) or when it is
  removed from the tree (``queue_free``, ``remove_child``: terminated, unless it was truncated
  already). Its last observation is taken then, while it is still in the tree, and goes out
  with its reward and flags in the answer of that step, once; it is never stepped or observed
  again;
- an answer holds the agents due to decide and those that left; a step runs until one that
  the client acts for is due (docs/protocol.md, "Agents that come and go").

A group of agents (:class:`~rlenv.agent_group.RLAgentGroup`) is one agent here: it decides as
a whole, its members' ends and joins since its last decision go out at its next one (its
outcome's arrays), and it leaves once no member is left in play. Groups are fixed children:
one added or removed during an episode is refused.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, cast

from gymnasium import spaces

from rlenv.agent import RLAgent
from rlenv.agent_group import RLAgentGroup
from rlenv.environment import RLEnvironment
from rlenv.protocol.messages import MAX_REPEAT_ACTION, joint_end
from rlenv.serving._roster import Outcome, Roster, reward_total

__all__ = [
    "LOCKSTEP_ONLY",
    "MAX_POSSIBLE_AGENTS",
    "AgentsInPlay",
    "Departure",
    "PossibleAgent",
    "roster_of",
]

LOCKSTEP_ONLY = (
    "is not supported where agents come and go or decide at their own pace: they play in lockstep"
)
"""Why real time is refused for such environments (``rlenv serve --real-time``, a config)."""

MAX_POSSIBLE_AGENTS = 1024
"""The most agents an environment may declare (each is in the hello, with its spaces)."""


@dataclass(frozen=True)
class PossibleAgent:
    """An agent that may appear: its name, class and spaces (what the hello lists)."""

    name: str
    cls: type[RLAgent]
    action_space: spaces.Space
    observation_space: spaces.Space

    def has_heuristic(self) -> bool:
        """Whether its class defines a heuristic (``rlenv serve --policy NAME=heuristic``)."""
        return self.cls.has_heuristic()


@dataclass
class Departure:
    """An agent's last transition, taken when it left, for the next answer."""

    observation: Any
    """Its packed observation."""
    reward: float
    terminated: bool
    truncated: bool
    outcome: dict[str, Any] | None = None
    """A group's outcome (its arrays over members); ``None`` for an agent."""


def roster_of(environment: RLEnvironment) -> Roster:
    """The roster of a ready environment: :class:`AgentsInPlay` when it plays by decisions.

    Raises:
        RuntimeError: the environment's agents, or its declaration of them, are not usable
            (see :meth:`Roster.of` and :class:`AgentsInPlay`).
    """
    if not _plays_by_decisions(environment):
        return Roster.of(environment)
    if environment.world is None:
        raise RuntimeError(
            f"{environment!r} has no world: add an RLEnvWorld child or set self.world"
        )
    return AgentsInPlay(environment)


def _plays_by_decisions(environment: RLEnvironment) -> bool:
    """Whether ``environment``'s answers hold the agents due (come and go, decision periods)."""
    classes = (environment.possible_agents or {}).values()
    return (
        environment.possible_agents is not None
        or any(agent.decision_period is not None for agent in environment.agents)
        or any(getattr(cls, "decision_period", None) is not None for cls in classes)
    )


class AgentsInPlay(Roster):
    """The agents in play in one environment's episodes: arrivals, departures, decisions.

    It keeps the environment's :attr:`~rlenv.environment.RLEnvironment.agents` list (the
    agents in play, in the order they came), which :attr:`agents` is.

    Args:
        environment: the environment, ready (its tree tells of agents added and removed).
        observe: packs one agent's observation (the instance's codecs).

    Raises:
        RuntimeError: a declaration that is not a map from names to RLAgent classes, an agent
            present that it does not declare (or declares of another class), a class without
            its spaces, or a decision period that is not a number of ticks.
    """

    __slots__ = (
        "_first_tick",
        "_observe",
        "asked",
        "departed",
        "due",
        "ends",
        "new",
        "possible",
        "tick",
        "used",
    )

    def __init__(
        self, environment: RLEnvironment, observe: Callable[[RLAgent], Any] | None = None
    ) -> None:
        super().__init__(environment)
        self.agents = environment.agents  # the same list: rlenv keeps it as agents come and go
        self.several = True
        self.possible = _possible_agents(environment)
        self._observe = observe or (lambda agent: agent.get_data({}))
        self.tick = 0
        self.used: set[str] = set()
        self.departed: dict[str, Departure] = {}
        self.due: set[str] = set()  # decisions come due since the last answer
        self.asked: set[str] = set()  # the agents answers asked to act, until an action
        self.new: set[str] = set()  # joined since the last answer: their first has no reward
        self.ends: list[tuple[bool, bool]] = []  # how each agent that left this episode left
        self._first_tick = False

    def set_observe(self, observe: Callable[[RLAgent], Any]) -> None:
        """Take each leaving agent's last observation with ``observe`` (packed, as answers are).

        The instance's :class:`~rlenv.serving._observing.Observer` sets it, so that a
        departure's observation is packed by the same codecs, for the same request, as the
        answer's others.
        """
        self._observe = observe

    def space(self, which: str) -> spaces.Space:
        """A ``Dict`` of every possible agent's ``which`` space, keyed by name."""
        return spaces.Dict({name: getattr(one, which) for name, one in self.possible.items()})

    def hello_classes(self) -> dict[str, str]:
        """The hello's ``possible_agents``: each name's class name."""
        return {name: one.cls.__name__ for name, one in self.possible.items()}

    # --- the episode ------------------------------------------------------------------------

    def actors(self) -> list[Any]:
        """Every possible agent (:class:`PossibleAgent`: its ``name`` and spaces)."""
        return list(self.possible.values())

    def deciding(self) -> list[RLAgent]:
        """The agents in play that the last answer asked to act (this step's actions)."""
        return [agent for agent in self.agents if agent.name in self.asked]

    def due_now(self) -> list[RLAgent]:
        """The agents in play whose decision came due since the last answer."""
        return [agent for agent in self.agents if agent.name in self.due]

    def begin(self) -> None:
        """Before the reset's hooks: no episode runs, so the tree may change freely."""
        self._open = False
        self.agents[:] = self._in_tree()
        super().begin()

    def started(self) -> None:
        """After the reset's hooks: the agents they left in the tree start, and all decide."""
        agents = self._in_tree()
        for agent in agents:
            agent.reward = 0.0
            agent.terminated = agent.truncated = False
            self._check_declared(agent)
        environment = self.environment
        self.agents[:] = agents
        environment.agent = agents[0] if agents else None
        self.tick = 0
        self.used = {agent.name for agent in agents}
        self.departed, self.new, self.ends = {}, set(), []
        self.due = set(self.used)
        self.asked = set()
        self._open = True
        self._first_tick = True
        for members in self.groups:
            members.start()

    def settable(self) -> list[RLAgent]:
        """The agents a ``config`` reaches: every agent in the tree, in play or not.

        A reset captures their settings before its hooks run, so a snapshot holds those of
        the agents it starts from, whoever played the episode before.
        """
        return self._in_tree()

    def absent_possible(self) -> frozenset[str]:
        """The names of possible agents that are not in the tree (they left, or never came)."""
        return frozenset(self.possible.keys() - {agent.name for agent in self._in_tree()})

    def _in_tree(self) -> list[RLAgent]:
        return [
            node
            for node in self.environment.get_children()
            if isinstance(node, RLAgent) and not node.is_queued_for_deletion()
        ]

    def after_tick(self, delta: float) -> None:
        """The end of a tick: the agents' ``_after_physics_tick``, who left, who is due."""
        for agent in list(self.agents):
            agent._after_physics_tick(delta)
        for members in self.groups:
            members.ticked()
        if self._first_tick:
            self._first_tick = False
            for agent in self.agents:
                if not agent.act_between_decisions:
                    agent.set_action(agent.no_action())
        for agent in [a for a in self.agents if a.terminated or a.truncated]:
            self._depart(agent, terminated=agent.terminated)
        self.tick += 1
        tick = self.tick
        for agent in self.agents:
            period = agent.decision_period
            if period is not None and (tick - agent.decision_offset) % period == 0:
                self.due.add(agent.name)

    def ended(self) -> bool:
        """Whether no agent is left in play (the episode is over)."""
        return self._open and not self.agents

    def joint_end(self) -> tuple[bool, bool]:
        """The episode's flags: how the agents left, once none is left."""
        if self.agents or not self._open:
            return False, False
        terminated, truncated = joint_end(self.ends)
        return bool(terminated), bool(truncated)

    def clear_rewards(self) -> None:
        """Forget what the agents earned and who left since the last answer."""
        super().clear_rewards()
        self.departed = {}

    # --- answers ----------------------------------------------------------------------------

    def answering(self, reports: bool) -> list[RLAgent]:
        """The agents in play an answer observes: those due (every one for an observer)."""
        if not reports:
            return list(self.agents)
        return [
            agent for agent in self.agents if agent.name in self.due or agent.name in self.asked
        ]

    def departures(self, reports: bool) -> dict[str, Departure]:
        """The agents that left since the last answer (none in an observer's answer)."""
        return self.departed if reports else {}

    def outcome(self, reports: bool) -> Outcome:
        """The answer's agents' rewards (``None`` for one that just joined) and flags."""
        outcomes: dict[str, dict[str, Any]] = {}
        answering = self.answering(reports)
        for agent in answering:
            name = agent.name
            if agent._IS_GROUP:
                outcomes[name], _ = cast(RLAgentGroup, agent)._members.outcome(reports)
                continue
            reward = None if name in self.new else float(agent.reward) if reports else 0.0
            outcomes[name] = {"reward": reward, "terminated": False, "truncated": False}
        for name, gone in self.departures(reports).items():
            outcomes[name] = gone.outcome or {
                "reward": gone.reward,
                "terminated": gone.terminated,
                "truncated": gone.truncated,
            }
        terminated, truncated = self.joint_end()
        if reports:
            for agent in answering:
                agent.reward = 0.0
                if agent._IS_GROUP:
                    cast(RLAgentGroup, agent)._members.clear()
            self.asked = {agent.name for agent in answering}
            self.due, self.departed, self.new = set(), {}, set()
        total = sum(reward_total(o["reward"]) for o in outcomes.values())
        return total, terminated, truncated, outcomes

    def acted(self) -> None:
        """A step starts: the agents due decide; the last answer told who joined and left.

        An agent's reward counts from its last decision (a replayed log's steps too).
        """
        for agent in self.agents:
            if agent.name in self.due and agent.name not in self.new:
                _forget_reward(agent)
        self.asked, self.due, self.departed, self.new = set(), set(), {}, set()

    def replayed(self) -> None:
        """A restore replayed the log: its last answer told the due their rewards, and who left."""
        for agent in self.agents:
            if agent.name in self.due:
                _forget_reward(agent)
                if agent._IS_GROUP:  # its members' comings and goings were told
                    cast(RLAgentGroup, agent)._members.clear()
        self.departed = {}

    # --- decisions --------------------------------------------------------------------------

    def ticks_for(self, repeat_action: int) -> int:
        """The ticks a step runs, at most ``repeat_action`` while agents without a period play.

        To the first tick at which an agent with a period is due, or ``repeat_action`` ticks
        while an agent without one is in play (it decides at every answer), whichever comes
        first.
        """
        now = self.tick
        soonest = [
            now + 1 + (agent.decision_offset - now - 1) % agent.decision_period
            for agent in self.agents
            if agent.decision_period is not None
        ]
        if len(soonest) < len(self.agents) or not soonest:
            soonest.append(now + repeat_action)
        return max(1, min(soonest) - now)

    def boundary(self) -> None:
        """A step's ticks ran: the agents without a period decide now.

        The next tick is the first of the agents' new actions: after it, an agent that does
        not act between its decisions gets its ``no_action()``.
        """
        self.due.update(a.name for a in self.agents if a.decision_period is None)
        self._first_tick = True

    def decided(self, names: Any) -> None:
        """The agents ``names`` decided in the server (driven): they are due no more.

        Their rewards count from now (since their last decision).
        """
        self.due.difference_update(names)
        for agent in self.agents:
            if agent.name in names:
                _forget_reward(agent)

    # --- the tree's changes (rlenv.environment.AgentWatch) ----------------------------------

    def joining(self, agent: RLAgent) -> None:
        """Refuse ``agent`` unless it may join this episode (raises ``ValueError``)."""
        if not self._open:
            return
        if agent._IS_GROUP:
            raise ValueError(
                f"cannot add group {agent.name!r} to {self.environment.name} during an "
                "episode: groups are fixed children (their members come and go: add_member)"
            )
        if agent.name in self.used:
            raise ValueError(
                f"cannot add agent {agent.name!r} to {self.environment.name}: the name was "
                "used already in this episode (an agent's name is never used twice in one "
                "episode)"
            )
        self._check_declared(agent)
        check_period(agent, agent.name)

    def joined(self, agent: RLAgent) -> None:
        """``agent`` is in the tree: it is in play, and decides at the next answer."""
        if not self._open or agent.name in self.used:
            return
        name = agent.name
        agent.reward = 0.0
        agent.terminated = agent.truncated = False
        self.used.add(name)
        self.agents.append(agent)
        self.new.add(name)
        self.due.add(name)

    def leaving(self, agent: RLAgent) -> None:
        """``agent`` leaves the tree: its last transition is taken now.

        It terminated, unless it was truncated already.
        """
        if self._open and agent in self.agents:
            if agent._IS_GROUP:
                raise ValueError(
                    f"cannot remove group {agent.name!r} from {self.environment.name} during "
                    "an episode: groups are fixed children (their members leave: "
                    "remove_member)"
                )
            self._depart(agent, terminated=agent.terminated or not agent.truncated)

    def _depart(self, agent: RLAgent, terminated: bool) -> None:
        name = agent.name
        observation = self._observe(agent)
        outcome = None
        if agent._IS_GROUP:  # its last members' final transitions
            members = cast(RLAgentGroup, agent)._members
            outcome, reward = members.outcome(True)
            members.clear()
        else:
            reward = 0.0 if name in self.new else float(agent.reward)
        self.departed[name] = Departure(observation, reward, terminated, not terminated, outcome)
        self.ends.append((terminated, not terminated))
        agent.reward = 0.0
        self.agents.remove(agent)
        environment = self.environment
        environment.agent = self.agents[0] if self.agents else None
        self.due.discard(name)
        self.asked.discard(name)
        self.new.discard(name)

    def _check_declared(self, agent: RLAgent) -> None:
        name, environment = agent.name, self.environment
        declared = self.possible.get(name)
        where = f"{type(environment).__name__}.possible_agents"
        if declared is None:
            if environment.possible_agents is None:
                raise ValueError(
                    f"cannot add agent {name!r} to {environment.name} during an episode: "
                    f"{type(environment).__name__} declares no possible_agents (declare "
                    "RLEnvironment.possible_agents, a map from each name that may appear to "
                    "its RLAgent class, to let agents join)"
                )
            raise ValueError(
                f"cannot add agent {name!r} to {environment.name}: {where} does not name it "
                f"(it names {', '.join(self.possible)})"
            )
        if not isinstance(agent, declared.cls):
            raise ValueError(
                f"cannot add agent {name!r} to {environment.name}: it is a "
                f"{type(agent).__name__}, and {where} declares it a {declared.cls.__name__}"
            )


def _forget_reward(agent: RLAgent) -> None:
    """An agent's reward counts from now (a group's rows too)."""
    agent.reward = 0.0
    if agent._IS_GROUP:
        cast(RLAgentGroup, agent)._rewards[:] = 0.0


def _possible_agents(environment: RLEnvironment) -> dict[str, PossibleAgent]:
    """Each possible agent, by name: the declaration, or the agents present after ``_ready``.

    An agent present takes its spaces from itself; one that may join later, from its class.
    """
    declared = environment.possible_agents
    present = {agent.name: agent for agent in environment.agents}
    where = f"{type(environment).__name__}.possible_agents"
    if declared is None:
        found: dict[str, tuple[type[RLAgent], Any]] = {
            name: (type(agent), agent) for name, agent in present.items()
        }
    else:
        _check_declaration(declared, where)
        for name, agent in present.items():
            if name not in declared:
                raise RuntimeError(f"agent {name!r} is in the tree, but {where} does not name it")
            if not isinstance(agent, declared[name]):
                raise RuntimeError(
                    f"agent {name!r} is a {type(agent).__name__}, but {where} declares it a "
                    f"{declared[name].__name__}"
                )
        found = {name: (cls, present.get(name, cls)) for name, cls in declared.items()}
    possible = {}
    for name, (cls, holder) in found.items():
        for which in ("action_space", "observation_space"):
            if not isinstance(getattr(holder, which, None), spaces.Space):
                raise RuntimeError(
                    f"{cls.__name__} (possible agent {name!r}) must set {which} as a class "
                    "attribute: the hello lists it before the agent joins"
                )
        check_period(holder, name)
        possible[name] = PossibleAgent(name, cls, holder.action_space, holder.observation_space)
    return possible


def _check_declaration(declared: Any, where: str) -> None:
    if not isinstance(declared, Mapping) or not declared:
        raise RuntimeError(
            f"{where} must be a non-empty map from agent name to RLAgent class, "
            f"got {declared!r:.80}"
        )
    if len(declared) > MAX_POSSIBLE_AGENTS:
        raise RuntimeError(
            f"{where} declares {len(declared)} agents; at most {MAX_POSSIBLE_AGENTS}"
        )
    for name, cls in declared.items():
        if not (isinstance(name, str) and name and not set(name) & set('/@:.%"')):
            raise RuntimeError(
                f'{where}: {name!r:.40} is not an agent name (a non-empty str, no / @ : . % ")'
            )
        if not (isinstance(cls, type) and issubclass(cls, RLAgent)):
            raise RuntimeError(f"{where}[{name!r}] must be an RLAgent class, got {cls!r:.60}")


def check_period(agent: Any, name: str) -> None:
    """Refuse an agent's ``decision_period`` or ``decision_offset`` that is not a tick count.

    Raises:
        RuntimeError: saying which and why.
    """
    period, offset = agent.decision_period, agent.decision_offset
    if period is None:
        return
    if type(period) is not int or not 1 <= period <= MAX_REPEAT_ACTION:
        raise RuntimeError(
            f"agent {name!r}: decision_period must be None or an integer in "
            f"1..{MAX_REPEAT_ACTION} ticks, got {period!r:.40}"
        )
    if type(offset) is not int or not 0 <= offset < period:
        raise RuntimeError(
            f"agent {name!r}: decision_offset must be an integer in 0..{period - 1} (within "
            f"its period), got {offset!r:.40}"
        )
