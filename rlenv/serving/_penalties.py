"""Slowing down token guessing: the guesser is slowed, never the address's rightful user.

Shared by the TCP endpoint (:mod:`rlenv.serving._connections`) and the HTTP gateway's door
(:mod:`rlenv_tools.http._guard`). Every token is compared, in constant time
(``hmac.compare_digest``), so a request with the right token is served whatever others on its
address sent. What a wrong token costs is the answer that says so:

- **Its answer is held.** The first :data:`FREE_FAILURES` wrong tokens of an address are
  answered at once (a person mistyping); each one after that is answered only after a delay
  twice as long as the one before (1 s, 2 s, 4 s ... up to :data:`MAX_PENALTY`). A guesser
  learns nothing of a guess before its answer.
- **Few guesses at a time.** An address may have at most :data:`MAX_HELD` answers held at once;
  while it has that many, the TCP server compares none of its new tokens (their connections
  wait, greeted, in their slots; the next is compared when a held answer goes out), so an
  address compares at most :data:`MAX_HELD` guesses per delay however many connections it
  opens (and with 64 answers held in all, no address's token is compared until one goes out:
  a wait, never a refusal). The gateway holds each wrong answer as long, on a connection of
  its own (bounded by its open connections), and never delays a right one.
- **Forgiving.** An address is forgiven one failure per :data:`FORGIVE_AFTER` seconds without
  one; the right token forgives nothing (a busy token holder beside a guesser must not renew
  the guesser's free tries).

Every wrong token is logged with the address (never the token). Other addresses are never
affected.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

__all__ = ["FORGIVE_AFTER", "FREE_FAILURES", "MAX_HELD", "MAX_PENALTY", "Penalties"]

logger = logging.getLogger(__name__)

FREE_FAILURES = 5
"""Wrong tokens an address may send before their answers are held."""
MAX_PENALTY = 8.0
"""The longest a wrong token's answer is held, in seconds."""
MAX_HELD = 4
"""Wrong tokens of one address whose answers may be held at once (TCP: beyond, none is
compared until one goes out)."""
FORGIVE_AFTER = 60.0
"""Seconds without a wrong token after which an address is forgiven one."""
_ADDRESSES = 4096  # addresses remembered at most (bounded against many addresses)


class _Record:
    __slots__ = ("failures", "held", "last")

    def __init__(self) -> None:
        self.failures = 0
        self.last = 0.0  # when the last wrong token came
        self.held = 0  # wrong answers held now


class Penalties:
    """What the wrong tokens of each address cost (see the module docstring).

    Args:
        clock: monotonic time in seconds (injectable for tests).
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._records: dict[str, _Record] = {}

    def may_compare(self, address: str) -> bool:
        """Whether a token from ``address`` may be compared now (fewer than MAX_HELD held)."""
        record = self._records.get(address)
        return record is None or record.held < MAX_HELD

    def failed(self, address: str) -> float:
        """Count a wrong token from ``address`` (and log it); seconds to hold its answer."""
        now = self._clock()
        record = self._records.get(address)
        if record is None:
            if len(self._records) >= _ADDRESSES:
                self._forget_some()
            record = self._records[address] = _Record()
        forgiven = int((now - record.last) / FORGIVE_AFTER) if record.failures else 0
        record.failures = max(0, record.failures - forgiven) + 1
        record.last = now
        beyond = record.failures - FREE_FAILURES
        if beyond <= 0:
            logger.warning("wrong token from %s (%d in a row)", address, record.failures)
            return 0.0
        delay = min(MAX_PENALTY, 2.0 ** (beyond - 1))
        logger.warning(
            "wrong token from %s (%d in a row): answered in %g s", address, record.failures, delay
        )
        return delay

    def hold(self, address: str) -> None:
        """A wrong answer to ``address`` is held (until :meth:`release`)."""
        record = self._records.get(address)
        if record is None:
            record = self._records[address] = _Record()
        record.held += 1

    def release(self, address: str) -> None:
        """A held wrong answer to ``address`` went out (or its client left)."""
        record = self._records.get(address)
        if record is not None and record.held > 0:
            record.held -= 1

    def _forget_some(self) -> None:
        """Make room: forget addresses holding nothing (the oldest quarter if all hold some)."""
        kept = {address: record for address, record in self._records.items() if record.held}
        if len(kept) >= _ADDRESSES // 2:
            kept = dict(list(kept.items())[_ADDRESSES // 4 :])
        self._records = kept
