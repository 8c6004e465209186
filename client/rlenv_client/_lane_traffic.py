"""A client's traffic through its shared-memory lane: the request in the slots and its answer.

:class:`LaneTraffic` is what a :class:`~rlenv_client.client.Client` holds once its lane is open
(:mod:`rlenv_client._lane_opening`): it writes a request, a step or a ``steps`` request into
the lane's slots and rings the server, keeps the kind of the request sent that way until it
is answered, and says whether the answer is in the slots, waits for it and reads it. Every
request and answer is noted on the client's sans-IO connection, as the socket's are, so that
the two ways in stay in order. An answer that does not fit the slots comes on the socket.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rlenv.protocol import Connection, Reply, Request
from rlenv.protocol.shared_memory import STEP, STEPS
from rlenv.transport.lanes import Lane, wait_for
from rlenv.transport.sockets import AnswerWaiter

__all__ = ["LaneTraffic"]


class LaneTraffic:
    """The requests that go through ``lane``, noted on ``connection``.

    Args:
        lane: the client's open lane.
        connection: the client's connection, where the lane's requests and answers are noted.
        waiter: the client's answer waiter (it spins after a request, then sleeps).
    """

    def __init__(self, lane: Lane, connection: Connection, waiter: AnswerWaiter) -> None:
        self.lane = lane
        self._connection = connection
        self._waiter = waiter
        self.kind = 0
        """The kind of the request sent by the lane, until it is answered (0: none)."""
        self._answers = 0  # the lane's answer sequence number last read

    def send(self, request: Request) -> bool:
        """Write ``request`` into the slots, if it fits them; whether it was sent."""
        kind = self.lane.slots.write_request(request)
        if kind:
            self._rang(request.id, kind)
        return bool(kind)

    def send_step(self, request_id: int, action: Any, repeat_action: int | None) -> bool:
        """Write a step straight into the slots, if its action fits; whether it was sent."""
        if not self.lane.slots.write_step(request_id, action, repeat_action):
            return False
        self._rang(request_id, STEP)
        return True

    def send_steps(
        self, request_id: int, action: Any, reset: np.ndarray | None, repeat_action: int | None
    ) -> bool:
        """Write a ``steps`` request straight into the slots, if it fits; whether it was sent."""
        if not self.lane.slots.write_steps(request_id, action, reset, repeat_action):
            return False
        self._rang(request_id, STEPS)
        return True

    def arrived(self) -> bool:
        """Whether the slots hold the answer to the lane's request."""
        return bool(self.kind) and self.lane.slots.answer_sequence != self._answers

    def wait(self, timeout: float) -> bool:
        """Wait for the answer to the lane's request; whether it is in the slots.

        Otherwise the socket has bytes: an answer that did not fit, an error, or the end.

        Raises:
            BlockingIOError: ``timeout`` seconds passed.
            LaneClosed: the server closed the lane.
            OSError: waiting failed.
        """
        slots = self.lane.slots
        return wait_for(
            lambda: slots.answer_sequence != self._answers, self.lane, self._waiter, timeout
        )

    def read(self, copy: bool) -> Reply:
        """The answer in the slots, noted on the connection.

        Raises:
            LocalProtocolError: it answers no request the connection awaits.
        """
        kind, self.kind = self.kind, 0
        slots = self.lane.slots
        self._answers = slots.answer_sequence
        reply = slots.read_answer(kind, copy)
        self._connection.note_reply(reply.id)  # type: ignore[arg-type]
        return reply

    def _rang(self, request_id: int, kind: int) -> None:
        """The lane's slots hold request ``request_id`` of ``kind``: wake the server."""
        self._connection.note_request(request_id)
        self.kind = kind
        self.lane.ring()
        self._waiter.sent()
