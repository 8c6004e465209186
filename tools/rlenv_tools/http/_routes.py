"""The session API under ``/v1``, gym-http-api's routes done right.

==========  ====================================  =============================================
method      path                                  answer
==========  ====================================  =============================================
POST        /v1/envs                              201 ``{"id", "env_id", "action_space",
                                                  "observation_space"}``
GET         /v1/envs                              ``{"envs": [session, ...]}``
GET         /v1/envs/{id}                         the session: status, episode, step ...
DELETE      /v1/envs/{id}                         204
POST        /v1/envs/{id}/reset                   ``{"observation", "info"}``
POST        /v1/envs/{id}/step                    ``{"observation", "reward", "terminated",
                                                  "truncated", "info"}``
GET         /v1/envs/{id}/render                  ``image/png`` (or raw bytes)
GET         /v1/envs/{id}/action_space            ``{"space", "schema"}``
GET         /v1/envs/{id}/observation_space       ``{"space", "schema"}``
POST        /v1/envs/{id}/action_space/sample     ``{"action"}``
POST        /v1/envs/{id}/action_space/contains   ``{"member"}`` (and ``"reason"`` when not)
GET         /v1/envs/{id}/snapshot                ``{"snapshot"}``
POST        /v1/envs/{id}/restore                 ``{"observation", "info"}``
GET         /v1                                   versions and capabilities
==========  ====================================  =============================================

Every refusal is a problem (:mod:`rlenv_tools.http.problems`).
"""

from __future__ import annotations

import asyncio
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from starlette.requests import Request
from starlette.responses import Response

from rlenv.protocol.errors import ErrorCode
from rlenv.protocol.messages import MAX_RENDER_SIZE
from rlenv.protocol.spaces import SpaceMismatch, check
from rlenv.serving._actions import MAX_REPEAT_ACTION
from rlenv_tools.http._endpoints import (
    Answer,
    Endpoint,
    Parameter,
    json_response,
    object_body,
    read_json,
)
from rlenv_tools.http._png import encode_png
from rlenv_tools.http.json_spaces import json_schema, space_to_json
from rlenv_tools.http.problems import COMMON_HEADERS, Problem

if TYPE_CHECKING:
    from rlenv_tools.http._sessions import Session
    from rlenv_tools.http.app import Gateway

__all__ = ["component_schemas", "session_endpoints", "target_schemas"]

_CREATE_KEYS = frozenset({"env_id", "kwargs"})
_RESET_KEYS = frozenset({"seed", "options"})
_STEP_KEYS = frozenset({"action", "repeat_action"})
_ACTION = frozenset({"action"})
_RESTORE_KEYS = frozenset({"snapshot"})
_RAW = "application/octet-stream"
_ONE = "/v1/envs/{id}"
_PIXELS = {"type": "integer", "minimum": 1, "maximum": MAX_RENDER_SIZE}

_ENV = ("unknown_session",)
_CALL = (*_ENV, "environment_error", "environment_lost", ErrorCode.TIMEOUT)


class _Handlers:
    """The ``/v1`` routes' handlers, each a request to ``gateway``'s sessions."""

    def __init__(self, gateway: Gateway) -> None:
        self.gateway = gateway
        self.sessions = gateway.sessions

    def session_at(self, path: Mapping[str, str]) -> Session:
        session = self.sessions.get(path["id"])
        session.touch()
        return session

    async def step(self, path: Mapping[str, str], body: Any) -> Any:
        session = self.session_at(path)
        body = object_body(body, _STEP_KEYS, _ACTION)
        return await session.step(body["action"], body.get("repeat_action"))

    async def reset(self, path: Mapping[str, str], body: Any) -> Any:
        session = self.session_at(path)
        body = object_body(body, _RESET_KEYS)
        return await session.reset(body.get("seed"), body.get("options"))

    async def create(self, request: Request) -> Response:
        body = object_body(await read_json(request, required=False), _CREATE_KEYS)
        env_id = body.get("env_id", self.gateway.catalog.target)
        if env_id is None:
            raise Problem(
                ErrorCode.BAD_REQUEST, f"env_id is required: one of {self.gateway.catalog.ids()}"
            )
        settings = body.get("kwargs")
        if settings is not None and type(settings) is not dict:
            raise Problem(
                ErrorCode.BAD_REQUEST,
                "kwargs must be a JSON object of settings (as BaseClient.configure takes them)",
            )
        client = request.client
        session = await self.sessions.create(
            env_id, settings, owner=None if client is None else client.host
        )
        if await request.is_disconnected():  # abandoned mid-request: nobody knows its id
            await self.sessions.abandon(session)
        return json_response(
            {"id": session.id, "env_id": session.env_id, **session.spaces()},
            201,
            headers={"Location": f"/v1/envs/{session.id}"},
        )

    async def list_sessions(self, request: Request) -> Response:
        return json_response({"envs": [session.describe() for session in self.sessions.all()]})

    async def get_session(self, request: Request) -> Response:
        return json_response(self.session_at(request.path_params).describe())

    async def delete_session(self, request: Request) -> Response:
        await self.sessions.delete(request.path_params["id"])
        return Response(status_code=204, headers=COMMON_HEADERS)

    async def render(self, request: Request) -> Response:
        session = self.session_at(request.path_params)
        width, height = _size(request, "width"), _size(request, "height")
        frame = await session.render(width, height)
        if _RAW in request.headers.get("accept", ""):
            return Response(
                frame.tobytes(),
                headers={
                    **COMMON_HEADERS,
                    "X-Shape": ",".join(map(str, frame.shape)),
                    "X-Dtype": frame.dtype.name,
                },
                media_type=_RAW,
            )
        png = await asyncio.to_thread(encode_png, frame)  # zlib lets the loop go on meanwhile
        return Response(png, headers=COMMON_HEADERS, media_type="image/png")

    async def action_space(self, request: Request) -> Response:
        space = self.session_at(request.path_params).client.action_space
        return json_response(
            {"space": space_to_json(space), "schema": json_schema(space, images=False)}
        )

    async def observation_space(self, request: Request) -> Response:
        space = self.session_at(request.path_params).client.observation_space
        return json_response({"space": space_to_json(space), "schema": json_schema(space)})

    async def sample(self, request: Request) -> Response:
        return json_response({"action": self.session_at(request.path_params).sample()})

    async def contains(self, request: Request) -> Response:
        session = self.session_at(request.path_params)
        body = object_body(await read_json(request), _ACTION, _ACTION)
        try:
            check(session.client.action_space, body["action"])
        except SpaceMismatch as mismatch:
            return json_response({"member": False, "reason": str(mismatch)})
        return json_response({"member": True})

    async def snapshot(self, request: Request) -> Response:
        return json_response({"snapshot": await self.session_at(request.path_params).snapshot()})

    async def restore(self, request: Request) -> Response:
        session = self.session_at(request.path_params)
        body = object_body(await read_json(request), _RESTORE_KEYS, _RESTORE_KEYS)
        return json_response(await session.restore(body["snapshot"]))

    async def versions(self, request: Request) -> Response:
        return json_response(self.gateway.about())


def session_endpoints(gateway: Gateway) -> list[Endpoint]:
    """The ``/v1`` routes, served from ``gateway``'s sessions (the hot ones first)."""
    handlers = _Handlers(gateway)
    return [
        *_loop_endpoints(handlers),
        *_lifecycle_endpoints(handlers),
        _render_endpoint(handlers),
        *_space_endpoints(handlers),
        *_snapshot_endpoints(handlers),
        Endpoint(
            "GET",
            "/v1",
            handlers.versions,
            "versions",
            "Versions, capabilities and limits",
            "gateway",
            {200: Answer("what this gateway serves", {"type": "object"})},
        ),
    ]


def _loop_endpoints(handlers: _Handlers) -> list[Endpoint]:
    """A trainer's loop: step and reset (JSON in, JSON out, the hot routes)."""
    return [
        Endpoint(
            "POST",
            f"{_ONE}/step",
            handlers.step,
            "step",
            "Act for repeat_action physics ticks",
            "sessions",
            {200: Answer("the transition; info.frames: the ticks that ran", "Step")},
            body="StepBody",
            body_required=True,
            json=True,
            problems=(
                *_CALL,
                ErrorCode.BAD_REQUEST,
                ErrorCode.RESET_REQUIRED,
                ErrorCode.INVALID_ACTION,
                ErrorCode.BUSY,
            ),
            description="A step before a reset, or after the episode ended, is refused "
            "(409); an action outside the space too (422), naming the field.",
        ),
        Endpoint(
            "POST",
            f"{_ONE}/reset",
            handlers.reset,
            "reset",
            "Start an episode (seed 0 is a seed)",
            "sessions",
            {200: Answer("the first observation", "Reset")},
            body="ResetBody",
            json=True,
            problems=(*_CALL, ErrorCode.BAD_REQUEST, ErrorCode.BUSY),
        ),
    ]


def _lifecycle_endpoints(handlers: _Handlers) -> list[Endpoint]:
    """A session's life: create, list, describe, close."""
    return [
        Endpoint(
            "POST",
            "/v1/envs",
            handlers.create,
            "create_session",
            "Create a session",
            "sessions",
            {201: Answer("the session's id and spaces", "Created")},
            body="CreateBody",
            problems=(
                ErrorCode.BAD_REQUEST,
                "session_limit",
                "environment_error",
                "environment_lost",
                ErrorCode.INVALID_CONFIG,
                ErrorCode.TIMEOUT,
                ErrorCode.BUSY,
            ),
            description="env_id: the command line's TARGET (the default) or a registered "
            "id; kwargs: settings, as BaseClient.configure takes them.",
        ),
        Endpoint(
            "GET",
            "/v1/envs",
            handlers.list_sessions,
            "list_sessions",
            "List the sessions",
            "sessions",
            {200: Answer("every session", "SessionList")},
        ),
        Endpoint(
            "GET",
            _ONE,
            handlers.get_session,
            "get_session",
            "A session's status, episode and step",
            "sessions",
            {200: Answer("the session", "Session")},
            problems=_ENV,
        ),
        Endpoint(
            "DELETE",
            _ONE,
            handlers.delete_session,
            "delete_session",
            "Close a session and its environment",
            "sessions",
            {204: Answer("closed", media_type="")},
            problems=_ENV,
        ),
    ]


def _render_endpoint(handlers: _Handlers) -> Endpoint:
    """The current frame: a PNG, or the raw bytes."""
    return Endpoint(
        "GET",
        f"{_ONE}/render",
        handlers.render,
        "render",
        "Draw the current state",
        "sessions",
        {
            200: Answer(
                "a PNG image, or with Accept: application/octet-stream the raw "
                "uint8 bytes (X-Shape: height,width,3 and X-Dtype headers)",
                {"type": "string", "contentMediaType": "image/png"},
                "image/png",
            )
        },
        problems=(*_CALL, ErrorCode.BAD_REQUEST, ErrorCode.RESET_REQUIRED),
        query=(Parameter("width", _PIXELS, "pixels"), Parameter("height", _PIXELS, "pixels")),
    )


def _space_endpoints(handlers: _Handlers) -> list[Endpoint]:
    """The spaces: each with its JSON Schema, a random action, a membership check."""
    return [
        Endpoint(
            "GET",
            f"{_ONE}/action_space",
            handlers.action_space,
            "action_space",
            "The action space and the JSON Schema of actions",
            "sessions",
            {200: Answer("the space in gymnasium's terms, and its schema", "SpaceAnswer")},
            problems=_ENV,
        ),
        Endpoint(
            "GET",
            f"{_ONE}/observation_space",
            handlers.observation_space,
            "observation_space",
            "The observation space and the JSON Schema of observations",
            "sessions",
            {200: Answer("the space in gymnasium's terms, and its schema", "SpaceAnswer")},
            problems=_ENV,
        ),
        Endpoint(
            "POST",
            f"{_ONE}/action_space/sample",
            handlers.sample,
            "sample_action",
            "A random action",
            "sessions",
            {200: Answer("an action", "Sample")},
            problems=_ENV,
        ),
        Endpoint(
            "POST",
            f"{_ONE}/action_space/contains",
            handlers.contains,
            "action_space_contains",
            "Whether an action belongs to the action space (checked as a step would)",
            "sessions",
            {200: Answer("member, and the reason when not", "Contains")},
            body="Sample",
            body_required=True,
            problems=_ENV,
        ),
    ]


def _snapshot_endpoints(handlers: _Handlers) -> list[Endpoint]:
    """The state as data: take a snapshot, restore one."""
    return [
        Endpoint(
            "GET",
            f"{_ONE}/snapshot",
            handlers.snapshot,
            "snapshot",
            "The state as data, to restore here or in another session",
            "sessions",
            {200: Answer("the snapshot", "SnapshotBody")},
            problems=(*_CALL, ErrorCode.RESET_REQUIRED, ErrorCode.BAD_REQUEST),
        ),
        Endpoint(
            "POST",
            f"{_ONE}/restore",
            handlers.restore,
            "restore",
            "Bring the environment to a snapshot's state",
            "sessions",
            {200: Answer("the observation in the restored state", "Reset")},
            body="SnapshotBody",
            body_required=True,
            problems=(
                *_CALL,
                ErrorCode.BAD_REQUEST,
                ErrorCode.INVALID_ACTION,
                ErrorCode.INVALID_CONFIG,
                ErrorCode.BUSY,
            ),
        ),
    ]


def _size(request: Request, name: str) -> int | None:
    text = request.query_params.get(name)
    if text is None:
        return None
    if not text.isdigit() or not 1 <= int(text) <= MAX_RENDER_SIZE:
        raise Problem(
            ErrorCode.BAD_REQUEST,
            f"{name} must be an integer in [1, {MAX_RENDER_SIZE}], got {text!r:.20}",
        )
    return int(text)


# The component schemas: the bodies and answers of the session routes, by name.
_INFO: dict[str, Any] = {
    "type": "object",
    "description": "the environment's info; frames: the physics "
    "ticks that ran; agents: each agent's reward and "
    "flags (several agents)",
    "properties": {"frames": {"type": "integer", "minimum": 0}},
}
_SPACE: dict[str, Any] = {
    "type": "object",
    "required": ["type"],
    "properties": {
        "type": {"enum": ["Box", "Discrete", "MultiDiscrete", "MultiBinary", "Tuple", "Dict"]}
    },
    "description": 'a gymnasium space: {"type": "Box", "shape", "low", '
    '"high", "dtype"}, {"type": "Discrete", "n", "start"}, '
    '{"type": "Dict", "spaces"} ...',
}
_SESSION: dict[str, Any] = {
    "type": "object",
    "required": ["id", "env_id", "status", "episode", "step"],
    "properties": {
        "id": {"type": "string"},
        "env_id": {"type": "string"},
        "status": {"enum": ["ready", "running", "ended", "timed_out", "lost"]},
        "episode": {"type": "integer"},
        "step": {"type": "integer"},
        "agents": {"type": "array", "items": {"type": "string"}},
        "idle_seconds": {"type": "number"},
        "created": {"type": "string"},
        "max_episode_steps": {"type": "integer"},
        "problem": {"$ref": "#/components/schemas/Problem"},
    },
}
_SCHEMAS: dict[str, Any] = {
    "Info": _INFO,
    "Space": _SPACE,
    "CreateBody": {
        "type": "object",
        "additionalProperties": False,
        "properties": {"env_id": {"type": "string"}, "kwargs": {"type": "object"}},
    },
    "Created": {
        "type": "object",
        "required": ["id", "env_id", "action_space", "observation_space"],
        "properties": {
            "id": {"type": "string"},
            "env_id": {"type": "string"},
            "action_space": {"$ref": "#/components/schemas/Space"},
            "observation_space": {"$ref": "#/components/schemas/Space"},
        },
    },
    "Session": _SESSION,
    "SessionList": {
        "type": "object",
        "properties": {
            "envs": {"type": "array", "items": {"$ref": "#/components/schemas/Session"}}
        },
    },
    "ResetBody": {
        "type": "object",
        "additionalProperties": False,
        "properties": {
            "seed": {"type": ["integer", "null"], "minimum": 0},
            "options": {"type": ["object", "null"]},
        },
    },
    "Reset": {
        "type": "object",
        "required": ["observation", "info"],
        "properties": {
            "observation": {"$ref": "#/components/schemas/Observation"},
            "info": {"$ref": "#/components/schemas/Info"},
        },
    },
    "StepBody": {
        "type": "object",
        "required": ["action"],
        "additionalProperties": False,
        "properties": {
            "action": {"$ref": "#/components/schemas/Action"},
            "repeat_action": {"type": "integer", "minimum": 1, "maximum": MAX_REPEAT_ACTION},
        },
    },
    "Step": {
        "type": "object",
        "required": ["observation", "reward", "terminated", "truncated", "info"],
        "properties": {
            "observation": {"$ref": "#/components/schemas/Observation"},
            "reward": {"type": "number"},
            "terminated": {"type": "boolean"},
            "truncated": {"type": "boolean"},
            "info": {"$ref": "#/components/schemas/Info"},
        },
    },
    "SpaceAnswer": {
        "type": "object",
        "required": ["space", "schema"],
        "properties": {
            "space": {"$ref": "#/components/schemas/Space"},
            "schema": {"type": "object", "description": "a JSON Schema (2020-12)"},
        },
    },
    "Sample": {
        "type": "object",
        "required": ["action"],
        "properties": {"action": {"$ref": "#/components/schemas/Action"}},
    },
    "Contains": {
        "type": "object",
        "required": ["member"],
        "properties": {"member": {"type": "boolean"}, "reason": {"type": "string"}},
    },
    "SnapshotBody": {
        "type": "object",
        "required": ["snapshot"],
        "properties": {
            "snapshot": {
                "type": "object",
                "description": "the state as data: configuration, "
                "generator, actions since the reset",
            }
        },
    },
}


def component_schemas(observation: dict[str, Any], action: dict[str, Any]) -> dict[str, Any]:
    """The component schemas the session routes name (for :mod:`rlenv_tools.http._openapi`).

    Args:
        observation: the JSON Schema of observations (the TARGET's, or any value).
        action: the JSON Schema of actions.
    """
    return {"Observation": observation, "Action": action, **_SCHEMAS}


def target_schemas(gateway: Gateway) -> tuple[dict[str, Any], dict[str, Any]]:
    """The observation and action schemas of the TARGET's environment (any value without)."""
    hello = gateway.hello
    if hello is None:
        return (
            {"description": "a value of the session's observation space"},
            {"description": "a value of the session's action space"},
        )
    return json_schema(hello.observation_space), json_schema(hello.action_space, images=False)
