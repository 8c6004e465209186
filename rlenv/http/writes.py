"""One write per response: uvicorn's HTTP protocol with its writes coalesced.

uvicorn writes a response's head when the application starts it and its body when the
application sends it: two ``write`` system calls, two TCP segments, two wake-ups of the client
for one answer. On the development VM a write to a loopback socket cost tens of microseconds,
as much as the rest of the HTTP layer. :func:`one_write_protocol` gives uvicorn's protocol
(httptools, or h11) a transport that gathers what is written during one step of the event loop
and sends it at the end of that step, in one write: a head and its body, or a WebSocket's
frames. Closing sends what is pending first. Connections also set ``TCP_NODELAY`` (see
:func:`rlenv.http.app.serve`), so a stream's later writes never wait for an acknowledgement.
"""

from __future__ import annotations

import asyncio
import importlib.util
from typing import Any

__all__ = ["one_write_protocol"]


class _OneWrite:
    """A transport whose writes within one event loop step leave in one system call."""

    def __init__(self, transport: asyncio.Transport) -> None:
        self._transport = transport
        self._pending: list[bytes] = []
        self._loop = asyncio.get_running_loop()

    def write(self, data: bytes | bytearray | memoryview) -> None:
        """Queue ``data``; it leaves with the step's other writes."""
        if not self._pending:
            self._loop.call_soon(self._flush)
        self._pending.append(bytes(data))

    def writelines(self, lines: Any) -> None:
        """Queue every line."""
        for line in lines:
            self.write(line)

    def _flush(self) -> None:
        if self._pending:
            data = b"".join(self._pending)
            self._pending.clear()
            if not self._transport.is_closing():
                self._transport.write(data)

    def close(self) -> None:
        """Send what is pending, then close."""
        self._flush()
        self._transport.close()

    def write_eof(self) -> None:
        """Send what is pending, then end the stream."""
        self._flush()
        self._transport.write_eof()

    def abort(self) -> None:
        """Drop what is pending and the connection."""
        self._pending.clear()
        self._transport.abort()

    def __getattr__(self, name: str) -> Any:  # the rest of the transport, as it is
        return getattr(self._transport, name)


def one_write_protocol(http: str) -> type[asyncio.Protocol]:
    """The uvicorn protocol ``http`` (``auto``, ``httptools`` or ``h11``), writing once a step.

    Raises:
        ValueError: an unknown implementation.
    """
    if http == "auto":
        http = "httptools" if importlib.util.find_spec("httptools") else "h11"
    if http == "httptools":
        from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol as base
    elif http == "h11":
        from uvicorn.protocols.http.h11_impl import H11Protocol as base  # type: ignore[assignment]
    else:
        raise ValueError(f"unknown HTTP implementation {http!r}: auto, httptools or h11")

    class OneWriteProtocol(base):  # type: ignore[valid-type,misc]
        def connection_made(self, transport: asyncio.BaseTransport) -> None:  # type: ignore[override]
            super().connection_made(_OneWrite(transport))  # type: ignore[arg-type]

    OneWriteProtocol.__name__ = OneWriteProtocol.__qualname__ = f"OneWrite{base.__name__}"
    return OneWriteProtocol
