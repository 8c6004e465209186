"""Slowing down token guessing: a penalty per peer address that grows with wrong tokens.

Shared by the TCP endpoint (:mod:`rlenv.serving.connections`) and the HTTP gateway's door
(:mod:`rlenv.http.guard`), as OpenSSH's ``PerSourcePenalties`` does for failed logins: the first
:data:`FREE_FAILURES` wrong tokens of an address cost nothing (a person mistyping); each one after
that refuses the address for twice as long as the one before (1 s, 2 s, 4 s ... up to
:data:`MAX_PENALTY`), its requests turned away without their token being compared. An address
is forgiven one failure per :data:`FORGIVE_AFTER` seconds without one, and all of them by the
right token. Other addresses are never affected. Every wrong token is logged with the address
(never the token); only as many as the penalties let through can be tried.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

__all__ = ["FORGIVE_AFTER", "FREE_FAILURES", "MAX_PENALTY", "Penalties", "refusal"]

logger = logging.getLogger(__name__)

FREE_FAILURES = 5
"""Wrong tokens an address may send before it is made to wait."""
MAX_PENALTY = 300.0
"""The longest an address is refused for, in seconds."""
FORGIVE_AFTER = 60.0
"""Seconds without a wrong token after which an address is forgiven one."""
_ADDRESSES = 4096  # addresses remembered at most (bounded against many addresses)


def refusal(address: str, wait: int) -> str:
    """What an address told to wait ``wait`` seconds reads."""
    return f"too many wrong tokens from {address}: try again in {wait} s"


class _Record:
    __slots__ = ("failures", "last", "until")

    def __init__(self) -> None:
        self.failures = 0
        self.last = 0.0  # when the last wrong token came
        self.until = 0.0  # when the penalty ends


class Penalties:
    """The penalties of the addresses that sent wrong tokens (see the module docstring).

    Args:
        clock: monotonic time in seconds (injectable for tests).
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._records: dict[str, _Record] = {}

    def wait(self, address: str) -> int:
        """Seconds (rounded up) ``address`` must wait before its token is checked (0: none)."""
        record = self._records.get(address)
        if record is None:
            return 0
        wait = math.ceil(record.until - self._clock())
        if wait > 0:
            logger.debug("refused %s: it waits %d s more", address, wait)
        return max(0, wait)

    def failed(self, address: str) -> None:
        """Count a wrong token from ``address`` (and log it); past the free ones, it waits."""
        now = self._clock()
        record = self._records.get(address)
        if record is None:
            if len(self._records) >= _ADDRESSES:
                self._forget_some(now)
            record = self._records[address] = _Record()
        forgiven = int((now - record.last) / FORGIVE_AFTER) if record.failures else 0
        record.failures = max(0, record.failures - forgiven) + 1
        record.last = now
        beyond = record.failures - FREE_FAILURES
        if beyond <= 0:
            logger.warning("wrong token from %s (%d in a row)", address, record.failures)
            return
        penalty = min(MAX_PENALTY, 2.0 ** (beyond - 1))
        record.until = now + penalty
        logger.warning("wrong token from %s (%d in a row): its requests are refused for %g s",
                       address, record.failures, penalty)

    def succeeded(self, address: str) -> None:
        """``address`` sent the right token: its failures are forgotten."""
        self._records.pop(address, None)

    def _forget_some(self, now: float) -> None:
        """Make room: forget the addresses no longer waiting (and the oldest quarter if all are)."""
        waiting = {address: record for address, record in self._records.items()
                   if record.until > now}
        if len(waiting) >= _ADDRESSES // 2:
            waiting = dict(list(waiting.items())[_ADDRESSES // 4:])
        self._records = waiting
