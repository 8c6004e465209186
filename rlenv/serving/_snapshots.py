"""EpisodeLog: what it takes to rebuild the current state exactly, as data.

rlenv simulations are deterministic, so the state of an environment is fully determined by its
configuration when the episode began, the random generator's state at the reset, the reset's
options, and what happened since (actions and mid-episode configuration). A snapshot is exactly
that, as plain msgpack-able data; restoring it resets a (fresh) environment and replays the
events, which reproduces the state bit for bit, the pymunk solver's warm-start included, and
never executes anything it carries: the configuration goes through the same checks as a
client's, the actions through the action space's.

Snapshot format (``version`` 1)::

    {"version": 1, "config": {"environment": {...}, "agent": {...}, "world": {...}},
     "rng": "<the generator's state, as JSON>", "options": {...},
     "events": [["config", {...}], ["action", action, frames],
                ["set", node path, property, value], ...]}

``config`` is a ``config`` part that sets everything again (:meth:`Settings.state
<rlenv.serving._settings.Settings.state>`): its ``agent`` holds the one agent's settings or,
with several agents, each agent's by name (protocol 2.6; before, one map, the first agent's,
which restores on every agent as it always did).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.protocol.snapshots import MAX_EVENTS, SNAPSHOT_VERSION, parse_snapshot

if TYPE_CHECKING:
    from rlenv.serving._settings import Captured

__all__ = ["MAX_EVENTS", "EpisodeLog", "generator_from_state", "parse_snapshot"]

_BIT_GENERATORS = {"PCG64": np.random.PCG64}


class EpisodeLog:
    """Records the current episode as it happens; see the module docstring."""

    def __init__(self) -> None:
        self._config: Captured | None = None
        self._rng_state: Mapping[str, Any] = {}
        self.options: Mapping[str, Any] = {}
        self.events: list[list[Any]] = []
        self.started = False
        self.overflowed = False  # the episode has more events than a snapshot may hold
        self.timed = False  # it ran in real time, at least for a while (no replay gives it)

    @property
    def config(self) -> dict[str, dict[str, Any]]:
        """The configuration at the reset (``{}`` before the first)."""
        return {} if self._config is None else self._config.state()

    def begin(self, config: Captured, rng: np.random.Generator, options: Mapping[str, Any]) -> None:
        """A reset: remember the configuration and the generator as they are now."""
        self._config = config  # as a map only when a snapshot asks
        self._rng_state = rng.bit_generator.state  # as JSON only when a snapshot asks
        self.options = dict(options)
        self.events = []
        self.started = True
        self.overflowed = False
        self.timed = False

    def configured(self, config: Mapping[str, Any]) -> None:
        """Configuration applied during the episode."""
        if self.started:
            self.record(["config", dict(config)])

    def acted(self, action: Any, frames: int, goes_on: bool = False) -> None:
        """An action that ran ``frames`` ticks at most.

        ``goes_on``: the actions of driven agents that decided in the server while the step
        went on (agents that decide at their own pace); logged as ``[..., true]``.
        """
        event = ["action", action, frames, True] if goes_on else ["action", action, frames]
        if len(self.events) < MAX_EVENTS and not self.overflowed:  # record()'s common case
            self.events.append(event)
        else:
            self.record(event)

    def record(self, event: list[Any]) -> None:
        """Append ``event``; past :data:`MAX_EVENTS`, forget them all and remember why."""
        if self.overflowed:
            return
        if len(self.events) >= MAX_EVENTS:
            self.events = []
            self.overflowed = True
            return
        self.events.append(event)

    def snapshot(self, events: slice | None = None) -> dict[str, Any]:
        """The episode so far, as data (see :meth:`check_snapshot` for when it is refused).

        Args:
            events: only these of its events (a page of a kept episode's, say); all if
                ``None``.
        """
        self.check_snapshot()
        return {
            "version": SNAPSHOT_VERSION,
            "config": self.config,
            "rng": json.dumps(self._rng_state),
            "options": self.options,
            "events": list(self.events) if events is None else self.events[events],
        }

    def check_snapshot(self) -> None:
        """Refuse a snapshot that cannot be taken.

        Raises:
            RequestError: ``reset_required`` before any episode; ``bad_request`` when the
                episode has more than :data:`MAX_EVENTS` events.
        """
        if not self.started:
            raise RequestError(
                ErrorCode.RESET_REQUIRED, "no episode has started; nothing to snapshot"
            )
        if self.overflowed:
            raise RequestError(
                ErrorCode.BAD_REQUEST,
                f"this episode is too long to snapshot: "
                f"more than {MAX_EVENTS:,} actions and changes since its reset "
                "(snapshot earlier, or reset)",
            )


def generator_from_state(state: str) -> np.random.Generator:
    """A generator in the state a snapshot recorded (JSON data, never code).

    Raises:
        RequestError: ``bad_request`` when the state is not a valid generator state.
    """
    try:
        parsed = json.loads(state)
        bit_generator = _BIT_GENERATORS[parsed["bit_generator"]]()
        bit_generator.state = parsed
    except (ValueError, TypeError, KeyError, OverflowError) as error:
        raise RequestError(ErrorCode.BAD_REQUEST, f"restore: invalid rng state ({error})") from None
    return np.random.Generator(bit_generator)
