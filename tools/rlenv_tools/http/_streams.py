"""Streaming: a WebSocket per session for a low-latency loop, server-sent events for watchers.

``WS /v1/envs/{id}/ws`` carries typed JSON messages, one answer per message, in order:

- ``{"type": "reset", "seed"?, "options"?}`` -> ``{"type": "reset", "observation", "info"}``;
- ``{"type": "step", "action", "repeat_action"?}`` -> ``{"type": "step", "observation",
  "reward", "terminated", "truncated", "info"}``;
- ``{"type": "close"}`` -> ``{"type": "close"}``, then the gateway closes the WebSocket (the
  session stays: ``DELETE`` ends it);
- anything refused -> ``{"type": "error", "problem": {...}}`` (the problem the HTTP route
  would answer); the conversation goes on.

``GET /v1/envs/{id}/events`` is a ``text/event-stream`` of the session's transitions:
``event: reset`` / ``step`` / ``restore`` (``id``: the step's index in the episode, 0 for a
reset; ``data``: the answer, with ``episode`` and ``step``), ``status`` when the session
fails; the stream ends when the session is deleted or the gateway stops.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from typing import TYPE_CHECKING, Any

from starlette.requests import Request
from starlette.responses import Response, StreamingResponse
from starlette.websockets import WebSocket, WebSocketDisconnect

from rlenv.protocol.errors import ErrorCode
from rlenv_tools.http._endpoints import Answer, Endpoint, object_body, parse_json
from rlenv_tools.http.json_spaces import dumps
from rlenv_tools.http.problems import COMMON_HEADERS, Problem

if TYPE_CHECKING:
    from rlenv_tools.http._sessions import Session
    from rlenv_tools.http.app import Gateway

__all__ = ["deny", "stream_endpoints"]

_KEEP_ALIVE = 15.0  # seconds between comments on a quiet event stream
_MESSAGE_KEYS = {
    "reset": frozenset({"type", "seed", "options"}),
    "step": frozenset({"type", "action", "repeat_action"}),
    "close": frozenset({"type"}),
}
_STEP_REQUIRED = frozenset({"action"})
_MESSAGE: dict[str, Any] = {  # the schema of a message, for OpenAPI
    "type": "object",
    "required": ["type"],
    "properties": {"type": {"enum": ["reset", "step", "close"]}},
}


class _Handlers:
    """The streams' handlers, each on one of ``gateway``'s sessions."""

    def __init__(self, gateway: Gateway) -> None:
        self.sessions = gateway.sessions

    async def conversation(self, websocket: WebSocket) -> None:
        """A session's WebSocket: each message answered in order, until it closes."""
        sessions = self.sessions
        session_id = websocket.path_params["id"]
        try:
            session = sessions.get(session_id)
        except Problem as problem:
            await deny(websocket, problem)
            return
        await websocket.accept()
        session.websockets += 1
        receive, send = websocket.receive, websocket.send
        try:
            while True:
                message = await receive()
                if message["type"] == "websocket.disconnect":
                    return
                try:  # a text frame, or a binary one holding UTF-8 JSON
                    answer = await _answer(
                        sessions.get(session_id), message.get("text") or message.get("bytes") or b""
                    )
                except Problem as problem:
                    answer = {"type": "error", "problem": problem.to_json(websocket.url.path)}
                await send({"type": "websocket.send", "text": dumps(answer).decode()})
                if answer["type"] == "close":
                    await websocket.close(1000)
                    return
        except WebSocketDisconnect:  # gone while its answer was on the way
            return
        finally:
            session.websockets -= 1

    async def events(self, request: Request) -> Response:
        """A session's event stream."""
        session = self.sessions.get(request.path_params["id"])
        session.touch()
        queue = session.watch()
        return StreamingResponse(
            _follow(session, queue),
            media_type="text/event-stream",
            headers={**COMMON_HEADERS, "X-Accel-Buffering": "no"},
        )


def stream_endpoints(gateway: Gateway) -> list[Endpoint]:
    """The WebSocket and the event stream of each session."""
    handlers = _Handlers(gateway)
    return [
        Endpoint(
            "WEBSOCKET",
            "/v1/envs/{id}/ws",
            handlers.conversation,
            "session_websocket",
            "A WebSocket of typed JSON messages: reset, step, close",
            "streams",
            {101: Answer("switching to the WebSocket protocol", _MESSAGE, "")},
            problems=("unknown_session",),
            description='Send {"type": "reset", "seed"?, "options"?}, {"type": '
            '"step", "action", "repeat_action"?} or {"type": '
            '"close"}; each is answered with a message of the same type '
            '(the HTTP route\'s answer), or {"type": "error", "problem"}.',
        ),
        Endpoint(
            "GET",
            "/v1/envs/{id}/events",
            handlers.events,
            "session_events",
            "Follow a session's transitions (server-sent events)",
            "streams",
            {
                200: Answer(
                    "events reset, step, restore and status; id: the step's index in the episode",
                    {"type": "string"},
                    "text/event-stream",
                )
            },
            problems=("unknown_session",),
        ),
    ]


async def _answer(session: Session, text: str | bytes) -> dict[str, Any]:
    """The answer to one WebSocket message."""
    message = parse_json(text, "the message")
    kind = message.get("type") if type(message) is dict else None
    if kind not in _MESSAGE_KEYS:
        raise Problem(
            ErrorCode.BAD_REQUEST,
            "a message is a JSON object whose type is 'reset', 'step' or 'close'",
        )
    body = object_body(
        message,
        _MESSAGE_KEYS[kind],
        _STEP_REQUIRED if kind == "step" else frozenset(),
        what=f"a {kind} message",
    )
    session.touch()
    if kind == "step":
        return {"type": kind, **await session.step(body["action"], body.get("repeat_action"))}
    if kind == "reset":
        return {"type": kind, **await session.reset(body.get("seed"), body.get("options"))}
    return {"type": "close"}


async def deny(websocket: WebSocket, problem: Problem) -> None:
    """Refuse a WebSocket with the problem as an HTTP answer (or close it, 1008)."""
    if "websocket.http.response" in websocket.scope.get("extensions", {}):
        await websocket.send_denial_response(problem.response(websocket.url.path))
    else:
        await websocket.close(1008, problem.detail[:120])


async def _follow(session: Session, queue: asyncio.Queue[bytes | None]) -> AsyncIterator[bytes]:
    """The event stream: a first comment (the headers go at once), then the events."""
    try:
        yield b": events of session " + session.id.encode() + b"\n\n"
        while True:
            try:
                event = await asyncio.wait_for(queue.get(), _KEEP_ALIVE)
            except TimeoutError:
                yield b": keep-alive\n\n"
                continue
            if event is None:
                return
            yield event
    finally:
        session.unwatch(queue)
