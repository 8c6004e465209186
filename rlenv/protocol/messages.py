"""Messages: what travels in a frame, as typed records with ``to_wire`` / ``from_wire``.

::

    hello    {"hello": {"protocol": [2, 1], "environment": ..., "action_space": {...}, ...}}
    request  {"id": 7, "token": "...", <parts>}     parts: config, reset, action, observation...
    response {"id": 7, "observation": {"agent": ...}, "reward": 1.0, "terminated": false,
              "truncated": false, "info": {...}, "frames": 4}
    error    {"id": 7, "error": {"code": "invalid_action", "message": ..., "fatal": false}}
    batch    {"id": 8, "batch": [{...response or error...}, null, ...]}
    steps    {"id": 9, "steps": {"observation": ..., "reward": <K f8>, "terminated": <K b1>,
              "truncated": <K b1>, "frames": <K i8>, "info": [{...}, ...], "errors": [...]}}

A request is an envelope (``id``, and ``token`` where the server asks for one) around **parts**.
The protocol leaves the parts to the server, which checks and applies each one by the record
of its kind (:mod:`rlenv.serving._parts`); :class:`Request` carries them as a map. Replies are
built by the server directly as these records and read back by the client with validation.

Columns of a steps reply (rewards, flags, tick counts) travel as raw little-endian bytes, one
value per instance; observations travel in their space's packed form (:mod:`rlenv.protocol.spaces`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np
from gymnasium import spaces

from rlenv.protocol.errors import ErrorCode, ProtocolVersionError, RemoteProtocolError
from rlenv.protocol.spaces import space_from_spec, space_to_spec

__all__ = [
    "MAX_REPEAT_ACTION",
    "MAX_RENDER_SIZE",
    "PROTOCOL_VERSION",
    "BatchResponse",
    "ErrorReply",
    "GroupSpec",
    "Hello",
    "Message",
    "Reply",
    "Request",
    "Response",
    "StepsResponse",
    "joint_end",
]

PROTOCOL_VERSION: Final = (2, 7)
"""(major, minor). Peers with different majors refuse each other; a newer minor only adds."""

MAX_REPEAT_ACTION: Final = 10_000
"""The most ticks one action may run: a request's or a ``steps`` request's ``repeat_action``, a
configured one, a restored snapshot's, a recording's (the hello's ``limits.max_repeat_action``,
protocol 2.6).

Trainers skip 1 to a few dozen frames; 10,000 ticks are almost three minutes at 60 ticks a
second, and a few tenths of a second of the server's loop for the examples (10 to 50 us a
tick), so that one request never holds the loop long enough for other clients to time out."""
MAX_RENDER_SIZE: Final = 4096
"""The largest ``width`` or ``height`` a ``render`` may ask for (over TCP and HTTP alike)."""

_REWARD = np.dtype("<f8")
_FRAMES = np.dtype("<i8")
_FLAG = np.dtype("|u1")


@dataclass(frozen=True, slots=True)
class GroupSpec:
    """A group of agents (protocol 2.7): its most members and one member's spaces.

    The group is one agent of the hello's ``agents``, whose spaces are these stacked over
    ``instance_count`` members (docs/protocol.md, "Swarms").
    """

    instance_count: int
    observation_space: spaces.Space
    action_space: spaces.Space

    def to_wire(self) -> dict[str, Any]:
        """The group's entry in the hello's ``groups``."""
        return {
            "instance_count": self.instance_count,
            "observation_space": space_to_spec(self.observation_space),
            "action_space": space_to_spec(self.action_space),
        }

    @classmethod
    def from_wire(cls, wire: Any) -> GroupSpec:
        """Read a hello's group entry.

        Raises:
            TypeError: it is not a map with a positive ``instance_count`` and two spaces.
        """
        count = wire["instance_count"]
        if type(count) is not int or count < 1:
            raise TypeError(f"a group's instance_count must be an int >= 1, got {count!r:.40}")
        return cls(
            count, space_from_spec(wire["observation_space"]), space_from_spec(wire["action_space"])
        )


@dataclass(slots=True)
class Hello:
    """What the server says first: who it is, what its spaces are, how many instances.

    ``render_size`` (protocol 2.1) is the (width, height) of a render that asks for no size.
    ``limits`` (protocol 2.1) holds the server's sizes and deadlines: ``max_frame_size`` (the
    largest request frame), ``max_first_frame_size`` (the same, until the first request),
    ``max_reply_size`` (the largest frame it sends), ``max_frame_objects`` (the most msgpack
    objects a frame may hold, either way; protocol 2.5), ``frame_deadline``, ``idle_timeout``
    (``None``: never) and ``write_timeout`` in seconds, and ``max_connections``; and what one
    request may ask (protocol 2.6): ``max_repeat_action`` (the ticks of one action),
    ``max_level_nodes`` and ``max_level_depth`` (a level's data). Empty from a 2.0 server.
    ``target`` (protocol 2.5) is the ``MODULE:CLASS`` another server of the same environment
    is started with (``rlenv serve TARGET``), or ``None`` when the server cannot name one (an
    environment object, a class defined in ``__main__``) or is older.
    ``driven`` (protocol 2.6) names the agents the server drives itself (``rlenv serve
    --policy``: a policy file or the agent's heuristic), in ``agents``' order; empty when none
    is, or from an older server. A trainer leaves them out: it needs no actions for them.
    ``possible_agents`` (protocol 2.6) maps each name that may appear in an episode to its
    class's name, in ``agents``' order, when agents come and go or decide at their own pace:
    then an answer holds only the agents due to decide and those that left (docs/protocol.md,
    "Agents that come and go"). ``None`` when every agent is in every answer.
    ``groups`` (protocol 2.7) maps each agent of ``agents`` that is a group of agents
    (``rlenv.RLAgentGroup``) to its :class:`GroupSpec`; empty when none is, or from an older
    server. An environment with a group has keyed spaces and outcomes (docs/protocol.md,
    "Swarms").
    """

    environment: str
    action_space: spaces.Space
    observation_space: spaces.Space
    agents: tuple[str, ...] = ("agent",)
    physics_ticks_per_second: int = 60
    repeat_action: int = 4
    render_modes: tuple[str, ...] = ()
    render_size: tuple[int, int] | None = None
    token_required: bool = False
    instances: int = 1
    limits: dict[str, Any] = field(default_factory=dict)
    target: str | None = None
    driven: tuple[str, ...] = ()
    possible_agents: dict[str, str] | None = None
    groups: dict[str, GroupSpec] = field(default_factory=dict)
    protocol: tuple[int, int] = PROTOCOL_VERSION

    def to_wire(self) -> dict[str, Any]:
        """The message as a msgpack-ready map."""
        return {
            "hello": {
                "protocol": list(self.protocol),
                "environment": self.environment,
                "action_space": space_to_spec(self.action_space),
                "observation_space": space_to_spec(self.observation_space),
                "agents": list(self.agents),
                "physics_ticks_per_second": self.physics_ticks_per_second,
                "repeat_action": self.repeat_action,
                "render_modes": list(self.render_modes),
                "render_size": None if self.render_size is None else list(self.render_size),
                "token_required": self.token_required,
                "instances": self.instances,
                "limits": self.limits,
                "target": self.target,
                "driven": list(self.driven),
                "possible_agents": self.possible_agents,
                "groups": {name: group.to_wire() for name, group in self.groups.items()},
            }
        }

    @classmethod
    def from_wire(cls, wire: Mapping[str, Any]) -> Hello:
        """Read a hello map.

        Raises:
            ProtocolVersionError: the server speaks another major version.
            RemoteProtocolError: the map is not a valid hello.
        """
        body = wire["hello"]
        if not isinstance(body, Mapping):
            raise RemoteProtocolError("hello must be a map")
        version = body.get("protocol")
        if not (isinstance(version, list) and len(version) == 2):
            raise RemoteProtocolError(f"hello carries no protocol version: {version!r:.80}")
        if version[0] != PROTOCOL_VERSION[0]:
            raise ProtocolVersionError(
                f"server speaks rlenv protocol {version[0]}.{version[1]}, this client speaks "
                f"{PROTOCOL_VERSION[0]}.{PROTOCOL_VERSION[1]}; install matching versions"
            )
        try:
            return cls(
                environment=str(body["environment"]),
                action_space=space_from_spec(body["action_space"]),
                observation_space=space_from_spec(body["observation_space"]),
                agents=tuple(body["agents"]),
                physics_ticks_per_second=int(body["physics_ticks_per_second"]),
                repeat_action=int(body["repeat_action"]),
                render_modes=tuple(body["render_modes"]),
                render_size=_size(body.get("render_size")),
                token_required=bool(body.get("token_required", False)),
                instances=int(body.get("instances", 1)),
                limits=dict(body.get("limits", {})),
                target=_target(body.get("target")),
                driven=_driven(body.get("driven", []), body["agents"]),
                possible_agents=_possible(body.get("possible_agents"), body["agents"]),
                groups=_groups(body.get("groups", {}), body["agents"]),
                protocol=(int(version[0]), int(version[1])),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise RemoteProtocolError(f"invalid hello: {exc!r}") from None


def _possible(value: Any, agents: Any) -> dict[str, str] | None:
    """A hello's possible agents: nil, or a map from each of ``agents`` to a class name."""
    if value is None:
        return None
    if not (
        isinstance(value, Mapping)
        and list(value) == list(agents)
        and all(isinstance(name, str) for name in value.values())
    ):
        raise TypeError(
            f"possible_agents must map each of agents, in order, to a class name, got {value!r:.80}"
        )
    return dict(value)


def _groups(value: Any, agents: Any) -> dict[str, GroupSpec]:
    """A hello's groups: a map from some of its ``agents`` to their group specs (2.7)."""
    if not (isinstance(value, Mapping) and all(name in agents for name in value)):
        raise TypeError(f"groups must map some of the agents to groups, got {value!r:.80}")
    return {str(name): GroupSpec.from_wire(group) for name, group in value.items()}


def _target(value: Any) -> str | None:
    """A hello's target: ``MODULE:CLASS``, or nil (absent from servers before 2.5)."""
    if value is not None and not isinstance(value, str):
        raise TypeError(f"target must be a string or nil, got {value!r:.80}")
    return value


def _driven(value: Any, agents: Any) -> tuple[str, ...]:
    """A hello's driven agents: names among its ``agents`` (absent from servers before 2.6)."""
    if not isinstance(value, list) or not all(name in agents for name in value):
        raise ValueError(f"driven must list some of the agents {agents!r:.80}, got {value!r:.80}")
    return tuple(value)


def _size(value: Any) -> tuple[int, int] | None:
    """A hello's render size: ``[width, height]``, or nil (absent from 2.0 servers)."""
    if value is None:
        return None
    width, height = value
    return int(width), int(height)


@dataclass(slots=True)
class Request:
    """One request: its id, its parts (a map from part name to value) and maybe a token.

    The server applies the parts it knows in its own order and refuses unknown ones; see
    ``docs/protocol.md`` for the parts and :mod:`rlenv.serving._parts` for how each is served.
    """

    id: int
    parts: dict[str, Any] = field(default_factory=dict)
    token: str | None = None

    def to_wire(self) -> dict[str, Any]:
        """The message as a msgpack-ready map."""
        wire = {"id": self.id, **self.parts}
        if self.token is not None:
            wire["token"] = self.token
        return wire

    @classmethod
    def from_wire(cls, wire: dict[str, Any]) -> Request:
        """Read a request map (which it takes apart: the map becomes the parts).

        Raises:
            RemoteProtocolError: ``bad_request``: no integer id, or a token that is not a
                string (with the id, when it could be read).
        """
        request_id = wire.pop("id", None)
        if type(request_id) is not int:
            raise RemoteProtocolError(
                f"request 'id' must be an integer, got {request_id!r:.40}", ErrorCode.BAD_REQUEST
            )
        token = wire.pop("token", None)
        if token is not None and type(token) is not str:
            raise RemoteProtocolError(
                "'token' must be a string", ErrorCode.BAD_REQUEST, request_id=request_id
            )
        return cls(request_id, wire, token)

    def __repr__(self) -> str:  # never show a token in logs
        parts = ", ".join(f"{name}={value!r:.80}" for name, value in self.parts.items())
        token = ", token=..." if self.token is not None else ""
        return f"Request(id={self.id}{', ' if parts else ''}{parts}{token})"


@dataclass(slots=True)
class Response:
    """The answer to a request that succeeded.

    ``observation`` maps what was asked (``agent``, ``world``, ``render``) to its value; the
    agent observation is in its space's packed form. ``reward`` is the sum over the ticks since
    the previous answer, ``frames`` how many ticks ran. ``agents`` holds, for several agents,
    each one's ``{"reward", "terminated", "truncated"}``.
    """

    id: int
    observation: dict[str, Any] | None = None
    reward: float = 0.0
    terminated: bool = False
    truncated: bool = False
    info: dict[str, Any] = field(default_factory=dict)
    frames: int = 0
    agents: dict[str, dict[str, Any]] | None = None

    def to_wire(self) -> dict[str, Any]:
        """The message as a msgpack-ready map."""
        wire = {
            "id": self.id,
            "observation": self.observation,
            "reward": self.reward,
            "terminated": self.terminated,
            "truncated": self.truncated,
            "info": self.info,
            "frames": self.frames,
        }
        if self.agents is not None:
            wire["agents"] = self.agents
        return wire

    @classmethod
    def from_wire(cls, wire: Mapping[str, Any]) -> Response:
        """Read a response map.

        Raises:
            RemoteProtocolError: a field is missing or has the wrong type.
        """
        try:
            reply_id, reward, frames = wire["id"], wire["reward"], wire["frames"]
            terminated, truncated = wire["terminated"], wire["truncated"]
            observation, info, agents = wire["observation"], wire["info"], wire.get("agents")
        except KeyError as missing:
            raise RemoteProtocolError(f"invalid response: no {missing}") from None
        if reward.__class__ is not float:
            if reward.__class__ is not int:
                raise _wrong("reward", reward)
            reward = float(reward)
        if frames.__class__ is not int:
            raise _wrong("frames", frames)
        if terminated.__class__ is not bool or truncated.__class__ is not bool:
            raise _wrong("terminated and truncated", (terminated, truncated))
        if info.__class__ is not dict:
            raise _wrong("info", info)
        if not (observation is None or observation.__class__ is dict) or not (
            agents is None or agents.__class__ is dict
        ):
            raise _wrong("observation and agents", (observation, agents))
        return cls(reply_id, observation, reward, terminated, truncated, info, frames, agents)


def _wrong(field: str, value: Any) -> RemoteProtocolError:
    return RemoteProtocolError(f"invalid response: {field} of the wrong type: {value!r:.100}")


@dataclass(slots=True)
class ErrorReply:
    """The answer to a request that failed, or a refusal of the connection (``id`` None)."""

    id: int | None
    code: str
    message: str
    fatal: bool = False

    def to_wire(self) -> dict[str, Any]:
        """The message as a msgpack-ready map."""
        return {
            "id": self.id,
            "error": {"code": str(self.code), "message": self.message, "fatal": self.fatal},
        }

    @classmethod
    def from_wire(cls, wire: Mapping[str, Any]) -> ErrorReply:
        """Read an error reply map.

        Raises:
            RemoteProtocolError: a field is missing or has the wrong type.
        """
        try:
            error = wire["error"]
            return cls(
                id=wire.get("id"),
                code=str(error["code"]),
                message=str(error["message"]),
                fatal=bool(error.get("fatal", False)),
            )
        except (KeyError, TypeError) as exc:
            raise RemoteProtocolError(f"invalid error reply: {exc!r}") from None


@dataclass(slots=True)
class BatchResponse:
    """The answer to a batch request: one reply per instance (``None`` where none was asked)."""

    id: int
    replies: tuple[Response | ErrorReply | None, ...]

    def to_wire(self) -> dict[str, Any]:
        """The message as a msgpack-ready map."""
        return {
            "id": self.id,
            "batch": [None if reply is None else reply.to_wire() for reply in self.replies],
        }

    @classmethod
    def from_wire(cls, wire: Mapping[str, Any]) -> BatchResponse:
        """Read a batch response map.

        Raises:
            RemoteProtocolError: a reply is malformed.
        """
        batch, reply_id = wire["batch"], wire.get("id")
        if not isinstance(batch, list) or type(reply_id) is not int:
            raise RemoteProtocolError("invalid batch response: 'batch' is not a list, or no id")
        replies: list[Response | ErrorReply | None] = []
        for reply in batch:
            if reply is None:
                replies.append(None)
            elif not isinstance(reply, Mapping):
                raise RemoteProtocolError("invalid batch response: a reply is not a map")
            else:
                replies.append(
                    ErrorReply.from_wire(reply) if "error" in reply else Response.from_wire(reply)
                )
        return cls(id=reply_id, replies=tuple(replies))


@dataclass(slots=True)
class StepsResponse:
    """The answer to a ``steps`` request: one column per field, one row per instance.

    ``observation`` stacks every instance's agent observation, in the packed form of the batched
    observation space (gymnasium's ``batch_space`` layout); ``reward`` (float64),
    ``terminated``, ``truncated`` (bool) and ``frames`` (int64) are arrays of length K; ``info``
    holds one map per instance (``agents`` in it for several agents). ``errors`` is ``None``
    when every instance succeeded, else one entry per instance: ``None`` or the
    :class:`ErrorReply` of an instance that failed (its row of the other columns is
    meaningless). ``due`` (protocol 2.6), while agents come and go: for each possible agent, K
    bools, whether it is in that row's answer (the ``observation`` column holds zeros where it
    is not); ``None`` otherwise.
    """

    id: int
    observation: Any
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    frames: np.ndarray
    info: tuple[dict[str, Any], ...]
    errors: tuple[ErrorReply | None, ...] | None = None
    due: dict[str, np.ndarray] | None = None

    def to_wire(self) -> dict[str, Any]:
        """The message as a msgpack-ready map (the numeric columns as raw bytes)."""
        columns: dict[str, Any] = {
            "observation": self.observation,
            "reward": np.asarray(self.reward, _REWARD).tobytes(),
            "terminated": np.asarray(self.terminated, _FLAG).tobytes(),
            "truncated": np.asarray(self.truncated, _FLAG).tobytes(),
            "frames": np.asarray(self.frames, _FRAMES).tobytes(),
            "info": list(self.info),
        }
        if self.errors is not None:
            columns["errors"] = [
                None if error is None else error.to_wire()["error"] for error in self.errors
            ]
        if self.due is not None:
            columns["due"] = {
                name: np.asarray(flags, _FLAG).tobytes() for name, flags in self.due.items()
            }
        return {"id": self.id, "steps": columns}

    @classmethod
    def from_wire(cls, wire: Mapping[str, Any]) -> StepsResponse:
        """Read a steps response map.

        Raises:
            RemoteProtocolError: a column is missing or has the wrong type or length.
        """
        columns = wire["steps"]
        try:
            info = columns["info"]
            size = len(info)
            reward = _column(columns["reward"], _REWARD, size)
            terminated, truncated = (
                _column(columns[name], _FLAG, size).astype(np.bool_)
                for name in ("terminated", "truncated")
            )
            frames = _column(columns["frames"], _FRAMES, size)
            errors = columns.get("errors")
            if errors is not None:
                if len(errors) != size:
                    raise ValueError(f"{len(errors)} errors for {size} instances")
                errors = tuple(
                    None
                    if error is None
                    else ErrorReply.from_wire({"id": wire["id"], "error": error})
                    for error in errors
                )
            if not all(type(item) is dict for item in info):
                raise ValueError("an info that is not a map")
            due = columns.get("due")
            if due is not None:
                due = {str(name): _column(flags, _FLAG, size).astype(np.bool_)
                       for name, flags in due.items()}  # fmt: skip
            return cls(
                id=wire["id"],
                observation=columns["observation"],
                reward=reward,
                terminated=terminated,
                truncated=truncated,
                frames=frames,
                info=tuple(info),
                errors=errors,
                due=due,
            )
        except (KeyError, TypeError, ValueError, RemoteProtocolError) as exc:
            raise RemoteProtocolError(f"invalid steps response: {exc!r}") from None


def _column(data: Any, dtype: np.dtype, size: int) -> np.ndarray:
    """One numeric column of a steps reply, ``size`` values of ``dtype`` as raw bytes."""
    if type(data) is not bytes or len(data) != size * dtype.itemsize:
        raise ValueError(f"a column must be {size} values of {dtype.str} as raw bytes")
    return np.frombuffer(data, dtype)


Message = Hello | Request | Response | BatchResponse | StepsResponse | ErrorReply
Reply = Response | BatchResponse | StepsResponse | ErrorReply
"""Any answer a server sends to a request."""


def joint_end(flags: Iterable[tuple[bool, bool]]) -> tuple[bool, bool]:
    """The joint episode's ``(terminated, truncated)``, from each agent's (protocol 2.6).

    The rule both ends follow: a server's answer for all its agents, a client's for the agents
    it trains (the others driven by the server).

    ``terminated`` when every agent ended terminated; ``truncated`` when every agent is done
    and at least one was truncated (a time-out after a catch is no terminal state, so a
    trainer still bootstraps from it). An agent both terminated and truncated counts as
    terminated; the two joint flags are never both true.
    """
    flags = list(flags)
    terminated = all(ended for ended, _ in flags)
    return terminated, not terminated and all(ended or cut for ended, cut in flags)
