"""The gateway as a Starlette application, and ``rlenv http``'s server (uvicorn).

:func:`create_app` assembles the route tables (:mod:`~rlenv_tools.http._routes`,
:mod:`~rlenv_tools.http._streams`, :mod:`~rlenv_tools.http._bevy`,
:mod:`~rlenv_tools.http._openenv`, ``/openapi.json``) behind the
:class:`~rlenv_tools.http._guard.Guard`, with every error answered as a problem (unknown routes,
methods, and the gateway's own bugs included: never an HTML page). :func:`serve` binds the
socket, says where, and runs uvicorn until SIGTERM or SIGINT: open streams end, sessions close
(their server subprocesses too), and the process exits.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass, replace
from importlib.metadata import PackageNotFoundError, version
from typing import Any

import uvicorn
from starlette.applications import Starlette
from starlette.exceptions import HTTPException
from starlette.middleware import Middleware
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import BaseRoute, Route, WebSocketRoute

from rlenv.protocol import PROTOCOL_VERSION, Hello
from rlenv.serving._access import bind_error
from rlenv.serving._endpoint import DEFAULT_HOST, InsecureBindError
from rlenv.transport.sockets import is_loopback
from rlenv_tools._origins import OriginPolicy, host_names
from rlenv_tools.http._bevy import bevy_endpoints
from rlenv_tools.http._endpoints import Answer, Endpoint, JSONRoute
from rlenv_tools.http._guard import Guard
from rlenv_tools.http._openapi import openapi_document
from rlenv_tools.http._openenv import openenv_endpoints
from rlenv_tools.http._routes import component_schemas, session_endpoints, target_schemas
from rlenv_tools.http._sessions import MAX_SESSIONS_PER_CLIENT, Sessions
from rlenv_tools.http._streams import stream_endpoints
from rlenv_tools.http._targets import Catalog
from rlenv_tools.http._uvicorn_protocol import connection_limit, http_protocol
from rlenv_tools.http.json_spaces import dumps
from rlenv_tools.http.problems import COMMON_HEADERS, PROBLEMS, Problem

__all__ = ["Gateway", "Settings", "create_app", "serve"]

logger = logging.getLogger(__name__)

_API_VERSION = "1.0"


@dataclass(frozen=True)
class Settings:
    """How the gateway serves.

    Attributes:
        target: the command line's TARGET (``MODULE:CLASS``, ``HOST:PORT`` or a registered
            id), or ``None``.
        host: the address to bind (loopback by default).
        port: the port to bind (0: a free one).
        token: the bearer token every request must carry (required beyond loopback).
        timeout: seconds an environment may take to answer one request (then 504).
        max_sessions: sessions at once (then 503).
        max_sessions_per_client: sessions at once created by one client, one address (then
            503).
        max_body: the largest request body or WebSocket message, in bytes (then 413).
        idle_timeout: seconds after which a session without requests is closed (``None``:
            never).
        head_timeout: seconds a connection has to complete a request head (then closed).
        max_connections: connections open at once (beyond: the oldest waiting for its
            request head is closed).
    """

    target: str | None = None
    host: str = DEFAULT_HOST
    port: int = 8000
    token: str | None = None
    timeout: float = 30.0
    max_sessions: int = 32
    max_sessions_per_client: int = MAX_SESSIONS_PER_CLIENT
    max_body: int = 1 << 20
    idle_timeout: float | None = 600.0
    head_timeout: float = 5.0
    max_connections: int = 100


class Gateway:
    """What the routes share: the settings, the sessions, the TARGET's description.

    Args:
        settings: how it serves.
        hello: what the TARGET's environment said on connecting (its spaces), if any.
    """

    def __init__(self, settings: Settings, hello: Hello | None = None) -> None:
        self.settings = settings
        self.hello = hello
        self.catalog = Catalog(settings.target, timeout=settings.timeout)
        self.sessions = Sessions(
            self.catalog,
            max_sessions=settings.max_sessions,
            max_sessions_per_client=settings.max_sessions_per_client,
            idle_timeout=settings.idle_timeout,
        )
        self._openapi: bytes | None = None
        self.endpoints: list[Endpoint] = [
            *session_endpoints(self),
            *stream_endpoints(self),
            *bevy_endpoints(self),
            *openenv_endpoints(self),
            Endpoint(
                "GET",
                "/openapi.json",
                self._openapi_route,
                "openapi",
                "This document (OpenAPI 3.1)",
                "gateway",
                {200: Answer("the OpenAPI document", {"type": "object"})},
            ),
        ]

    def about(self) -> dict[str, Any]:
        """``GET /v1``: versions, capabilities and limits."""
        settings = self.settings
        return {
            "versions": ["v1"],
            "api": _API_VERSION,
            "rlenv": _package_version(),
            "protocol": list(PROTOCOL_VERSION),
            "target": settings.target,
            "env_ids": self.catalog.ids(),
            "hosting": "isolated",
            "capabilities": {
                "websocket": True,
                "events": True,
                "bevy_rl": bool(settings.target),
                "openenv": "/openenv" if settings.target else None,
                "render": ["image/png", "application/octet-stream"],
                "snapshots": True,
                "openapi": "/openapi.json",
            },
            "limits": {
                "max_sessions": settings.max_sessions,
                "max_sessions_per_client": settings.max_sessions_per_client,
                "max_body": settings.max_body,
                "timeout": settings.timeout,
                "idle_timeout": settings.idle_timeout,
                "head_timeout": settings.head_timeout,
                "max_connections": settings.max_connections,
            },
            "token_required": settings.token is not None,
        }

    def openapi(self) -> dict[str, Any]:
        """The OpenAPI document, generated from the route table and the TARGET's spaces."""
        observation, action = target_schemas(self)
        return openapi_document(
            self.endpoints,
            component_schemas(observation, action),
            title="rlenv HTTP gateway",
            version=_API_VERSION,
            token_required=self.settings.token is not None,
            description=f"Sessions on {self.settings.target or 'registered ids'}"
            ", bevy_rl's routes, a WebSocket and server-sent events per session. Errors are "
            "RFC 9457 problems (application/problem+json) with the error code in 'code'.",
        )

    async def _openapi_route(self, request: Request) -> Response:
        if self._openapi is None:
            self._openapi = dumps(self.openapi())
        return Response(self._openapi, headers=COMMON_HEADERS, media_type="application/json")

    async def reap_forever(self) -> None:
        """Close idle sessions, checking a few times per ``idle_timeout``."""
        idle_timeout = self.settings.idle_timeout
        if idle_timeout is None:
            return
        while True:
            await asyncio.sleep(min(max(idle_timeout / 4, 0.05), 30.0))
            await self.sessions.reap()


def create_app(settings: Settings, hello: Hello | None = None) -> Starlette:
    """The gateway's ASGI application (``settings.port``: the port it is reached on).

    Args:
        settings: how it serves.
        hello: the TARGET's hello (:meth:`Catalog.describe`), for ``/openapi.json``.
    """
    gateway = Gateway(settings, hello)

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        reaper = asyncio.create_task(gateway.reap_forever())
        try:
            yield
        finally:
            reaper.cancel()
            await gateway.sessions.close_all()

    origins = OriginPolicy(settings.port, host_names(settings.host))
    app = Starlette(
        routes=_routes(gateway.endpoints),
        middleware=[
            Middleware(Guard, origins=origins, token=settings.token, max_body=settings.max_body)
        ],
        exception_handlers={Problem: _problem, HTTPException: _http_exception, Exception: _bug},
        lifespan=lifespan,
    )
    app.state.gateway = gateway
    return app


def _routes(endpoints: list[Endpoint]) -> list[BaseRoute]:
    """Starlette's routes: one per path (so that a 405 lists every method of its path)."""
    by_path: dict[str, dict[str, Endpoint]] = {}
    for endpoint in endpoints:
        by_path.setdefault(endpoint.path, {})[endpoint.method] = endpoint
    routes: list[BaseRoute] = []
    for path, methods in by_path.items():
        if "WEBSOCKET" in methods:
            routes.append(WebSocketRoute(path, methods["WEBSOCKET"].handler))
        elif len(methods) == 1:
            ((method, endpoint),) = methods.items()
            handler = (
                JSONRoute(endpoint.handler, body_required=endpoint.body_required)
                if endpoint.json
                else endpoint.handler
            )
            routes.append(Route(path, handler, methods=[method]))
        else:
            assert not any(e.json for e in methods.values()), f"{path}: JSON routes go alone"
            routes.append(Route(path, _dispatch(methods), methods=list(methods)))
    return routes


def _dispatch(methods: dict[str, Endpoint]) -> Callable[[Request], Awaitable[Response]]:
    """One handler for a path's methods (HEAD is GET without the body)."""
    handlers = {method: endpoint.handler for method, endpoint in methods.items()}
    if "GET" in handlers:
        handlers["HEAD"] = handlers["GET"]

    async def dispatch(request: Request) -> Response:
        return await handlers[request.method](request)

    return dispatch


async def _problem(request: Request, problem: Exception) -> Response:
    assert isinstance(problem, Problem)
    return problem.response(request.url.path)


async def _http_exception(request: Request, error: Exception) -> Response:
    """Starlette's own refusals (no such route, or method) as problems."""
    assert isinstance(error, HTTPException)
    if error.status_code == 405:
        problem = Problem(
            "method_not_allowed",
            f"{request.method} is not allowed on {request.url.path}",
            headers=error.headers,
        )
    elif error.status_code == 404:
        problem = Problem(
            "not_found", f"no route {request.url.path!r:.100} (GET /openapi.json lists them)"
        )
    else:
        code = next(
            (c for c, kind in PROBLEMS.items() if kind.status == error.status_code), "bad_request"
        )
        problem = Problem(code, str(error.detail), headers=error.headers)
    return problem.response(request.url.path)


async def _bug(request: Request, error: Exception) -> Response:
    """The gateway's own bug: logged, answered as a problem; the next request is served."""
    logger.error("%s %s failed", request.method, request.url.path, exc_info=error)
    return Problem("internal_error", f"the gateway failed: {error!r:.300}").response(
        request.url.path
    )


def _package_version() -> str:
    try:
        return version("rlenv")
    except PackageNotFoundError:
        return "unknown"


class _Server(uvicorn.Server):
    """uvicorn's server, ending the gateway's streams as soon as it starts to stop."""

    def __init__(self, config: uvicorn.Config, gateway: Gateway) -> None:
        super().__init__(config)
        self._gateway = gateway

    async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
        """Stop: end the event streams at once, then uvicorn's graceful shutdown."""
        self._gateway.sessions.end_watches()
        await super().shutdown(sockets)


def serve(
    settings: Settings,
    *,
    ready: Callable[[str], None] | None = None,
    loop: str = "auto",
    http: str = "auto",
) -> None:
    """Run the gateway until SIGTERM or SIGINT (on this, the main, thread).

    Args:
        settings: how it serves (port 0: a free one).
        ready: called with the base URL (``http://HOST:PORT``) once it listens.
        loop: uvicorn's event loop (``auto``: uvloop when installed).
        http: uvicorn's HTTP implementation (``auto``: httptools when installed).

    Raises:
        InsecureBindError: a host beyond loopback without a token.
        OSError: the address cannot be bound (the port is in use, say), said in words.
        Exception: the TARGET cannot be served (checked before listening).
    """
    if settings.token is None and not is_loopback(settings.host):
        raise InsecureBindError(
            f"refusing to listen on {settings.host}: anyone who can reach it could drive the "
            "environments. Set a token (rlenv http --token, or RLENV_TOKEN) that clients must "
            "send as Authorization: Bearer, or bind 127.0.0.1"
        )
    hello = Catalog(settings.target, timeout=settings.timeout).describe()
    family = socket.AF_INET6 if ":" in settings.host else socket.AF_INET
    sock = _listen(family, settings.host, settings.port)
    settings = replace(settings, port=sock.getsockname()[1])
    app = create_app(settings, hello)
    config = uvicorn.Config(
        app,
        loop=loop,
        lifespan="on",
        http=http_protocol(
            http, head_timeout=settings.head_timeout, max_connections=settings.max_connections
        ),
        limit_concurrency=connection_limit(settings.max_connections),
        log_config=None,
        access_log=False,
        proxy_headers=False,
        server_header=False,
        ws_max_size=settings.max_body,
        ws_per_message_deflate=False,
        timeout_keep_alive=15,
        timeout_graceful_shutdown=3,
    )
    server = _Server(config, app.state.gateway)
    if ready is not None:
        shown = f"[{settings.host}]" if family == socket.AF_INET6 else settings.host
        ready(f"http://{shown}:{settings.port}")
    server.run(sockets=[sock])


def _listen(family: socket.AddressFamily, host: str, port: int) -> socket.socket:
    """A listening TCP socket whose connections never wait for Nagle's algorithm.

    uvicorn writes a response's head and body in two writes; with Nagle on, the second waits
    for the client's (delayed) acknowledgement of the first: 40 ms per request. Connections
    accepted from this socket inherit ``TCP_NODELAY`` (Linux), and asyncio's transports set it
    on sockets whose protocol is ``IPPROTO_TCP`` (uvloop on every TCP socket).
    """
    sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.bind((host, port))
        sock.listen(128)
    except OSError as error:
        sock.close()
        raise bind_error(error, host, port) from None
    except BaseException:
        sock.close()
        raise
    return sock
