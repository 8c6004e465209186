"""Recent episodes: an instance's last finished episodes, kept as recordings.

An episode is *finished* when the next reset (or restore) starts another. Its
:class:`~rlenv.serving._snapshots.EpisodeLog` is what the instance already built while it ran
(the configuration at its reset, the generator's state, the options, every action and change),
so keeping it costs nothing per step: the instance hands the log over and starts the next
episode in a new one. Nothing is copied or encoded until a client asks (the ``episodes`` part,
protocol 2.5; by index and in pages since 2.6): each kept log then becomes a snapshot, which
restores the episode's start on any server of the same environment and replays to the same
observations, bit for bit.

**What is kept.** Nothing, until someone asks: an instance starts keeping at the first
``episodes`` request it gets (an inspector's, say), unless the server was told to keep from the
start (``rlenv serve --keep-episodes N``) or never (``--keep-episodes 0``). Then at most ``keep``
episodes (:data:`KEEP_EPISODES` by default) holding at most ``max_events`` events in all (the
server's :data:`KEEP_EVENTS`, shared among its instances): the oldest go first.

**What is served.** ``{"index": true}`` lists the kept episodes without their events (an
``id`` each, that stays the episode's while it is kept); ``{"episode": id, "from": k}`` is one
page of one: its snapshot with at most :data:`PAGE_EVENTS` events from the ``k``-th on. No
answer holds more than a page, so none is refused for its size, and an observer fetching a
long episode takes turns with the controller's steps. The 2.5 forms (``{}``, ``{"last": n}``)
still answer whole snapshots, up to :data:`WHOLE_EVENTS` events in all.

Not kept: an episode without an action, one stopped by an ``environment_error`` (its replay
would fail the same way), one longer than a snapshot may be (its log stopped at
:data:`~rlenv.serving._snapshots.MAX_EVENTS`) or than ``max_events``, and one that ran in real
time (its actions applied between ticks, not as a replay gives them).
"""

from __future__ import annotations

from collections import deque
from typing import Any

from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.protocol.snapshots import PAGE_EVENTS, WHOLE_EVENTS
from rlenv.serving._snapshots import EpisodeLog

__all__ = ["KEEP_EPISODES", "KEEP_EVENTS", "PAGE_EVENTS", "WHOLE_EVENTS", "RecentEpisodes"]

KEEP_EPISODES = 8
"""How many finished episodes an instance keeps once asked (``rlenv serve --keep-episodes``)."""

KEEP_EVENTS = 200_000
"""Most events (actions and changes: about steps) a server keeps in all, its instances sharing
them (some 40 MB at 200 bytes a step)."""


class _Kept:
    __slots__ = ("id", "log", "steps", "stop", "terminated", "truncated")

    def __init__(self, identifier: int, log: EpisodeLog, terminated: bool, truncated: bool) -> None:
        events = log.events
        stop = len(events)
        while events[stop - 1][0] != "action":  # the events after its last action are no step's
            stop -= 1
        self.id, self.log, self.stop = identifier, log, stop
        self.terminated, self.truncated = terminated, truncated
        self.steps = sum(event[0] == "action" for event in events)

    def entry(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "terminated": self.terminated,
            "truncated": self.truncated,
            "steps": self.steps,
            "events": self.stop,
        }


class RecentEpisodes:
    """The logs of an instance's last finished episodes (see the module docstring).

    Args:
        keep: how many to keep at most (0: none, ever).
        max_events: how many events they may hold in all.
        eager: keep from the start (else from the first :meth:`start`).

    Raises:
        ValueError: ``keep`` or ``max_events`` is negative.
    """

    __slots__ = ("_events", "_kept", "_next_id", "keep", "keeping", "max_events")

    def __init__(
        self, keep: int = KEEP_EPISODES, max_events: int = KEEP_EVENTS, eager: bool = False
    ) -> None:
        if keep < 0:
            raise ValueError(f"keep_episodes must be >= 0 (0: keep none), got {keep}")
        if max_events < 0:
            raise ValueError(f"max_events must be >= 0, got {max_events}")
        self.keep, self.max_events = keep, max_events
        self.keeping = eager and keep > 0
        self._kept: deque[_Kept] = deque()
        self._events = 0  # events held by the kept logs
        self._next_id = 0

    def __len__(self) -> int:
        return len(self._kept)

    def start(self) -> None:
        """Keep the episodes that finish from now on (a client asked for them)."""
        self.keeping = self.keep > 0

    def finished(self, log: EpisodeLog, terminated: bool, truncated: bool) -> bool:
        """Keep ``log``, an episode that ended so (both false: cut short); whether it was kept.

        A log that is kept must not be used again: the instance starts the next episode in a
        new one.
        """
        if (
            not self.keeping
            or log.overflowed
            or log.timed
            or len(log.events) > self.max_events
            or not _acted(log.events)
        ):
            return False
        kept = _Kept(self._next_id, log, terminated, truncated)
        self._next_id += 1
        self._kept.append(kept)
        self._events += len(log.events)
        while len(self._kept) > self.keep or self._events > self.max_events:
            self._events -= len(self._kept.popleft().log.events)
        return True

    def index(self) -> list[dict[str, Any]]:
        """The kept episodes, oldest first, without their events (the ``index`` form, 2.6).

        Each is ``{"id", "terminated", "truncated", "steps", "events"}``: ``events`` is how
        many its snapshot holds (to its last action), what :meth:`page` serves.
        """
        return [kept.entry() for kept in self._kept]

    def page(self, identifier: int, start: int) -> dict[str, Any] | None:
        """One page of the kept episode ``identifier`` (``None``: not kept, or no longer).

        The answer is :meth:`index`'s entry with ``from`` (``start``) and ``snapshot``: the
        episode's snapshot holding at most :data:`PAGE_EVENTS` of its events, from ``start``.
        """
        kept = next((kept for kept in self._kept if kept.id == identifier), None)
        if kept is None:
            return None
        stop = min(kept.stop, start + PAGE_EVENTS)
        return {
            **kept.entry(),
            "from": start,
            "snapshot": kept.log.snapshot(slice(min(start, stop), stop)),
        }

    def to_wire(self, last: int | None = None) -> list[dict[str, Any]]:
        """The kept episodes (the ``last`` ones only, if given), oldest first, whole (2.5).

        Each is ``{"snapshot", "id", "terminated", "truncated", "steps"}`` (``id`` since 2.6);
        the snapshot holds the episode up to its last action (the changes that came after it,
        the next reset's configuration say, belong to no step of it).

        Raises:
            RequestError: ``bad_request``: they hold more than :data:`WHOLE_EVENTS` events.
        """
        kept = list(self._kept)
        if last is not None:
            kept = kept[-last:]
        events = sum(entry.stop for entry in kept)
        if events > WHOLE_EVENTS:
            raise RequestError(
                ErrorCode.BAD_REQUEST,
                f"these episodes hold {events:,} events, "
                f"more than one answer carries ({WHOLE_EVENTS:,}); ask for "
                'fewer (last), or page them (protocol 2.6: {"index": true}, '
                'then {"episode": ID, "from": K})',
            )
        return [
            {
                "snapshot": entry.log.snapshot(slice(0, entry.stop)),
                "id": entry.id,
                "terminated": entry.terminated,
                "truncated": entry.truncated,
                "steps": entry.steps,
            }
            for entry in kept
        ]


def _acted(events: list[list[Any]]) -> bool:
    return any(event[0] == "action" for event in events)
