"""Client: drive one rlenv environment over TCP.

A blocking socket pumps bytes into a sans-IO :class:`rlenv.protocol.Connection`; everything about
the protocol is decided there. The socket's timeouts are enforced by the kernel
(``SO_RCVTIMEO`` / ``SO_SNDTIMEO``, see :mod:`rlenv.protocol.sockets`), so no system call is
added to a step. Every failure surfaces as a typed error: :class:`RemoteError` (the server refused a
request, with its code and message), :class:`RequestTimeout` (no answer within the deadline;
the connection is closed so that a late answer can never be taken for the answer to a later
request) and :class:`ConnectionLost`.
"""

from __future__ import annotations

import os
import socket
import time
from typing import NoReturn

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
    ProtocolError,
    RemoteError,
    RequestTimeout,
)
from rlenv.protocol.sockets import AnswerWaiter, configure_socket
from rlenv_client.base import BaseClient, StepResult

__all__ = ["Client", "StepResult"]

_READ_SIZE = 64 * 1024


class Client(BaseClient):
    """A connection to one environment server.

    Args:
        host: the server's address.
        port: the server's port.
        timeout: seconds to wait for connecting and for each answer.
        world_data: also ask for the world's data on reset and step; it is returned as
            ``info["world"]``.
        token: the secret of a server that requires one (default: ``$RLENV_TOKEN``); sent only
            to servers that ask for it.

    Raises:
        ConnectionLost: the server cannot be reached, or closed the connection at once.
        RequestTimeout: the server did not say hello within ``timeout``.
        RemoteError: the server refused the connection (``busy``, ``unauthorized``).
        ProtocolVersionError: the server speaks another major protocol version.
    """

    def __init__(
        self, host: str = "127.0.0.1", port: int = 0, *, timeout: float = 30.0,
        world_data: bool = False, token: str | None = None,
    ) -> None:
        super().__init__(world_data=world_data)
        self.address = f"{host}:{port}"
        self.timeout = timeout
        self._closed_because = ""  # what closed the connection, when it was no error of its own
        self._waiter = AnswerWaiter()
        self._connection = Connection(Role.CLIENT)
        try:
            self._sock: socket.socket | None = socket.create_connection((host, port), timeout)
        except TimeoutError:
            raise RequestTimeout(f"connecting to {self.address} took longer than {timeout}s")\
                from None
        except OSError as error:
            raise ConnectionLost(f"cannot connect to {self.address}: {error}") from None
        configure_socket(self._sock, timeout, timeout)
        try:
            message = self._next_message()
        except BaseException:
            self.close()
            raise
        if isinstance(message, ErrorReply):
            self.close()
            raise RemoteError(message.code, message.message, message.fatal)
        if not isinstance(message, Hello):
            self.close()
            raise ConnectionLost(f"{self.address} did not start with a hello")
        self._set_hello(message)
        if message.token_required:
            token = token if token is not None else os.environ.get("RLENV_TOKEN")
            if token is None:
                self.close()
                raise RemoteError(ErrorCode.UNAUTHORIZED, f"{self.address} requires a token: "
                                  "pass token=... (or set RLENV_TOKEN)", fatal=True)
            self._post(Request(next(self._ids), token=token))
            self._response(self.receive_reply())

    def close(self) -> None:
        """Close the connection; safe to repeat."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    @property
    def closed(self) -> bool:
        """Whether the connection is closed."""
        return self._sock is None

    def __enter__(self) -> Client:
        return self

    def __repr__(self) -> str:
        state = "closed" if self.closed else "open"
        return f"<Client {self.hello.environment!r} at {self.address}, {state}>"

    # --- transport --------------------------------------------------------------------------

    def _send(self, request: Request) -> None:
        sock = self._sock
        if sock is None:
            raise ConnectionLost(f"the connection to {self.address} is closed"
                                 f"{self._closed_because}")
        data = self._connection.send(request)
        try:
            sock.sendall(data)
            self._waiter.sent()
        except BlockingIOError:
            self.close()
            raise RequestTimeout(f"sending to {self.address} took longer than {self.timeout}s; "
                                 "connection closed") from None
        except OSError as error:
            self.close()
            raise ConnectionLost(f"sending to {self.address} failed: {error}") from None
        except BaseException as error:  # interrupted (KeyboardInterrupt): the frame may be cut
            self.close()
            self._closed_because = (f": a request was interrupted ({type(error).__name__}) "
                                    "while it was being sent; connect again")
            raise

    def _receive(self) -> Reply:
        message = self._next_message()
        if message.__class__ is Hello or message.__class__ is Request:
            self.close()
            raise ConnectionLost(f"{self.address} broke the protocol: {message!r:.80}")
        return message  # type: ignore[return-value]

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
        suite's :class:`~rlenv_client.compliance.harness.TappedClient` does). It is on every
        step's path: keep an override cheap.
        """
        sock = self._sock
        if sock is None:
            raise ConnectionLost(f"the connection to {self.address} is closed"
                                 f"{self._closed_because}")
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
            f"{self.address} did not answer within {self.timeout}s; connection closed")
