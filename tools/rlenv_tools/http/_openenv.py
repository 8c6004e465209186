"""OpenEnv's routes (``openenv-core`` 0.3), under ``/openenv``, on the command line's TARGET.

An OpenEnv client works unchanged: ``GenericEnvClient(base_url="http://HOST:PORT/openenv")``
(or any ``EnvClient``) speaks to ``WS /openenv/ws``.

- ``WS /openenv/ws``: each connection is a session of its own on TARGET, created when it
  opens (the client's, within ``--max-sessions-per-client``) and deleted when it closes.
  Messages are OpenEnv's ``{"type", "data"}``: ``reset`` (``data``: ``seed``, ``episode_id``,
  ``options``, each optional) and ``step`` (``data``: the action, below) are answered
  ``{"type": "observation", "data": OBSERVATION}``, ``state`` ``{"type": "state", "data":
  STATE}``; ``close`` ends the session and the WebSocket, unanswered, as in OpenEnv; anything
  refused ``{"type": "error", "data": {"message", "code", "problem"}}`` (``code``: OpenEnv's
  ``INVALID_JSON``, ``UNKNOWN_TYPE``, ``VALIDATION_ERROR``, ``EXECUTION_ERROR``,
  ``CAPACITY_REACHED``, ``FACTORY_ERROR`` or ``SESSION_ERROR``; ``problem``: the problem the
  gateway's HTTP routes would answer), and the conversation goes on.
- ``POST /openenv/reset`` (``ResetRequest``: ``{"seed"?, "episode_id"?, "options"?}``),
  ``POST /openenv/step`` (``StepRequest``: ``{"action": ACTION, "request_id"?}``) answer
  ``OBSERVATION``; ``GET /openenv/state`` answers ``STATE``. They drive one shared session,
  ``openenv``, created by the first of them (``GET /v1/envs/openenv`` shows it).
- ``GET /openenv/health`` (``{"status": "healthy"}``), ``/schema`` (``{"action",
  "observation", "state"}``: JSON Schemas, from TARGET's spaces) and ``/metadata`` (OpenEnv's
  ``EnvironmentMetadata``).

ACTION is an OpenEnv ``Action``: ``{"action": VALUE, "metadata"?: {...}}``, the value as the
``/v1`` routes take it, and rlenv's ``repeat_action`` as an addition. OBSERVATION is
``{"observation": {"observation": VALUE, "metadata": {"terminated", "truncated", "info"}},
"reward", "done"}``: ``done`` is ``terminated or truncated``, and the two flags stay apart in
the metadata, where an OpenEnv ``Observation``'s ``metadata`` is read from. STATE is an OpenEnv
``State``: ``{"episode_id", "step_count", "env_id", "episode", "status"}``. Errors of the HTTP
routes are the gateway's problems.
"""

from __future__ import annotations

import uuid
import weakref
from typing import TYPE_CHECKING, Any

from starlette.requests import Request
from starlette.responses import Response
from starlette.websockets import WebSocket, WebSocketDisconnect

from rlenv.protocol.errors import ErrorCode
from rlenv.serving._actions import MAX_REPEAT_ACTION
from rlenv_tools.http._endpoints import Answer, Endpoint, json_response, object_body, parse_json
from rlenv_tools.http._routes import target_schemas
from rlenv_tools.http._streams import deny
from rlenv_tools.http.json_spaces import dumps
from rlenv_tools.http.problems import Problem

if TYPE_CHECKING:
    from rlenv_tools.http._sessions import Session
    from rlenv_tools.http.app import Gateway

__all__ = ["OPENENV_SESSION", "openenv_endpoints"]

OPENENV_SESSION = "openenv"
"""The id of the session OpenEnv's HTTP routes drive."""

_PREFIX = "/openenv"
_RESET_KEYS = frozenset({"seed", "episode_id", "options"})
_ACTION_KEYS = frozenset({"action", "metadata", "repeat_action"})
_STEP_KEYS = frozenset({"action", "request_id"})
_ACTION = frozenset({"action"})
_TYPE = frozenset({"type"})
_MESSAGE_KEYS = frozenset({"type", "data"})
_MAX_EPISODE_ID = 255  # characters, as OpenEnv's ResetRequest
_WS_CODES = {  # the problems' codes as OpenEnv's WSErrorCode
    ErrorCode.BAD_REQUEST: "VALIDATION_ERROR",
    ErrorCode.INVALID_ACTION: "VALIDATION_ERROR",
    ErrorCode.INVALID_CONFIG: "VALIDATION_ERROR",
    ErrorCode.TIMEOUT: "SESSION_ERROR",
    "environment_lost": "SESSION_ERROR",
}
_PROBLEMS = ("not_found", "environment_error", "environment_lost", ErrorCode.TIMEOUT)


class _Handlers:
    """OpenEnv's handlers on ``gateway``'s TARGET."""

    def __init__(self, gateway: Gateway) -> None:
        self.gateway = gateway
        self.sessions = gateway.sessions
        self.episode_ids: weakref.WeakKeyDictionary[Session, str] = weakref.WeakKeyDictionary()

    def target(self) -> str:
        target = self.gateway.catalog.target
        if target is None:
            raise Problem(
                "not_found",
                "OpenEnv's routes serve the command line's TARGET, and this gateway has "
                "none (rlenv http TARGET)",
            )
        return target

    async def shared(self) -> Session:
        return await self.sessions.shared(OPENENV_SESSION, self.target())

    # --- what both the WebSocket and the HTTP routes answer ---------------------------------

    async def reset(self, session: Session, data: Any) -> dict[str, Any]:
        body = object_body(data, _RESET_KEYS, what="a reset's data")
        episode_id = body.get("episode_id")
        if episode_id is not None and (
            type(episode_id) is not str or len(episode_id) > _MAX_EPISODE_ID
        ):
            raise Problem(
                ErrorCode.BAD_REQUEST,
                f"episode_id must be a string of at most {_MAX_EPISODE_ID} characters",
            )
        session.touch()
        answer = await session.reset(body.get("seed"), body.get("options"))
        self.episode_ids[session] = episode_id or str(uuid.uuid4())
        return _observation(answer)

    async def step(self, session: Session, data: Any) -> dict[str, Any]:
        body = object_body(data, _ACTION_KEYS, _ACTION, what="an action")
        if type(body.get("metadata", {})) is not dict:
            raise Problem(ErrorCode.BAD_REQUEST, "an action's metadata must be a JSON object")
        session.touch()
        return _observation(await session.step(body["action"], body.get("repeat_action")))

    def state(self, session: Session) -> dict[str, Any]:
        session.touch()
        return {
            "episode_id": self.episode_ids.get(session),
            "step_count": session.step_index,
            "env_id": session.env_id,
            "episode": session.episode,
            "status": session.status.value,
        }

    # --- the WebSocket ----------------------------------------------------------------------

    async def conversation(self, websocket: WebSocket) -> None:
        """A session of its own, answering each message in order, until it closes."""
        try:
            target = self.target()
        except Problem as problem:
            await deny(websocket, problem)
            return
        await websocket.accept()
        client = websocket.client
        try:
            session = await self.sessions.create(
                target, owner=None if client is None else client.host
            )
        except Problem as problem:  # full: try again later (1013); else an internal error
            full = problem.code == "session_limit"
            code = "CAPACITY_REACHED" if full else "FACTORY_ERROR"
            await _send(websocket, _error(problem, code, websocket.url.path))
            await websocket.close(1013 if full else 1011, problem.detail[:120])
            return
        session.websockets += 1
        try:
            while True:
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    return
                answer = await self.answer(
                    session, message.get("text") or message.get("bytes") or b"", websocket
                )
                if answer is None:  # close: the session ends first, then the WebSocket
                    break
                await _send(websocket, answer)
        except WebSocketDisconnect:  # gone while its answer was on the way
            return
        finally:
            session.websockets -= 1
            if self.sessions.find(session.id) is session:
                await self.sessions.delete(session.id)
        await websocket.close(1000)

    async def answer(
        self, session: Session, text: str | bytes, websocket: WebSocket
    ) -> dict[str, Any] | None:
        """The answer to one message (``None``: close)."""
        path = websocket.url.path
        try:
            message = parse_json(text, "the message")
        except Problem as problem:
            return _error(problem, "INVALID_JSON", path)
        kind = message.get("type") if type(message) is dict else None
        if kind not in ("reset", "step", "state", "close"):
            return _error(
                Problem(
                    ErrorCode.BAD_REQUEST,
                    f"unknown message type {kind!r:.40}: a message is a JSON object "
                    "whose type is 'reset', 'step', 'state' or 'close'",
                ),
                "UNKNOWN_TYPE",
                path,
            )
        try:
            body = object_body(
                message,
                _MESSAGE_KEYS if kind in ("reset", "step") else _TYPE,
                _MESSAGE_KEYS if kind == "step" else _TYPE,
                what=f"a {kind} message",
            )
            if kind == "reset":
                return {"type": "observation", "data": await self.reset(session, body.get("data"))}
            if kind == "step":
                return {"type": "observation", "data": await self.step(session, body["data"])}
            if kind == "state":
                return {"type": "state", "data": self.state(session)}
            return None
        except Problem as problem:
            return _error(problem, _WS_CODES.get(problem.code, "EXECUTION_ERROR"), path)

    # --- the HTTP routes --------------------------------------------------------------------

    async def http_reset(self, path: dict[str, str], body: Any) -> Any:
        return await self.reset(await self.shared(), body)

    async def http_step(self, path: dict[str, str], body: Any) -> Any:
        request = object_body(body, _STEP_KEYS, _ACTION, what="a step request")
        return await self.step(await self.shared(), request["action"])

    async def http_state(self, request: Request) -> Response:
        return json_response(self.state(await self.shared()))

    async def health(self, request: Request) -> Response:
        return json_response({"status": "healthy"})

    async def schema(self, request: Request) -> Response:
        self.target()
        observation, action = target_schemas(self.gateway)
        return json_response(
            {
                "action": _action_schema(action),
                "observation": _observation_schema(observation),
                "state": _STATE,
            }
        )

    async def metadata(self, request: Request) -> Response:
        target = self.target()
        hello = self.gateway.hello
        described = (
            target if hello is None else f"{hello.environment} (agents: {', '.join(hello.agents)})"
        )
        return json_response(
            {
                "name": target,
                "description": f"rlenv's {described}, served by rlenv http: each WebSocket "
                "a session of its own; GET /openenv/schema gives its action and observation",
                "readme_content": None,
                "version": self.gateway.about()["rlenv"],
                "author": None,
                "documentation_url": None,
            }
        )


def openenv_endpoints(gateway: Gateway) -> list[Endpoint]:
    """OpenEnv's seven routes under ``/openenv``, on ``gateway``'s TARGET."""
    handlers = _Handlers(gateway)
    return [*_session_endpoints(handlers), *_about_endpoints(handlers)]


def _openenv(
    method: str,
    name: str,
    handler: Any,
    summary: str,
    answers: dict[int, Answer],
    operation: str | None = None,
    **more: Any,
) -> Endpoint:
    """The OpenEnv route ``/openenv/NAME``, tagged ``openenv``.

    Its operation is ``openenv_NAME`` (or ``operation``), its summary ``OpenEnv: SUMMARY``;
    ``more`` are :class:`Endpoint`'s other fields.
    """
    return Endpoint(
        method,
        f"{_PREFIX}/{name}",
        handler,
        operation or f"openenv_{name}",
        f"OpenEnv: {summary}",
        "openenv",
        answers,
        **more,
    )


def _session_endpoints(handlers: _Handlers) -> list[Endpoint]:
    """The routes that drive sessions: the WebSocket's own; step, reset, state on the shared one."""
    step_problems = (
        *_PROBLEMS,
        ErrorCode.BAD_REQUEST,
        ErrorCode.RESET_REQUIRED,
        ErrorCode.INVALID_ACTION,
        "session_limit",
    )
    return [
        _openenv(
            "WEBSOCKET",
            "ws",
            handlers.conversation,
            "a session of its own, messages {type, data}: reset, step, state, close",
            {101: Answer("switching to the WebSocket protocol", _WS_MESSAGE, "")},
            operation="openenv_websocket",
            problems=("not_found",),
            description='Send {"type": "reset", "data": {"seed"?, "episode_id"?, "options"?}}, '
            '{"type": "step", "data": {"action", "metadata"?, "repeat_action"?}}, {"type": '
            '"state"} or {"type": "close"}; answered {"type": "observation", "data"}, {"type": '
            '"state", "data"}, or {"type": "error", "data": {"message", "code", "problem"}}.',
        ),
        _openenv(
            "POST",
            "step",
            handlers.http_step,
            "act in the shared session openenv",
            {200: Answer("OpenEnv's StepResponse", _OBSERVATION_ANSWER)},
            body={
                "type": "object",
                "required": ["action"],
                "additionalProperties": False,
                "properties": {
                    "action": _action_schema({"$ref": "#/components/schemas/Action"}),
                    "request_id": {"type": "string"},
                },
            },
            body_required=True,
            json=True,
            problems=step_problems,
        ),
        _openenv(
            "POST",
            "reset",
            handlers.http_reset,
            "start an episode of the shared session openenv",
            {200: Answer("OpenEnv's ResetResponse", _OBSERVATION_ANSWER)},
            body=_RESET_SCHEMA,
            json=True,
            problems=(*_PROBLEMS, ErrorCode.BAD_REQUEST, "session_limit"),
        ),
        _openenv(
            "GET",
            "state",
            handlers.http_state,
            "the shared session's State",
            {200: Answer("OpenEnv's State", _STATE)},
            problems=(*_PROBLEMS, "session_limit"),
        ),
    ]


def _about_endpoints(handlers: _Handlers) -> list[Endpoint]:
    """The routes that describe TARGET: health, schema, metadata."""
    return [
        _openenv(
            "GET",
            "health",
            handlers.health,
            "health",
            {200: Answer("healthy", {"type": "object", "properties": {"status": {}}})},
        ),
        _openenv(
            "GET",
            "schema",
            handlers.schema,
            "the JSON Schemas of actions, observations and states",
            {200: Answer("OpenEnv's SchemaResponse", {"type": "object"})},
            problems=("not_found",),
        ),
        _openenv(
            "GET",
            "metadata",
            handlers.metadata,
            "the environment's metadata",
            {200: Answer("OpenEnv's EnvironmentMetadata", {"type": "object"})},
            problems=("not_found",),
        ),
    ]


def _observation(answer: dict[str, Any]) -> dict[str, Any]:
    """A session's answer (a reset's or a step's) as OpenEnv's observation payload."""
    terminated = answer.get("terminated", False)
    truncated = answer.get("truncated", False)
    return {
        "observation": {
            "observation": answer["observation"],
            "metadata": {"terminated": terminated, "truncated": truncated, "info": answer["info"]},
        },
        "reward": answer.get("reward"),
        "done": terminated or truncated,
    }


def _error(problem: Problem, code: str, path: str) -> dict[str, Any]:
    return {
        "type": "error",
        "data": {"message": problem.detail, "code": code, "problem": problem.to_json(path)},
    }


async def _send(websocket: WebSocket, message: dict[str, Any]) -> None:
    await websocket.send({"type": "websocket.send", "text": dumps(message).decode()})


def _action_schema(value: dict[str, Any]) -> dict[str, Any]:
    return {
        "type": "object",
        "required": ["action"],
        "additionalProperties": False,
        "properties": {
            "action": value,
            "metadata": {"type": "object"},
            "repeat_action": {"type": "integer", "minimum": 1, "maximum": MAX_REPEAT_ACTION},
        },
    }


def _observation_schema(value: dict[str, Any]) -> dict[str, Any]:
    return {
        "type": "object",
        "required": ["observation", "metadata"],
        "properties": {
            "observation": value,
            "metadata": {
                "type": "object",
                "required": ["terminated", "truncated", "info"],
                "properties": {
                    "terminated": {"type": "boolean"},
                    "truncated": {"type": "boolean"},
                    "info": {"type": "object"},
                },
            },
            "done": {"type": "boolean"},
            "reward": {"type": ["number", "null"]},
        },
    }


_OBSERVATION_ANSWER: dict[str, Any] = {
    "type": "object",
    "required": ["observation", "reward", "done"],
    "properties": {
        "observation": _observation_schema({"$ref": "#/components/schemas/Observation"}),
        "reward": {"type": ["number", "null"]},
        "done": {"type": "boolean"},
    },
}
_STATE: dict[str, Any] = {
    "type": "object",
    "required": ["episode_id", "step_count"],
    "properties": {
        "episode_id": {"type": ["string", "null"]},
        "step_count": {"type": "integer", "minimum": 0},
        "env_id": {"type": "string"},
        "episode": {"type": "integer", "minimum": 0},
        "status": {"enum": ["ready", "running", "ended", "timed_out", "lost"]},
    },
}
_RESET_SCHEMA: dict[str, Any] = {
    "type": "object",
    "additionalProperties": False,
    "properties": {
        "seed": {"type": ["integer", "null"], "minimum": 0},
        "episode_id": {"type": ["string", "null"], "maxLength": _MAX_EPISODE_ID},
        "options": {"type": ["object", "null"]},
    },
}
_WS_MESSAGE: dict[str, Any] = {
    "type": "object",
    "required": ["type"],
    "properties": {"type": {"enum": ["reset", "step", "state", "close"]}, "data": {}},
}
