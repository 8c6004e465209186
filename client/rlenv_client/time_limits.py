"""Time limits kept on the client's side, for several agents too.

A time limit that a client keeps (``RemoteEnv``'s and ``RemoteVectorEnv``'s
``max_episode_steps``, the HTTP gateway's) cuts the episode of every agent still in it: the
joint episode is then truncated, and so is each of those agents in ``info["agents"]``, so that
the per-agent flags agree with the joint ones (``docs/several-agents.md``, "When the episode
ends"); a group's members in play are truncated in its ``truncated`` array.
"""

from __future__ import annotations

from typing import Any

__all__ = ["truncate_agents"]


def truncate_agents(info: dict[str, Any]) -> dict[str, Any]:
    """``info`` with every agent still in the episode marked truncated in ``info["agents"]``.

    Agents whose episode had already ended keep their flags; so do a group's members
    (protocol 2.7: its outcome is arrays over them), those in the answer that are still in
    play being truncated. An ``info`` without ``agents`` (one agent) is returned as it is;
    otherwise a copy (``info`` itself is left unchanged).
    """
    agents = info.get("agents")
    if not agents:
        return info
    return {**info, "agents": {name: _truncated(outcome) for name, outcome in agents.items()}}


def _truncated(outcome: dict[str, Any]) -> dict[str, Any]:
    """One agent's outcome, truncated unless it ended (a group's: each member's row)."""
    if "joined" in outcome:  # a group's, one row per member
        playing = outcome["active"] & ~(outcome["terminated"] | outcome["truncated"])
        return {**outcome, "truncated": outcome["truncated"] | playing}
    if outcome["terminated"] or outcome["truncated"]:
        return outcome
    return {**outcome, "truncated": True}
