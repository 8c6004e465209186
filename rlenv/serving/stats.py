"""Episode statistics: what the controlling client's episodes came to, kept for inspectors.

An instance counts the rewards, steps and ticks it reports to its controller, and closes the
episode's record when the episode ends (``terminated`` / ``truncated``), when a reset cuts it
short (``reset``: the client's time limit, say), or when user code fails (``error``). An
observer reads them with ``{"inspect": {"stats": {"since": n}}}``: the records numbered ``n`` and
later (the last :data:`KEPT`), the totals, and the episode under way.
"""

from __future__ import annotations

from collections import deque
from itertools import islice
from typing import Any

__all__ = ["KEPT", "EpisodeStats"]

KEPT = 1000
"""How many finished episodes the server remembers."""


class EpisodeStats:
    """Running totals and the last :data:`KEPT` finished episodes of one instance.

    Args:
        agents: the agents' names when there are several (returns are then kept per agent).
    """

    __slots__ = ("_agents", "_length", "_open", "_returns", "_ticks", "errors", "episodes",
                 "finished", "steps", "ticks")

    def __init__(self, agents: list[str] | None = None) -> None:
        self._agents = agents
        self.finished: deque[dict[str, Any]] = deque(maxlen=KEPT)
        self.episodes = 0  # finished so far (the number the next one gets)
        self.steps = 0  # actions reported, all episodes
        self.ticks = 0
        self.errors = 0  # environment errors
        self._open = False
        self._returns = dict.fromkeys(agents or ["agent"], 0.0)
        self._length = 0
        self._ticks = 0

    def begin(self) -> None:
        """A new episode starts; one under way (that acted) ends as cut short by a reset."""
        if self._open and self._length:
            self.end("reset")
        self._open = True
        for name in self._returns:
            self._returns[name] = 0.0
        self._length = self._ticks = 0

    def reported(self, reward: float, ticks: int, acted: bool) -> None:
        """An answer reported ``reward`` and ``ticks`` to the controller (one agent)."""
        self._returns["agent"] += reward
        self._ticks += ticks
        self._length += acted
        self.ticks += ticks
        self.steps += acted

    def reported_agents(self, rewards: dict[str, float], ticks: int, acted: bool) -> None:
        """As :meth:`reported`, with several agents' rewards."""
        returns = self._returns
        for name, reward in rewards.items():
            returns[name] += reward
        self._ticks += ticks
        self._length += acted
        self.ticks += ticks
        self.steps += acted

    def end(self, how: str) -> None:
        """The episode under way ended: ``terminated``, ``truncated``, ``reset`` or ``error``."""
        self.errors += how == "error"
        if not self._open:
            return
        self._open = False
        record: dict[str, Any] = {"episode": self.episodes, "return": sum(self._returns.values()),
                                  "length": self._length, "ticks": self._ticks, "end": how}
        if self._agents:
            record["returns"] = dict(self._returns)
        self.finished.append(record)
        self.episodes += 1

    def since(self, first: int) -> dict[str, Any]:
        """The finished episodes numbered ``first`` and later (those still kept), and totals."""
        skip = max(first - (self.episodes - len(self.finished)), 0)
        current: dict[str, Any] | None = None
        if self._open:
            current = {"return": sum(self._returns.values()), "length": self._length,
                       "ticks": self._ticks}
            if self._agents:
                current["returns"] = dict(self._returns)
        return {"episodes": list(islice(self.finished, skip, None)), "next": self.episodes,
                "steps": self.steps, "ticks": self.ticks, "errors": self.errors,
                "current": current}
