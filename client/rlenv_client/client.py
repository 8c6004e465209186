"""Client: drive one rlenv environment over TCP.

A blocking socket pumps bytes into a sans-IO :class:`rlenv.protocol.Connection`; everything about
the protocol is decided there. The socket's timeouts are enforced by the kernel
(``SO_RCVTIMEO`` / ``SO_SNDTIMEO``, see :mod:`rlenv.transport.sockets`), so no system call is
added to a step. Every failure surfaces as a typed error: :class:`RemoteError` (the server refused a
request, with its code and message), :class:`RequestTimeout` (no answer within the deadline;
the connection is closed so that a late answer can never be taken for the answer to a later
request) and :class:`ConnectionLost`.

A client on the same machine as its server moves its steps to a **shared-memory lane**
(protocol 2.3, :mod:`rlenv.transport.lanes`) when both ends can: a plain step and a ``steps``
request then travel through fixed slots of memory both map, with no msgpack and no TCP; every
other request, and any answer that does not fit the slots (an error, an ``info``), goes on the
socket as before. Nothing else changes: the same requests, the same answers, the same errors.
``shared_memory=False`` (or ``RLENV_SHARED_MEMORY=0``) keeps everything on the socket.
"""

from __future__ import annotations

import logging
import os
import socket
import time
from collections.abc import Mapping, Sequence
from typing import Any, NoReturn

import numpy as np

from rlenv.protocol import (
    CONNECTION_CLOSED,
    NEED_DATA,
    Connection,
    ErrorReply,
    Hello,
    Message,
    Reply,
    Request,
    Role,
)
from rlenv.protocol.errors import (
    ConnectionLost,
    ErrorCode,
    LocalProtocolError,
    ProtocolError,
    RemoteError,
    RequestTimeout,
)
from rlenv.transport.lanes import LaneClosed
from rlenv.transport.sockets import AnswerWaiter, configure_socket, readable_now
from rlenv_client._addresses import format_address, parse_address
from rlenv_client._lane_opening import open_lane
from rlenv_client._lane_traffic import LaneTraffic
from rlenv_client.base import AGENT_ONLY, BaseClient, StepResult

__all__ = ["Client", "StepResult"]

logger = logging.getLogger(__name__)

_READ_SIZE = 64 * 1024


class Client(BaseClient):
    """A connection to one environment server.

    ``Client("127.0.0.1", 5000)`` and ``Client("127.0.0.1:5000")`` (what
    :attr:`ServerProcess.address <rlenv_client.launcher.ServerProcess.address>` gives) are the
    same; an IPv6 host goes in brackets in the latter: ``Client("[::1]:5000")``.

    Args:
        host: the server's host, or ``HOST:PORT`` when ``port`` is not given.
        port: the server's port.
        timeout: seconds to wait for connecting and for each answer.
        world_data: also ask for the world's data on reset and step; it is returned as
            ``info["world"]``.
        token: the secret of a server that requires one (default: ``$RLENV_TOKEN``); sent only
            to servers that ask for it.
        shared_memory: step through a shared-memory lane (see the module docstring): ``None``
            (the default) when the server is on this machine and can (else silently not, and
            never with ``RLENV_SHARED_MEMORY=0``), ``True`` always (else an error says why),
            ``False`` never.

    Raises:
        ConnectionLost: the server cannot be reached, or closed the connection at once.
        RequestTimeout: the server did not say hello within ``timeout``.
        RemoteError: the server refused the connection (``busy``, ``unauthorized``), or the
            lane asked for with ``shared_memory=True`` (``bad_request``, saying why).
        ProtocolVersionError: the server speaks another major protocol version.
        ValueError: ``shared_memory=True``, but no lane is possible here (the message says
            why); or, without ``port``, ``host`` is not ``HOST:PORT``.
        OSError: ``shared_memory=True``, but this process cannot listen on a Unix socket.
    """

    def __init__(
        self,
        host: str,
        port: int | None = None,
        *,
        timeout: float = 30.0,
        world_data: bool = False,
        token: str | None = None,
        shared_memory: bool | None = None,
    ) -> None:
        if port is None:
            host, port = parse_address(host)
        super().__init__(world_data=world_data)
        self.address = format_address(host, port)
        self.timeout = timeout
        self._closed_because = ""  # what closed the connection, when it was no error of its own
        self._waiter = AnswerWaiter()
        self._connection = Connection(Role.CLIENT)
        self._lane: LaneTraffic | None = None  # once a shared-memory lane is open
        self._sock: socket.socket | None = _connected(host, port, timeout, self.address)
        try:  # a failure of the handshake closes the connection
            message = self._next_message()
            if isinstance(message, ErrorReply):
                raise RemoteError(message.code, message.message, message.fatal)
            if not isinstance(message, Hello):
                raise ConnectionLost(f"{self.address} did not start with a hello")
            self._set_hello(message)
            if message.token_required:
                token = token if token is not None else os.environ.get("RLENV_TOKEN")
                if token is None:
                    raise RemoteError(
                        ErrorCode.UNAUTHORIZED,
                        f"{self.address} requires a token: pass token=... (or set RLENV_TOKEN)",
                        fatal=True,
                    )
                self._post(Request(next(self._ids), token=token))
                self._response(self.receive_reply())
            if shared_memory is not False:
                lane = open_lane(
                    message,
                    host,
                    self._sock,
                    address=self.address,
                    timeout=timeout,
                    required=shared_memory is True,
                    ask=lambda lane: self._call(shared_memory=lane),
                )
                if lane is not None:
                    self._lane = LaneTraffic(lane, self._connection, self._waiter)
        except BaseException:
            self.close()
            raise

    @property
    def shared_memory(self) -> bool:
        """Whether steps go through a shared-memory lane (see the module docstring)."""
        return self._lane is not None

    def close(self) -> None:
        """Close the connection (and the lane); safe to repeat."""
        if self._lane is not None:
            self._lane.lane.close()
            self._lane = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    @property
    def closed(self) -> bool:
        """Whether the connection is closed."""
        return self._sock is None

    def fileno(self) -> int:
        """The socket's descriptor (-1 once closed).

        Without a lane (``shared_memory=False``) every answer arrives there; an event loop
        awaiting answers watches :meth:`answer_descriptors`.
        """
        return -1 if self._sock is None else self._sock.fileno()

    def answer_descriptors(self) -> tuple[int, ...]:
        """What an event loop watches for the next answer: the socket, and the lane's doorbell.

        When one is readable, :meth:`wake` says whether the answer has arrived (a doorbell
        rings for each answer in the lane's slots; the socket carries the others).
        """
        lane = self._lane
        return (self.fileno(),) if lane is None else (self.fileno(), lane.lane.doorbell.fileno())

    def wake(self) -> bool:
        """Whether the answer has arrived, after one of :meth:`answer_descriptors` was readable.

        Reads the doorbell's bytes (so that it stops being readable), then
        :meth:`answer_arrived`. A closed doorbell (the server is gone) counts as arrived:
        receiving says so.
        """
        lane = self._lane
        if lane is not None:
            try:
                lane.lane.drain()
            except LaneClosed:
                return True
        return self.answer_arrived()

    def __enter__(self) -> Client:
        return self

    def __repr__(self) -> str:
        state = "closed" if self.closed else "open"
        return f"<Client {self.hello.environment!r} at {self.address}, {state}>"

    # --- transport --------------------------------------------------------------------------

    def _send(self, request: Request) -> None:
        sock = self._sock
        if sock is None:
            raise ConnectionLost(
                f"the connection to {self.address} is closed{self._closed_because}"
            )
        if self._lane is not None:
            self._settle()
            if self._lane.send(request):
                return
        data = self._connection.send(request)
        try:
            sock.sendall(data)
            self._waiter.sent()
        except BlockingIOError:
            self.close()
            raise RequestTimeout(
                f"sending to {self.address} took longer than {self.timeout}s; connection closed"
            ) from None
        except OSError as error:
            self.close()
            raise ConnectionLost(f"sending to {self.address} failed: {error}") from None
        except BaseException as error:  # interrupted (KeyboardInterrupt): the frame may be cut
            self.close()
            self._closed_because = (
                f": a request was interrupted ({type(error).__name__}) "
                "while it was being sent; connect again"
            )
            raise

    def send_step(self, action: Any, repeat_action: int | None = None) -> None:
        """Send a step request without waiting (see :class:`BaseClient`).

        Through the lane, an action of the space's exact dtype and shape (or a ``Discrete``
        integer) is written straight into its slot.
        """
        lane = self._free_lane()
        if lane is not None and self._observation_request is AGENT_ONLY:
            request_id = next(self._ids)
            if lane.send_step(request_id, action, repeat_action):
                self._answers.awaited = request_id
                return
        super().send_step(action, repeat_action)

    def send_steps(
        self,
        action: Any,
        reset: np.ndarray | None = None,
        repeat_action: int | None = None,
        reset_with: Sequence[Mapping[str, Any] | None] | None = None,
    ) -> None:
        """Step every instance of the server at once, in columns (see :class:`BaseClient`).

        Through the lane, an array of the K actions' exact dtype and shape (and boolean reset
        flags) is written straight into its slots; a request with ``reset_with`` entries goes
        on the socket.
        """
        lane = self._free_lane()
        if lane is not None and (reset_with is None or all(entry is None for entry in reset_with)):
            request_id = next(self._ids)
            if lane.send_steps(request_id, action, reset, repeat_action):
                self._answers.awaited = request_id
                return
        super().send_steps(action, reset, repeat_action, reset_with)

    def _free_lane(self) -> LaneTraffic | None:
        """The lane, if a request can go through it now (none is owed an answer)."""
        if self._sock is None or self._connection.outstanding:
            return None
        return self._lane

    def _receive(self, copy: bool = True) -> Reply:
        lane = self._lane
        if lane is not None and lane.kind and not self._connection.buffered:
            if self._answered_by_lane(lane):
                try:
                    return lane.read(copy)
                except LocalProtocolError as error:
                    self.close()
                    raise ConnectionLost(f"{self.address} broke the protocol: {error}") from None
        message = self._next_message()
        if message.__class__ is Hello or message.__class__ is Request:
            self.close()
            raise ConnectionLost(f"{self.address} broke the protocol: {message!r:.80}")
        if lane is not None and message.id is not None:  # type: ignore[union-attr]
            lane.kind = 0  # the lane's request (if any) was answered on the socket
        return message  # type: ignore[return-value]

    def answer_arrived(self) -> bool:
        """Whether the next answer has arrived: receiving it would not wait (a hint).

        True when the lane's slots hold an answer, or the socket has bytes (perhaps only the
        start of a frame) or reached its end; false while the server is still at work.
        """
        if self._lane is not None and self._lane.arrived():
            return True
        sock = self._sock
        return self._connection.buffered > 0 or sock is None or readable_now(sock)

    def _answered_by_lane(self, lane: LaneTraffic) -> bool:
        """Wait for the answer to the lane's request; whether it is in the slots.

        Otherwise the socket has bytes: an answer that did not fit, an error, or the end.
        """
        if self._sock is None:
            raise ConnectionLost(
                f"the connection to {self.address} is closed{self._closed_because}"
            )
        try:
            return lane.wait(self.timeout)
        except BlockingIOError:
            self._timed_out()
        except LaneClosed:
            self.close()
            raise ConnectionLost(f"{self.address} closed the connection") from None
        except OSError as error:
            self.close()
            raise ConnectionLost(f"receiving from {self.address} failed: {error}") from None

    def _settle(self) -> None:
        """Receive (and drop) the answers still owed, so that requests stay in order.

        Only an interrupted wait leaves any: the lane and the socket are two ways in, and the
        server must not take a later request before an earlier one.
        """
        while self._connection.outstanding:
            message = self._receive()
            logger.info(
                "%s: dropped the answer to request %s, whose caller gave up on it",
                self.address,
                message.id,
            )

    def _next_message(self) -> Message:
        connection = self._connection
        if not connection.buffered:  # the usual case: wait for the answer right away
            connection.receive_data(self._recv())
        deadline = None
        while True:
            try:
                message = connection.next_message()
            except ProtocolError as error:
                self.close()
                raise ConnectionLost(f"{self.address} broke the protocol: {error}") from None
            if message is NEED_DATA:
                if deadline is None:
                    deadline = time.monotonic() + self.timeout
                elif time.monotonic() > deadline:  # a server that trickles bytes
                    self._timed_out()
                connection.receive_data(self._recv())
                continue
            if message is CONNECTION_CLOSED:
                self.close()
                raise ConnectionLost(f"{self.address} closed the connection")
            return message  # type: ignore[return-value]

    def _recv(self) -> bytes:
        """What the socket has now (waiting up to the timeout): every received byte, once.

        All the client reads comes through here, in order, the hello included: a subclass may
        override it to watch the byte stream, calling this one for the bytes (the compliance
        suite's :class:`~rlenv_tools.compliance._harness.TappedClient` does). It is on every
        step's path: keep an override cheap.
        """
        sock = self._sock
        if sock is None:
            raise ConnectionLost(
                f"the connection to {self.address} is closed{self._closed_because}"
            )
        try:
            return self._waiter.recv(sock, _READ_SIZE)
        except BlockingIOError:
            self._timed_out()
        except OSError as error:
            self.close()
            raise ConnectionLost(f"receiving from {self.address} failed: {error}") from None

    def _timed_out(self) -> NoReturn:
        self.close()
        raise RequestTimeout(
            f"{self.address} did not answer within {self.timeout}s; connection closed"
        )


def _connected(host: str, port: int, timeout: float, address: str) -> socket.socket:
    """A socket connected to ``host:port`` (``address``, in messages), its timeouts set.

    Raises:
        RequestTimeout: connecting took longer than ``timeout`` seconds.
        ConnectionLost: the server cannot be reached.
    """
    try:
        sock = socket.create_connection((host, port), timeout)
    except TimeoutError:
        raise RequestTimeout(f"connecting to {address} took longer than {timeout}s") from None
    except OSError as error:
        raise ConnectionLost(f"cannot connect to {address}: {error}") from None
    configure_socket(sock, timeout, timeout)
    return sock
