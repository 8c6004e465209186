"""The gateway's door: every request is checked here before any route sees it.

- ``Host`` and ``Origin`` as the inspector checks them (:mod:`rlenv_tools._origins`): a foreign
  ``Host`` (DNS rebinding) or a page of another site gets 403 ``forbidden``;
- so does a request a browser marks as sent by a page of another origin: ``Sec-Fetch-Site``
  other than ``same-origin`` or ``none`` (a page's ``<img src>`` sends no ``Origin``, and
  bevy_rl's ``GET /step`` and ``/reset`` change state);
- with a token (required to bind beyond loopback: ``RLENV_TOKEN``), ``Authorization: Bearer
  TOKEN``, compared in constant time; else 401 ``unauthorized``. Every token is compared: the
  right one is served whatever its address sent before. Past a few wrong tokens from an
  address, each wrong one's 401 is held, longer and longer, as at the TCP server
  (:mod:`rlenv.serving._penalties`): the guesser is slowed, not the address;
- bodies of at most ``max_body`` bytes: a larger ``Content-Length`` is refused before anything
  is read, a chunked body as soon as it grows past it (413 ``payload_too_large``, and the
  connection closes).

WebSockets are refused the same way, before they are accepted. No CORS header is ever sent.
"""

from __future__ import annotations

import asyncio
import hmac
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

from rlenv.protocol.errors import ErrorCode
from rlenv.serving._penalties import Penalties
from rlenv_tools._origins import OriginPolicy
from rlenv_tools.http.problems import Problem

__all__ = ["Guard"]

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

_REMEMBERED = 256  # (Host, Origin) pairs whose verdict is kept
_CLOSE = {"Connection": "close"}  # an unread body is never taken for the next request
_OWN_FETCHES = (b"same-origin", b"none")  # Sec-Fetch-Site: this gateway's pages, or a person


class Guard:
    """ASGI middleware enforcing the rules of the module docstring.

    Args:
        app: the application behind the door.
        origins: the ``Host`` and ``Origin`` headers accepted.
        token: the bearer token every request must carry, or ``None``.
        max_body: the largest request body, in bytes.
    """

    def __init__(
        self, app: ASGIApp, *, origins: OriginPolicy, token: str | None, max_body: int
    ) -> None:
        self.app = app
        self._origins = origins
        self._token = None if token is None else token.encode()
        self._max_body = max_body
        self._refusals: dict[tuple[bytes | None, bytes | None], str | None] = {}
        self._penalties = Penalties()

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Serve ``scope`` if it passes, else answer its problem."""
        kind = scope["type"]
        if kind != "http" and kind != "websocket":
            await self.app(scope, receive, send)
            return
        host = origin = None
        authorization = length = fetch_site = b""
        chunked = False
        for name, value in scope["headers"]:
            if name == b"host":
                host = value
            elif name == b"origin":
                origin = value
            elif name == b"authorization":
                authorization = value
            elif name == b"content-length":
                length = value
            elif name == b"transfer-encoding":
                chunked = True
            elif name == b"sec-fetch-site":
                fetch_site = value
        client = scope.get("client")
        peer = "an unknown address" if client is None else client[0]
        problem, delay = self._problem(host, origin, authorization, length, fetch_site, peer)
        if problem is not None:
            if delay:  # a wrong token: its answer waits (on its own connection)
                await asyncio.sleep(delay)
            await _refuse(problem, scope, receive, send)
            return
        if chunked and kind == "http":
            receive = self._counted(receive)
        await self.app(scope, receive, send)

    def _problem(
        self,
        host: bytes | None,
        origin: bytes | None,
        authorization: bytes,
        length: bytes,
        fetch_site: bytes,
        peer: str,
    ) -> tuple[Problem | None, float]:
        """Why the request is refused (``None``: it passes), and how long to hold the answer."""
        try:
            refusal = self._refusals[host, origin]
        except KeyError:
            refusal = self._origins.refusal(
                None if host is None else host.decode("latin-1"),
                None if origin is None else origin.decode("latin-1"),
            )
            if len(self._refusals) >= _REMEMBERED:  # bounded against a flood of names
                self._refusals.clear()
            self._refusals[host, origin] = refusal
        if refusal is not None:
            return Problem("forbidden", refusal), 0.0
        if fetch_site and fetch_site.lower() not in _OWN_FETCHES:
            site = fetch_site.decode("latin-1")
            return Problem(
                "forbidden",
                f"refused: a request a page of another origin made (Sec-Fetch-Site: {site:.20})",
            ), 0.0
        if self._token is not None:
            problem, delay = self._token_problem(authorization, peer)
            if problem is not None:
                return problem, delay
        if length and (not length.isdigit() or int(length) > self._max_body):
            return Problem(
                "payload_too_large",
                f"a body is at most {self._max_body} bytes, "
                f"this one {length.decode('latin-1')[:20]}",
                headers=_CLOSE,
            ), 0.0
        return None, 0.0

    def _token_problem(self, authorization: bytes, peer: str) -> tuple[Problem | None, float]:
        """Why ``authorization`` from ``peer`` is refused (``None``: it passes); the hold."""
        assert self._token is not None
        scheme, _, token = authorization.partition(b" ")
        if (
            scheme.lower() == b"bearer"
            and token
            and hmac.compare_digest(token.strip(), self._token)
        ):
            return None, 0.0
        delay = self._penalties.failed(peer) if token else 0.0
        return Problem(
            ErrorCode.UNAUTHORIZED,
            "this gateway requires its token: send Authorization: Bearer TOKEN (the "
            "RLENV_TOKEN it was started with)"
            if not token
            else "wrong token",
            headers={"WWW-Authenticate": 'Bearer realm="rlenv"'},
        ), delay

    def _counted(self, receive: Receive) -> Receive:
        """``receive`` that refuses a chunked body once it grows past ``max_body``."""
        received = 0

        async def counted() -> Message:
            nonlocal received
            message = await receive()
            received += len(message.get("body", b""))
            if received > self._max_body:
                raise Problem(
                    "payload_too_large", f"a body is at most {self._max_body} bytes", headers=_CLOSE
                )
            return message

        return counted


async def _refuse(problem: Problem, scope: Scope, receive: Receive, send: Send) -> None:
    """Answer ``problem``: as HTTP, or a WebSocket's denial (close code 1008 without one)."""
    if scope["type"] == "websocket" and "websocket.http.response" not in scope.get(
        "extensions", {}
    ):
        await send({"type": "websocket.close", "code": 1008})
        return
    await problem.response(scope.get("path"))(scope, receive, send)
