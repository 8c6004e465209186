"""Opening a client's shared-memory lane (protocol 2.3): whether one can be, and the handshake.

:class:`~rlenv_client.client.Client` calls :func:`open_lane` once, after the hello (and the
token): it says why no lane is possible here (:func:`lane_refusal`), or listens on a Unix
socket, sends the ``shared_memory`` request and takes the block the server hands over
(:mod:`rlenv.transport.lanes` has the two ends). Without a lane, steps stay on the socket,
unless one was required.
"""

from __future__ import annotations

import logging
import os
import socket
from collections.abc import Callable
from typing import Any

from rlenv.protocol import Hello
from rlenv.protocol.errors import ConnectionLost, RemoteError
from rlenv.protocol.shared_memory import lane_unavailable
from rlenv.transport.lanes import Lane, accept_lane, listen_for_lane
from rlenv.transport.sockets import is_loopback

__all__ = ["lane_refusal", "open_lane"]

logger = logging.getLogger(__name__)

_LANES_SINCE = (2, 3)


def lane_refusal(hello: Hello, host: str, required: bool) -> str | None:
    """Why no lane can carry the steps of the server at ``host`` that said ``hello``, or ``None``.

    ``RLENV_SHARED_MEMORY=0`` refuses a lane that is not ``required``.
    """
    why = lane_unavailable(hello)
    if not is_loopback(host):
        why = f"the server is at {host}, not on this machine"
    elif hello.protocol < _LANES_SINCE:
        why = "the server speaks protocol {}.{} (lanes came with 2.3)".format(*hello.protocol)
    elif not required and os.environ.get("RLENV_SHARED_MEMORY") == "0":
        why = "RLENV_SHARED_MEMORY=0"
    return why


def open_lane(
    hello: Hello,
    host: str,
    sock: socket.socket,
    *,
    address: str,
    timeout: float,
    required: bool,
    ask: Callable[[dict[str, Any]], object],
) -> Lane | None:
    """Ask the server for a lane; without one, steps stay on the socket (unless required).

    Args:
        hello: the server's hello.
        host: the host the client connected to.
        sock: the client's socket to the server.
        address: the server's address, for messages.
        timeout: seconds to wait for the server to open its end.
        required: raise instead of going on without a lane.
        ask: sends the ``shared_memory`` part (the client's ``_call``) and waits for its answer.

    Returns:
        The lane, or ``None`` (steps stay on the socket; the log says why).

    Raises:
        ValueError: ``required``, but no lane is possible here (the message says why).
        OSError: ``required``, but this process cannot listen on a Unix socket.
        RemoteError: ``required``, but the server refused the lane.
        ConnectionLost: ``required``, but the server did not open the lane it offered.
    """
    why = lane_refusal(hello, host, required)
    if why is not None:
        if required:
            raise ValueError(f"shared_memory=True, but {why}")
        logger.debug("%s: steps go on the socket: %s", address, why)
        return None
    try:
        listener, name, key = listen_for_lane()
    except OSError as error:  # no Unix sockets here (a sandbox, say)
        if required:
            raise
        logger.info("%s: steps go on the socket: %s", address, error)
        return None
    try:
        try:
            ask({"address": name, "key": key})
        except RemoteError as error:
            if required:
                raise
            logger.info("%s: steps go on the socket: %s", address, error)
            return None
        try:
            return accept_lane(listener, key, hello, sock, timeout)
        except OSError as error:  # the server's end closes when it finds ours gone
            if required:
                raise ConnectionLost(
                    f"{address} did not open the shared-memory lane it offered: {error}"
                ) from None
            logger.warning(
                "%s: the shared-memory lane failed (%s); steps go on the socket", address, error
            )
            return None
    finally:
        listener.close()
