"""The route table's record, and what every handler shares: JSON in, JSON out.

Each route is one :class:`Endpoint`: Starlette serves it (:mod:`rlenv_tools.http.app`) and the
OpenAPI document describes it (:mod:`rlenv_tools.http._openapi`) from the same record, so the two
never disagree.
"""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable, Mapping, MutableMapping
from dataclasses import dataclass
from typing import Any, NamedTuple

from starlette.requests import Request
from starlette.responses import Response

from rlenv.protocol.errors import ErrorCode
from rlenv_tools.http.json_spaces import dumps
from rlenv_tools.http.problems import COMMON_HEADERS, Problem

__all__ = [
    "JSON",
    "Answer",
    "Endpoint",
    "JSONRoute",
    "Parameter",
    "json_response",
    "object_body",
    "parse_json",
    "read_json",
]

JSON = "application/json"
_JSON_HEADERS = [
    (b"content-type", JSON.encode()),
    *((k.lower().encode(), v.encode()) for k, v in COMMON_HEADERS.items()),
]


class Answer(NamedTuple):
    """One successful answer of a route, for OpenAPI."""

    description: str
    schema: Any = None  # a JSON Schema, or the name of a component schema
    media_type: str = JSON


class Parameter(NamedTuple):
    """A query parameter, for OpenAPI."""

    name: str
    schema: dict[str, Any]
    description: str
    required: bool = False


@dataclass(frozen=True)
class Endpoint:
    """One route: its handler, and how OpenAPI describes it.

    Attributes:
        method: ``GET``, ``POST``, ``DELETE``, or ``WEBSOCKET``.
        path: Starlette's path, with ``{id}`` parameters.
        handler: ``async (Request) -> Response``; with ``json``, ``async (path_params,
            body) -> value`` (see :class:`JSONRoute`); a WebSocket's ``async (WebSocket)``.
        operation: the operation's id.
        summary: one line.
        tag: its group (``sessions``, ``streams``, ``bevy_rl``, ``gateway``).
        body: the JSON Schema of its JSON body (a name: a component schema), or ``None``.
        body_required: whether the body must be sent.
        answers: status -> answer.
        problems: the codes of the problems it may answer (see
            :data:`rlenv_tools.http.problems.PROBLEMS`), besides those every route may.
        query: its query parameters.
        description: more, for OpenAPI.
        json: the handler takes the path parameters and the JSON body and returns the JSON
            answer (served by a :class:`JSONRoute`: the hot routes).
    """

    method: str
    path: str
    handler: Callable[..., Awaitable[Any]]
    operation: str
    summary: str
    tag: str
    answers: Mapping[int, Answer]
    body: Any = None
    body_required: bool = False
    problems: tuple[str, ...] = ()
    query: tuple[Parameter, ...] = ()
    description: str = ""
    json: bool = False


class JSONRoute:
    """A route as a bare ASGI application: path parameters and JSON body in, a JSON value out.

    The hot routes (a step, a reset) use it: no request or response objects, one prepared
    list of headers. Problems it raises are answered like any route's.

    Args:
        handler: ``async (path_params, body) -> value``; ``body`` is the parsed JSON, or
            ``None`` when there is none and it is not required.
        body_required: refuse a request without a body (400).
    """

    def __init__(
        self, handler: Callable[[dict[str, str], Any], Awaitable[Any]], *, body_required: bool
    ) -> None:
        self.handler = handler
        self.body_required = body_required

    async def __call__(
        self,
        scope: MutableMapping[str, Any],
        receive: Callable[[], Awaitable[MutableMapping[str, Any]]],
        send: Callable[[MutableMapping[str, Any]], Awaitable[None]],
    ) -> None:
        """Serve one request."""
        message = await receive()
        body = message.get("body", b"")
        while message.get("more_body"):
            message = await receive()
            body += message.get("body", b"")
        answer = dumps(
            await self.handler(
                scope["path_params"],
                _parse(body, self.body_required, f"{scope['method']} {scope['path']}"),
            )
        )
        await send(
            {
                "type": "http.response.start",
                "status": 200,
                "headers": [*_JSON_HEADERS, (b"content-length", b"%d" % len(answer))],
            }
        )
        await send({"type": "http.response.body", "body": answer})


def json_response(
    value: Any, status: int = 200, headers: Mapping[str, str] | None = None
) -> Response:
    """``value`` as an ``application/json`` answer (numpy values and NaN converted)."""
    return Response(
        dumps(value),
        status,
        headers=COMMON_HEADERS if headers is None else {**COMMON_HEADERS, **headers},
        media_type=JSON,
    )


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON")


_decode = json.JSONDecoder(parse_constant=_no_constant).decode


async def read_json(request: Request, *, required: bool = True) -> Any:
    """The request's JSON body (``None`` when empty and not ``required``).

    Raises:
        Problem: ``bad_request`` (400): no body, or not JSON (NaN and Infinity are not).
    """
    return _parse(await request.body(), required, f"{request.method} {request.url.path}")


def _parse(body: bytes, required: bool, route: str) -> Any:
    if not body.strip():
        if required:
            raise Problem(ErrorCode.BAD_REQUEST, f"{route} needs a JSON body")
        return None
    return parse_json(body)


def parse_json(text: str | bytes, what: str = "the body") -> Any:
    """``text`` (UTF-8 when bytes) as a JSON value.

    Raises:
        Problem: ``bad_request`` naming ``what``: not JSON (NaN and Infinity are not).
    """
    try:
        return _decode(text if isinstance(text, str) else text.decode())
    except (ValueError, RecursionError) as error:  # UnicodeDecodeError is a ValueError
        raise Problem(ErrorCode.BAD_REQUEST, f"{what} is not JSON: {error}") from None


def object_body(
    value: Any,
    allowed: frozenset[str],
    required: frozenset[str] = frozenset(),
    what: str = "the body",
) -> dict[str, Any]:
    """``value`` checked to be a JSON object with ``required`` keys and no others.

    Raises:
        Problem: ``bad_request`` naming the missing or unknown key.
    """
    if value is None:
        value = {}
    if type(value) is not dict:
        raise Problem(
            ErrorCode.BAD_REQUEST,
            f"{what} must be a JSON object with keys {sorted(allowed)}, got {type(value).__name__}",
        )
    unknown = value.keys() - allowed
    if unknown:
        raise Problem(
            ErrorCode.BAD_REQUEST,
            f"{what} has an unknown key {sorted(unknown)[0]!r} (expected {sorted(allowed)})",
        )
    missing = required - value.keys()
    if missing:
        raise Problem(ErrorCode.BAD_REQUEST, f"{what} lacks {sorted(missing)[0]!r}")
    return value
