"""Episode statistics: what the controlling client's episodes came to, kept for inspectors.

An instance counts the rewards, steps and ticks it reports to its controller, and closes the
episode's record when the episode ends (``terminated`` / ``truncated``), when a reset cuts it
short (``reset``: the client's time limit, say), or when user code fails (``error``). An
observer reads them with ``{"inspect": {"stats": {"since": n}}}``: the records numbered ``n`` and
later (the last :data:`KEPT`), the totals, and the episode under way.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
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

    __slots__ = (
        "_agents",
        "_length",
        "_open",
        "_return",
        "_returns",
        "_steps",
        "_ticks",
        "_total_ticks",
        "episodes",
        "errors",
        "finished",
    )

    def __init__(self, agents: list[str] | None = None) -> None:
        self._agents = agents
        self.finished: deque[dict[str, Any]] = deque(maxlen=KEPT)
        self.episodes = 0  # finished so far (the number the next one gets)
        self.errors = 0  # environment errors
        self._steps = self._total_ticks = 0  # of the finished episodes
        self._open = False
        self._return = 0.0  # the episode under way (one agent; several: _returns)
        self._returns = dict.fromkeys(agents or (), 0.0)
        self._length = self._ticks = 0

    def begin(self) -> None:
        """A new episode starts; one under way (that acted) ends as cut short by a reset."""
        if self._open and self._length:
            self.end("reset")
        self._total_ticks += self._ticks  # an episode that never acted is no record
        self._open = True
        self._return = 0.0
        for name in self._returns:
            self._returns[name] = 0.0
        self._length = self._ticks = 0

    def reported(self, reward: float, ticks: int, acted: bool) -> None:
        """An answer reported ``reward`` and ``ticks`` to the controller (one agent)."""
        self._return += reward
        self._ticks += ticks
        self._length += acted

    def reported_agents(self, rewards: Mapping[str, float | None], ticks: int, acted: bool) -> None:
        """As :meth:`reported`, with several agents' rewards."""
        returns = self._returns
        for name, reward in rewards.items():
            if reward is not None:  # None: an agent's first transition (it just joined)
                returns[name] += reward
        self._ticks += ticks
        self._length += acted

    def end(self, how: str) -> None:
        """The episode under way ended: ``terminated``, ``truncated``, ``reset`` or ``error``."""
        self.errors += how == "error"
        if not self._open:
            return
        self._open = False
        self.finished.append({"episode": self.episodes, **self._current(), "end": how})
        self.episodes += 1
        self._steps += self._length
        self._total_ticks += self._ticks
        self._length = self._ticks = 0

    def since(self, first: int) -> dict[str, Any]:
        """The finished episodes numbered ``first`` and later (those still kept), and totals."""
        skip = max(first - (self.episodes - len(self.finished)), 0)
        return {
            "episodes": list(islice(self.finished, skip, None)),
            "next": self.episodes,
            "steps": self._steps + self._length,
            "ticks": self._total_ticks + self._ticks,
            "errors": self.errors,
            "current": self._current() if self._open else None,
        }

    def _current(self) -> dict[str, Any]:
        """The episode under way: its return (per agent too), length and ticks."""
        if self._agents:
            return {
                "return": sum(self._returns.values()),
                "length": self._length,
                "ticks": self._ticks,
                "returns": dict(self._returns),
            }
        return {"return": self._return, "length": self._length, "ticks": self._ticks}
