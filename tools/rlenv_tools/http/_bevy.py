"""bevy_rl's REST routes, in bevy_rl's own formats, on the command line's TARGET.

A bevy_rl client works unchanged against ``rlenv http TARGET``:

- ``GET /state``: the observation as JSON (several agents: an object keyed by agent);
- ``GET /visual_observations``: the current frame, ``image/png``;
- ``POST /reset`` (and ``GET /reset``, as bevy_rl 0.10 and later): ``[{"reward": 0.0,
  "is_terminated": false}, ...]``, one entry per agent;
- ``GET /step?payload=...``: the payload is URL-encoded JSON, ``[{"action": "<the action as
  JSON text>"}, ...]``, one entry per agent in the environment's order (``null``: no action
  for an agent that is done); the answer ``[{"reward": ..., "is_terminated": ...}, ...]``
  (``is_terminated``: the agent's episode is over, terminated or truncated).

They drive one session, ``bevy``, created (and reset) by the first of these requests; it is a
session like any other (``GET /v1/envs/bevy``, ``DELETE`` to start afresh). Unlike bevy_rl, a
bad payload or action is an error status with a problem body, never a 200 carrying a message,
and a step never waits beyond the gateway's deadline. Additions: ``seed`` on ``/reset`` and
``repeat_action`` on ``/step``, as query parameters.
"""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, Any

from starlette.requests import Request
from starlette.responses import Response

from rlenv.protocol.errors import ErrorCode
from rlenv.serving._actions import MAX_REPEAT_ACTION
from rlenv_tools.http._endpoints import Answer, Endpoint, Parameter, json_response, parse_json
from rlenv_tools.http._png import encode_png
from rlenv_tools.http.problems import COMMON_HEADERS, Problem

if TYPE_CHECKING:
    from rlenv_tools.http._sessions import Session
    from rlenv_tools.http.app import Gateway

__all__ = ["BEVY_SESSION", "bevy_endpoints"]

BEVY_SESSION = "bevy"
"""The id of the session bevy_rl's routes drive."""

_AGENT_STATES = {
    "type": "array",
    "items": {
        "type": "object",
        "required": ["reward", "is_terminated"],
        "properties": {"reward": {"type": "number"}, "is_terminated": {"type": "boolean"}},
    },
}
_PROBLEMS = (
    "not_found",
    "environment_error",
    "environment_lost",
    ErrorCode.TIMEOUT,
    "session_limit",
)


_PAYLOAD = Parameter(
    "payload",
    {"type": "string"},
    'URL-encoded JSON: [{"action": "<the action as JSON text>"}, ...], one entry per agent',
    required=True,
)
_REPEAT_ACTION = Parameter(
    "repeat_action",
    {"type": "integer", "minimum": 1, "maximum": MAX_REPEAT_ACTION},
    "physics ticks (default: the environment's)",
)
_SEED = Parameter(
    "seed", {"type": "integer", "minimum": 0}, "the episode's seed (an addition to bevy_rl)"
)


class _Handlers:
    """bevy_rl's handlers, each driving the ``bevy`` session of ``gateway``'s TARGET."""

    def __init__(self, gateway: Gateway) -> None:
        self.gateway = gateway

    async def session(self) -> Session:
        """The ``bevy`` session, created and reset by the first request that needs it."""
        target = self.gateway.catalog.target
        if target is None:
            raise Problem(
                "not_found",
                "bevy_rl's routes drive the command line's TARGET, and "
                "this gateway has none (rlenv http TARGET)",
            )
        return await self.gateway.sessions.shared(BEVY_SESSION, target, reset=True)

    async def state(self, request: Request) -> Response:
        return json_response(await (await self.session()).observe())

    async def visual_observations(self, request: Request) -> Response:
        frame = await (await self.session()).render()
        png = await asyncio.to_thread(encode_png, frame)
        return Response(png, headers=COMMON_HEADERS, media_type="image/png")

    async def reset(self, request: Request) -> Response:
        driven = await self.session()
        await driven.reset(_integer(request, "seed", 0))
        return json_response([{"reward": 0.0, "is_terminated": False} for _ in driven.agents])

    async def step(self, request: Request) -> Response:
        driven = await self.session()
        action = _action(request.query_params.get("payload"), driven.agents)
        answer = await driven.step(action, _integer(request, "repeat_action", 1, MAX_REPEAT_ACTION))
        if len(driven.agents) == 1:
            done = answer["terminated"] or answer["truncated"]
            return json_response([{"reward": answer["reward"], "is_terminated": done}])
        outcomes = answer["info"].get("agents", {})
        return json_response([_agent_state(outcomes.get(name)) for name in driven.agents])


def bevy_endpoints(gateway: Gateway) -> list[Endpoint]:
    """bevy_rl's four routes, on ``gateway``'s TARGET."""
    handlers = _Handlers(gateway)
    return [
        Endpoint(
            "GET",
            "/step",
            handlers.step,
            "bevy_step",
            "bevy_rl: act, one action per agent",
            "bevy_rl",
            {200: Answer("each agent's reward and whether it is done", _AGENT_STATES)},
            problems=(
                *_PROBLEMS,
                ErrorCode.BAD_REQUEST,
                ErrorCode.RESET_REQUIRED,
                ErrorCode.INVALID_ACTION,
            ),
            query=(_PAYLOAD, _REPEAT_ACTION),
        ),
        Endpoint(
            "GET",
            "/state",
            handlers.state,
            "bevy_state",
            "bevy_rl: the observation as JSON",
            "bevy_rl",
            {200: Answer("the observation", "Observation")},
            problems=(*_PROBLEMS, ErrorCode.RESET_REQUIRED),
        ),
        Endpoint(
            "GET",
            "/visual_observations",
            handlers.visual_observations,
            "bevy_visual_observations",
            "bevy_rl: the current frame",
            "bevy_rl",
            {
                200: Answer(
                    "a PNG image", {"type": "string", "contentMediaType": "image/png"}, "image/png"
                )
            },
            problems=_PROBLEMS,
        ),
        *(
            Endpoint(
                method,
                "/reset",
                handlers.reset,
                f"bevy_reset_{method.lower()}",
                "bevy_rl: start an episode",
                "bevy_rl",
                {200: Answer("each agent's state", _AGENT_STATES)},
                problems=(*_PROBLEMS, ErrorCode.BAD_REQUEST),
                query=(_SEED,),
            )
            for method in ("POST", "GET")
        ),
    ]


def _integer(request: Request, name: str, minimum: int, maximum: int | None = None) -> int | None:
    text = request.query_params.get(name)
    if text is None:
        return None
    if not text.isdigit() or int(text) < minimum:
        raise Problem(
            ErrorCode.BAD_REQUEST, f"{name} must be an integer >= {minimum}, got {text!r:.20}"
        )
    if maximum is not None and (len(text) > 20 or int(text) > maximum):
        raise Problem(ErrorCode.BAD_REQUEST, f"{name} must be at most {maximum}, got {text!r:.20}")
    return int(text)


def _action(payload: str | None, agents: tuple[str, ...]) -> Any:
    """The action of a bevy_rl payload: one agent's, or a map from agent to action."""
    shape = (
        f'[{{"action": "<the action as JSON text>"}}, ...] with one entry per agent '
        f"({len(agents)}: {list(agents)})"
    )
    if payload is None:
        raise Problem(ErrorCode.BAD_REQUEST, f"GET /step needs ?payload= (URL-encoded): {shape}")
    entries = parse_json(payload, f"the payload (expected {shape})")
    if (
        type(entries) is not list
        or len(entries) != len(agents)
        or not all(type(entry) is dict and "action" in entry for entry in entries)
    ):
        raise Problem(ErrorCode.BAD_REQUEST, f"the payload must be {shape}")
    actions = [
        parse_json(entry["action"], f"payload[{index}].action")
        if isinstance(entry["action"], str)
        else entry["action"]
        for index, entry in enumerate(entries)
    ]
    if len(agents) == 1:
        return actions[0]
    return {
        name: action for name, action in zip(agents, actions, strict=True) if action is not None
    }


def _agent_state(outcome: Any) -> dict[str, Any]:
    if not isinstance(outcome, dict):  # an agent done before this step
        return {"reward": 0.0, "is_terminated": True}
    return {
        "reward": float(outcome.get("reward", 0.0)),
        "is_terminated": bool(outcome.get("terminated") or outcome.get("truncated")),
    }
