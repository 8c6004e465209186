"""Who acts for an agent beside the controller's action (2.6): ``heuristic`` and ``claim``.

Records of :data:`rlenv.serving._parts.PARTS`. In a request's action, ``heuristic`` names the
agents that act by their ``RLAgent.heuristic``; ``claim`` lets an observer play one agent of
several (the held actions: :mod:`rlenv.serving._claims`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.serving._instance import Instance, Plan
from rlenv.serving._part_record import Part, as_map, bad
from rlenv.serving._settings import check_keys

__all__ = ["Claim", "Heuristic"]


class Heuristic(Part):
    """Agent names (2.6): in this request's action, they act by their ``RLAgent.heuristic``.

    As for agents the server drives (``rlenv serve --policy NAME=heuristic``), each named agent
    still in the episode gets its heuristic's action for its observation just before the
    action applies, and the episode's log records it; the action has no entry for them. The
    inspector's demonstrations send it: a person plays one agent, the others their heuristic.
    """

    name = "heuristic"

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
        names = parts["heuristic"]
        agents = {agent.name: agent for agent in instance.agents}
        if not (isinstance(names, list) and all(isinstance(n, str) for n in names)):
            raise bad(f"{where}'heuristic' must be a list of agent names")
        if parts.get("action") is None:
            raise bad(f"{where}'heuristic' given without an 'action'")
        if not instance.multi_agent:
            raise bad(
                f"{where}'heuristic' names agents of an action of several; to let a "
                "lone agent's heuristic play, serve it with --policy NAME=heuristic"
            )
        driven = instance.driven.names if instance.driven is not None else frozenset()
        for name in names:
            agent = agents.get(name)
            if agent is None:
                raise bad(
                    f"{where}heuristic: no agent {name!r:.40}; the agents: {', '.join(agents)}"
                )
            if not agent.has_heuristic():
                raise bad(
                    f"{where}heuristic: agent {name!r} (class {type(agent).__name__}) "
                    "has no heuristic"
                )
            if name in driven:
                raise bad(
                    f"{where}heuristic: agent {name!r} is driven by the server "
                    "already (rlenv serve --policy)"
                )
        return frozenset(names)


class Claim(Part):
    """``{"agent": NAME, "action": A}`` or ``nil`` (2.6): an observer plays one agent.

    The observer claims agent ``NAME`` of several (or changes the action it holds for the agent
    it claimed) and holds ``A`` until changed; the controller's steps then act for the agent
    with ``A`` (:mod:`rlenv.serving._claims`). ``nil`` releases the observer's claim. It takes
    no control: the controller may not send it.
    """

    name = "claim"
    alone = True
    _KEYS = frozenset({"agent", "action"})

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
        claim, owner = parts["claim"], instance.requester.peer
        if owner is None:
            raise bad(f"{where}claim: a claim comes from a client's connection")
        if claim is None:  # release
            return None
        claim = as_map(claim, "claim", where)
        check_keys(claim, self._KEYS, f"{where}claim")
        agents = [agent.name for agent in instance.agents]
        if not instance.multi_agent:
            raise bad(
                f"{where}claim: this environment has one agent ({agents[0]}), and the "
                "client that controls the environment owns it: claims are for "
                "environments of several agents"
            )
        name = claim.get("agent")
        if name not in agents:
            raise bad(f"{where}claim.agent: no agent {name!r:.40}; the agents: {', '.join(agents)}")
        if instance.driven is not None and name in instance.driven.names:
            raise bad(
                f"{where}claim: agent {name!r} is driven by the server (rlenv serve "
                "--policy); claim another"
            )
        claims = instance.claims
        if claims is not None:
            holder = claims.owners.get(name)
            if holder is not None and holder is not owner:
                raise RequestError(
                    ErrorCode.BUSY,
                    f"{where}claim: agent {name!r} is claimed "
                    f"by another client ({getattr(holder, 'address', '?')}): "
                    "one claim per agent",
                )
            mine = claims.of(owner)
            if mine is not None and mine != name:
                raise bad(
                    f"{where}claim: this client plays {mine!r} already (one claim per "
                    f"client): release it first (claim: nil) to play {name!r}"
                )
        if "action" not in claim:
            raise bad(f"{where}claim.action: the action to hold for {name!r} is missing")
        return name, instance.checked_action.of_agent(name, claim["action"], f"{where}claim.")

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        owner = instance.requester.peer
        if instance.answer.reports:  # type: ignore[union-attr]
            raise bad(
                "claim: this client controls the environment and acts for every agent "
                "itself; claims are for the clients that observe it"
            )
        if value is None:
            instance.release_claim(owner)
        else:
            instance.claim(owner, *value)
