"""Players: who acts for the agents of an instance besides the client that controls it.

Within the controller's steps of an episode of several agents, others may act for some agents,
each over the entries before it (:meth:`Players.complete`):

- policies the server drives agents with (``rlenv serve --policy``:
  :mod:`rlenv.serving.policy_driver`);
- observers that claim an agent and hold its action (:mod:`rlenv.serving._claims`);
- an agent's own heuristic, for the agents a step names in its ``heuristic`` part (unless an
  observer claims it).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from rlenv.agent import RLAgent
from rlenv.serving._agents_in_play import AgentsInPlay
from rlenv.serving._claims import Claims
from rlenv.serving._roster import Roster
from rlenv.serving.policy_driver import HEURISTIC, DrivenAgents

__all__ = ["Players"]


class Players:
    """The policies, claims and heuristics that act for agents within the controller's steps.

    Attributes:
        driven: the agents policies drive (``rlenv serve --policy``), or ``None``.
        claims: the agents observers play (:mod:`rlenv.serving._claims`), ``None`` while none
            is claimed (then they cost nothing in a step).
    """

    __slots__ = ("_heuristics", "claims", "driven")

    def __init__(self) -> None:
        self.driven: DrivenAgents | None = None
        self.claims: Claims | None = None
        self._heuristics: DrivenAgents | None = None  # made on first use

    def claim(self, owner: object, name: str, action: Any) -> None:
        """``owner`` (an observer's connection) plays agent ``name`` with ``action`` (checked)."""
        if self.claims is None:
            self.claims = Claims()
        self.claims.hold(owner, name, action)

    def release(self, owner: object) -> None:
        """End ``owner``'s claim, if it holds one (its agent goes back to the controller)."""
        if self.claims is not None and not self.claims.release(owner):
            self.claims = None

    def complete(self, action: Any, heuristic: frozenset[str], roster: Roster) -> Any:
        """The joint ``action`` completed by the others who act within it.

        The driven agents' actions go in, then the claimed agents' held actions, then those of
        the agents named in ``heuristic`` (by their heuristic): of the agents that decide now
        (every agent, unless agents come and go).

        Raises:
            PolicyError: a policy or a heuristic gave no action of its agent's space.
        """
        agents = roster.deciding()
        if self.driven is not None:
            action = self.driven.complete(action, agents)
        if self.claims is not None:
            action, heuristic = self.claims.complete(action, heuristic)
        if heuristic:
            acting = self._heuristic(roster.actors())
            action = {**action, **acting.actions(agents, heuristic)}
        return action

    def decide(self, roster: Roster) -> Any:
        """After a step's ticks: the driven agents' action unless others are due (``None``).

        The step then goes on (agents that come and go and decide at their own pace): those
        agents decided in the server.

        Raises:
            PolicyError: a policy or a heuristic gave no action of its agent's space.
        """
        driven = self.driven
        if driven is None or driven.every_agent or not isinstance(roster, AgentsInPlay):
            return None
        due = roster.due_now()
        if any(agent.name not in driven.names for agent in due):
            return None  # an agent the client acts for decides: the step answers
        if not due:
            return {}  # the agent due left on the way: no one decides, the step goes on
        action = driven.actions(due)
        roster.decided(action)
        return action

    def claimed(self, agents: Sequence[RLAgent]) -> list[str]:
        """The names of the claimed ``agents``, in the environment's order."""
        owners = self.claims.owners if self.claims is not None else {}
        return [agent.name for agent in agents if agent.name in owners]

    def _heuristic(self, agents: Sequence[Any]) -> DrivenAgents:
        """Every agent that has a heuristic, driven by it (for a request's ``heuristic``)."""
        if self._heuristics is None:
            self._heuristics = DrivenAgents(
                {a.name: HEURISTIC for a in agents if a.has_heuristic()}, agents
            )
        return self._heuristics
