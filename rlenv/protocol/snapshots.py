"""The snapshot format, as both ends read it: its version, its bound and its structure.

A snapshot (``docs/protocol.md``, *Snapshots and introspection*) is plain data: the settings at
a reset, the generator's state as JSON, the reset's options and the events since::

    {"version": 1, "config": {"environment": {...}, "agent": {...}, "world": {...}},
     "rng": "<the generator's state, as JSON>", "options": {...},
     "events": [["config", {...}], ["action", action, frames], ["action", action, frames, true],
                ["set", node path, property, value], ...]}

:func:`parse_snapshot` checks the structure (a server before it restores one, a client before
it keeps a recording); what it means, the environment checks when it restores
(:mod:`rlenv.serving._snapshots` records and replays them).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rlenv.protocol.errors import ErrorCode, RequestError

__all__ = ["MAX_EVENTS", "PAGE_EVENTS", "SNAPSHOT_VERSION", "WHOLE_EVENTS", "parse_snapshot"]

SNAPSHOT_VERSION = 1
MAX_EVENTS = 100_000
"""Most events a snapshot holds. The log of a longer episode stops there (bounded memory:
an endless episode would otherwise grow its log forever) and its snapshots are refused."""

PAGE_EVENTS = 2_000
"""Most events one answer of the ``episodes`` part's paged form (2.6) holds."""

WHOLE_EVENTS = 20_000
"""Most events an answer of the ``episodes`` part's whole forms holds in all (beyond: refused,
saying to page)."""


def parse_snapshot(snapshot: Any) -> dict[str, Any]:
    """Check a snapshot's structure (not its content, which the environment checks).

    Raises:
        RequestError: ``bad_request`` naming the field.
    """

    def bad(message: str) -> RequestError:
        return RequestError(ErrorCode.BAD_REQUEST, f"restore: {message}")

    if not isinstance(snapshot, Mapping):
        raise bad("a snapshot is a map")
    expected = {"version", "config", "rng", "options", "events"}
    if set(snapshot) != expected:
        raise bad(f"a snapshot has exactly the keys {sorted(expected)}")
    if snapshot["version"] != SNAPSHOT_VERSION:
        raise bad(f"snapshot version {snapshot['version']!r:.20} is not {SNAPSHOT_VERSION}")
    config = snapshot["config"]
    if not isinstance(config, Mapping) or not all(isinstance(v, Mapping) for v in config.values()):
        raise bad("config must map parts to maps")
    if not isinstance(snapshot["rng"], str) or not isinstance(snapshot["options"], Mapping):
        raise bad("rng must be a string and options a map")
    events = snapshot["events"]
    if not isinstance(events, list) or len(events) > MAX_EVENTS:
        raise bad(f"events must be a list of at most {MAX_EVENTS}")
    for index, event in enumerate(events):
        valid = isinstance(event, list) and (
            (len(event) == 2 and event[0] == "config" and isinstance(event[1], Mapping))
            or (
                len(event) in (3, 4)
                and event[0] == "action"
                and type(event[2]) is int
                and event[2] >= 1
                and event[3:] in ([], [True])  # true: the step goes on (driven agents decided)
            )
            or (
                len(event) == 4
                and event[0] == "set"
                and isinstance(event[1], str)
                and isinstance(event[2], str)
            )
        )
        if not valid:
            raise bad(
                f"events[{index}] must be ['config', map], ['action', action, frames] "
                "or ['set', path, property, value]"
            )
    return dict(snapshot)
