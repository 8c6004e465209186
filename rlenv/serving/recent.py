"""Recent episodes: an instance's last finished episodes, kept as recordings.

An episode is *finished* when the next reset (or restore) starts another. Its
:class:`~rlenv.serving.snapshots.EpisodeLog` is what the instance already built while it ran
(the configuration at its reset, the generator's state, the options, every action and change),
so keeping it costs nothing per step: the instance hands the log over and starts the next
episode in a new one. Nothing is copied or encoded until a client asks (the ``episodes`` part,
protocol 2.5): each kept log then becomes a snapshot, which restores the episode's start on any
server of the same environment and replays to the same observations, bit for bit.

Not kept: an episode without an action, one stopped by an ``environment_error`` (its replay
would fail the same way), one longer than a snapshot may be (its log stopped at
:data:`~rlenv.serving.snapshots.MAX_EVENTS`), and one that ran in real time (its actions
applied between ticks, not as a replay gives them).
"""

from __future__ import annotations

from collections import deque
from typing import Any

from rlenv.serving.snapshots import EpisodeLog

__all__ = ["KEEP_EPISODES", "RecentEpisodes"]

KEEP_EPISODES = 8
"""How many finished episodes an instance keeps by default (``rlenv serve --keep-episodes``)."""


class RecentEpisodes:
    """The logs of an instance's last ``keep`` finished episodes (none when ``keep`` is 0).

    Args:
        keep: how many to keep; the oldest is dropped when another finishes.

    Raises:
        ValueError: ``keep`` is negative.
    """

    __slots__ = ("_kept", "keep")

    def __init__(self, keep: int = KEEP_EPISODES) -> None:
        if keep < 0:
            raise ValueError(f"keep_episodes must be >= 0 (0: keep none), got {keep}")
        self.keep = keep
        self._kept: deque[tuple[EpisodeLog, bool, bool]] = deque(maxlen=keep)

    def __len__(self) -> int:
        return len(self._kept)

    def finished(self, log: EpisodeLog, terminated: bool, truncated: bool) -> bool:
        """Keep ``log``, an episode that ended so (both false: cut short); whether it was kept.

        A log that is kept must not be used again: the instance starts the next episode in a
        new one.
        """
        if not self.keep or log.overflowed or log.timed or not _acted(log.events):
            return False
        self._kept.append((log, terminated, truncated))
        return True

    def to_wire(self, last: int | None = None) -> list[dict[str, Any]]:
        """The kept episodes (the ``last`` ones only, if given), oldest first, as data.

        Each is ``{"snapshot", "terminated", "truncated", "steps"}``; the snapshot holds the
        episode up to its last action (the changes that came after it, the next reset's
        configuration say, belong to no step of it).
        """
        kept = list(self._kept)
        if last is not None:
            kept = kept[-last:]
        entries = []
        for log, terminated, truncated in kept:
            snapshot = log.snapshot()
            events = snapshot["events"]  # a copy of the log's
            while events[-1][0] != "action":  # kept logs have one
                events.pop()
            entries.append({"snapshot": snapshot, "terminated": terminated,
                            "truncated": truncated,
                            "steps": sum(event[0] == "action" for event in events)})
        return entries


def _acted(events: list[list[Any]]) -> bool:
    return any(event[0] == "action" for event in events)
