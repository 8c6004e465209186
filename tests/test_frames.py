"""rlenv.transport.frames: one whole frame from a blocking socket, over a real socket pair."""

from __future__ import annotations

import socket
import threading

from rlenv.protocol.codec import frame, unpack
from rlenv.transport.frames import receive_frame


def test_a_frame_sent_in_pieces_is_read_whole_and_the_next_after_it() -> None:
    mine, theirs = socket.socketpair()
    with mine, theirs:
        first, second = frame({"id": 1, "data": b"x" * 300_000}), frame({"id": 2})
        sender = threading.Thread(
            target=lambda: (
                [theirs.sendall(first[i : i + 7000]) for i in range(0, len(first), 7000)]
                + [theirs.sendall(second)]
            )
        )
        sender.start()
        body = receive_frame(mine)
        sender.join(60)
        assert body is not None and unpack(body) == {"id": 1, "data": b"x" * 300_000}
        assert unpack(receive_frame(mine)) == {"id": 2}  # type: ignore[arg-type]


def test_a_peer_that_closes_before_or_within_a_frame_gives_none() -> None:
    for sent in (b"", frame({"id": 1})[:3], frame({"id": 1})[:-1]):
        mine, theirs = socket.socketpair()
        with mine:
            theirs.sendall(sent)
            theirs.close()
            assert receive_frame(mine) is None
