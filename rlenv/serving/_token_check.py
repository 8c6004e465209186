"""The token check of an endpoint's clients: each first request's token, wrong ones held.

Every token is compared, in constant time (``hmac.compare_digest``): the right one is let in
whatever its address sent before. A wrong one's refusal is held as long as its address's
penalty says (:mod:`rlenv.serving._penalties`), with at most :data:`_HELD_IN_ALL` refusals held
at once, all addresses together; :meth:`TokenCheck.release_due` sends those that are due and
closes their connections. :class:`~rlenv.serving._connections.Connections` asks it.
"""

from __future__ import annotations

import heapq
import hmac
import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

from rlenv.protocol import ErrorReply
from rlenv.protocol.errors import LocalProtocolError
from rlenv.serving._penalties import Penalties

if TYPE_CHECKING:
    from rlenv.serving._connections import Peer

__all__ = ["TokenCheck"]

logger = logging.getLogger(__name__)

_HELD_IN_ALL = 64  # wrong-token answers held at once, all addresses together


class TokenCheck:
    """Which first requests' tokens are refused, and the wrong tokens' held refusals.

    Args:
        token: the secret the client's first request must carry (``None``: no token needed).
        clock: monotonic time in seconds (injectable for tests).
    """

    def __init__(self, token: str | None, clock: Callable[[], float]) -> None:
        self._token = token
        self._clock = clock
        self._penalties = Penalties(clock)
        self._held: list[tuple[float, int, Peer, ErrorReply]] = []  # wrong tokens' answers
        self._held_count = 0  # a tie-breaker for the heap

    def refusal(self, peer: Peer, token: str | None) -> tuple[str | None, float]:
        """Why ``token`` is refused, or None; and how long to hold the refusal (seconds)."""
        if self._token is None:
            return None, 0.0
        if token is None:
            logger.warning("client %s: refused, no token", peer.address)
            return (
                "this server requires a token: pass token=... to the client (or set RLENV_TOKEN)",
                0.0,
            )
        if not hmac.compare_digest(token.encode(), self._token.encode()):
            return "wrong token", self._penalties.failed(peer.host)
        return None, 0.0

    def may_compare(self, peer: Peer) -> bool:
        """Whether ``peer``'s token may be compared now (its address holds few answers)."""
        return len(self._held) < _HELD_IN_ALL and self._penalties.may_compare(peer.host)

    def hold(self, peer: Peer, refusal: ErrorReply, delay: float) -> None:
        """Answer ``peer``'s wrong token after ``delay`` seconds (it left its slot already)."""
        self._penalties.hold(peer.host)
        self._held_count += 1
        heapq.heappush(self._held, (self._clock() + delay, self._held_count, peer, refusal))

    def release_due(self) -> bool:
        """Send the held refusals that are due, and close their connections; whether any was."""
        now = self._clock()
        released = False
        while self._held and self._held[0][0] <= now:
            _, _, peer, refusal = heapq.heappop(self._held)
            try:
                peer.sock.sendall(peer.connection.send(refusal))
            except (OSError, LocalProtocolError):
                pass  # it left meanwhile: nothing to tell
            peer.sock.close()
            self._penalties.release(peer.host)
            released = True
        return released

    def next_release(self) -> float | None:
        """When the next held refusal is due."""
        return self._held[0][0] if self._held else None

    def close(self) -> None:
        """Close the connections whose refusals are held, unanswered."""
        for _, _, peer, _ in self._held:
            peer.sock.close()
        self._held.clear()
