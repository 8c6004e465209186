"""The rlenv wire protocol, sans-IO: bytes in, messages out; messages in, bytes out.

Rule 1: everything that decides what may be sent or received, and when, lives in this module.
The server's endpoint (:mod:`rlenv.communication`) and the client (:mod:`rlenv_client.client`)
only move bytes between a socket and a :class:`Connection`.

**Frames.** A frame is a 4-byte big-endian length followed by that many bytes holding exactly one
msgpack map. numpy arrays travel as msgpack ext type :data:`NDARRAY_EXT` (dtype, shape, raw
bytes) and decode with ``np.frombuffer``: no copy, read-only.

**Messages.** On connect the server sends a :class:`Hello` (protocol version, environment name,
spaces, rates). Then the client sends :class:`Request` s; the server answers each one, in order,
with exactly one :class:`Response` or :class:`ErrorReply` carrying the request's id::

    hello    {"hello": {"protocol": [1, 1], "environment": ..., "action_space": {...}, ...}}
    request  {"id": 7, "config": {...}, "reset": {...}, "action": ..., "observation": {...},
              "repeat_action": 4}                      # every key but id optional
    response {"id": 7, "observation": {"agent": ...}, "reward": 1.0, "terminated": false,
              "truncated": false, "info": {...}, "frames": 4}
    error    {"id": 7, "error": {"code": "invalid_action", "message": ..., "fatal": false}}
    batch    {"id": 8, "batch": [{"action": ...}, null, {"reset": {}}]}   # several instances
    replies  {"id": 8, "batch": [{...response...}, null, {...response or error...}]}
    steps    {"id": 9, "steps": {"action": <K actions>, "reset": <K bools>, "repeat_action": 4}}
    columns  {"id": 9, "steps": {"observation": <K observations>, "reward": <K float64>,
              "terminated": <K bools>, "truncated": <K bools>, "frames": <K int64>,
              "info": [{...}, ...], "errors": [null, {"code": ..., "message": ...}, ...]}}

A server hosting several environment instances (its hello says ``instances``) takes a batch:
one request per instance, answered by one :class:`BatchResponse` with one reply per instance.
It also takes :class:`Steps`, the vector environment's step in columns: every instance steps
(or resets, where ``reset`` says so) and the answer is one :class:`StepsResponse` whose arrays
are stacked along a first axis of length K, in gymnasium's ``batch_space`` layout, so that
neither end handles K maps per step.

**States** (:class:`State`): a client connection starts in ``AWAIT_HELLO`` and moves to
``READY`` on the hello; a server connection starts in ``AWAIT_HELLO`` and moves to ``READY`` when
it sends the hello. A fatal error reply, a broken frame or the end of the stream moves either to
``CLOSED``.
"""

from __future__ import annotations

import struct
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from enum import Enum
from typing import Any, Final

import msgpack
import numpy as np
from gymnasium import spaces

from rlenv.errors import (
    ErrorCode,
    LocalProtocolError,
    ProtocolVersionError,
    RemoteProtocolError,
)
from rlenv.spaces import space_from_spec, space_to_spec

__all__ = [
    "CONNECTION_CLOSED",
    "BatchResponse",
    "DEFAULT_MAX_FRAME_SIZE",
    "NDARRAY_EXT",
    "NEED_DATA",
    "PROTOCOL_VERSION",
    "STEPS_SINCE",
    "REQUEST_KEYS",
    "Connection",
    "ErrorReply",
    "Hello",
    "Message",
    "Reply",
    "Request",
    "Response",
    "Role",
    "State",
    "Steps",
    "StepsResponse",
    "pack",
    "unpack",
]

PROTOCOL_VERSION: Final = (1, 1)
"""(major, minor). Peers with different majors refuse each other; minors are compatible, a
newer minor only adds messages (1.1: ``steps`` requests, see :data:`STEPS_SINCE`)."""

STEPS_SINCE: Final = (1, 1)
"""The first protocol version whose multi-instance servers take ``steps`` requests."""

DEFAULT_MAX_FRAME_SIZE: Final = 64 * 1024 * 1024
"""Largest frame body accepted by default, checked against the length prefix before reading."""

NDARRAY_EXT: Final = 1
"""msgpack ext type code of a numpy array."""

REQUEST_KEYS: Final = ("config", "reset", "action", "observation")
"""The request parts, in the order the server applies them."""

_HEADER = struct.Struct(">I")
_ARRAY_HEADER = struct.Struct("<BB")  # dtype string length, number of dimensions
_MAX_NDIM = 32
_ARRAY_KINDS = frozenset("biufc")
_HEADER_CACHE_SIZE = 1024  # distinct (dtype, shape) pairs remembered; bounded against hostile peers
_HEADERS: dict[tuple[np.dtype, tuple[int, ...]], bytes] = {}
_PARSED_HEADERS: dict[bytes, tuple[np.dtype, tuple[int, ...], int, int]] = {}


class _Sentinel:
    def __init__(self, name: str) -> None:
        self._name = name

    def __repr__(self) -> str:
        return self._name


NEED_DATA: Final = _Sentinel("NEED_DATA")
"""Returned by :meth:`Connection.next_message` when no whole frame is buffered yet."""

CONNECTION_CLOSED: Final = _Sentinel("CONNECTION_CLOSED")
"""Returned by :meth:`Connection.next_message` once the peer closed the stream cleanly."""


# --- codec ---------------------------------------------------------------------------------


def _encode_ndarray(array: np.ndarray) -> msgpack.ExtType:
    key = (array.dtype, array.shape)
    header = _HEADERS.get(key)
    if header is None:
        if array.dtype.kind not in _ARRAY_KINDS or array.dtype.fields is not None:
            raise TypeError(f"arrays of dtype {array.dtype} cannot travel on the wire")
        if array.ndim > _MAX_NDIM:
            raise TypeError(f"arrays of more than {_MAX_NDIM} dimensions cannot travel on the wire")
        dtype = array.dtype.str.encode()
        header = _ARRAY_HEADER.pack(len(dtype), array.ndim) + dtype
        header += struct.pack(f"<{array.ndim}Q", *array.shape)
        if len(_HEADERS) < _HEADER_CACHE_SIZE:
            _HEADERS[key] = header
    return msgpack.ExtType(NDARRAY_EXT, header + array.tobytes())


def _parse_header(data: bytes) -> tuple[np.dtype, tuple[int, ...], int, int]:
    """(dtype, shape, element count, header length) of an encoded array; cached by header."""
    try:
        dtype_len, ndim = _ARRAY_HEADER.unpack_from(data)
        header_len = _ARRAY_HEADER.size + dtype_len + 8 * ndim
    except struct.error:
        raise ValueError("malformed ndarray header: too short") from None
    header = data[:header_len]
    parsed = _PARSED_HEADERS.get(header)
    if parsed is not None:
        return parsed
    if ndim > _MAX_NDIM:
        raise ValueError(f"ndarray of {ndim} dimensions; at most {_MAX_NDIM} are allowed")
    try:
        dtype = np.dtype(data[_ARRAY_HEADER.size : _ARRAY_HEADER.size + dtype_len].decode("ascii"))
        shape = struct.unpack_from(f"<{ndim}Q", data, _ARRAY_HEADER.size + dtype_len)
    except (struct.error, UnicodeDecodeError, TypeError, ValueError) as exc:
        raise ValueError(f"malformed ndarray header: {exc}") from None
    if dtype.kind not in _ARRAY_KINDS or dtype.fields is not None or dtype.subdtype is not None:
        raise ValueError(f"ndarray dtype {dtype} is not allowed on the wire")
    count = 1
    for n in shape:
        count *= n
    parsed = (dtype, shape, count, header_len)
    if len(_PARSED_HEADERS) < _HEADER_CACHE_SIZE:
        _PARSED_HEADERS[header] = parsed
    return parsed


def _decode_ndarray(data: bytes) -> np.ndarray:
    dtype, shape, count, offset = _parse_header(data)
    if count * dtype.itemsize != len(data) - offset:
        raise ValueError(
            f"ndarray of shape {shape} and dtype {dtype} needs {count * dtype.itemsize} bytes, "
            f"the frame holds {len(data) - offset}"
        )
    return np.frombuffer(data, dtype=dtype, count=count, offset=offset).reshape(shape)


def _default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return _encode_ndarray(obj)
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"objects of type {type(obj).__name__} cannot travel on the wire")


def _ext_hook(code: int, data: bytes) -> Any:
    if code != NDARRAY_EXT:
        raise ValueError(f"unknown msgpack ext type {code}")
    return _decode_ndarray(data)


_packer = msgpack.Packer(default=_default, use_bin_type=True, autoreset=True)


def pack(obj: Any) -> bytes:
    """Encode ``obj`` as msgpack, numpy arrays and scalars included (no framing).

    Raises:
        TypeError: ``obj`` holds something that cannot travel on the wire.
    """
    return _packer.pack(obj)


def unpack(body: bytes, max_size: int = DEFAULT_MAX_FRAME_SIZE) -> Any:
    """Decode one msgpack object that fills ``body`` exactly.

    Raises:
        RemoteProtocolError: invalid msgpack, trailing bytes, a foreign ext type, a malformed
            array, or a container larger than ``max_size`` allows.
    """
    try:
        return msgpack.unpackb(
            body,
            ext_hook=_ext_hook,
            raw=False,
            strict_map_key=True,
            max_str_len=max_size,
            max_bin_len=max_size,
            max_array_len=max_size,
            max_map_len=max_size,
            max_ext_len=max_size,
        )
    except msgpack.ExtraData:
        raise RemoteProtocolError("trailing bytes after the message in the frame") from None
    except (ValueError, TypeError, msgpack.UnpackException, RecursionError) as exc:
        detail = str(exc) or type(exc).__name__
        raise RemoteProtocolError(f"frame is not valid msgpack: {detail}") from None


# --- messages ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Hello:
    """What the server says first: who it is and what its spaces are."""

    environment: str
    action_space: spaces.Space
    observation_space: spaces.Space
    agents: tuple[str, ...] = ("agent",)
    physics_ticks_per_second: int = 60
    repeat_action: int = 4
    render_modes: tuple[str, ...] = ()
    token_required: bool = False
    instances: int = 1
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
                "token_required": self.token_required,
                "instances": self.instances,
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
                token_required=bool(body.get("token_required", False)),
                instances=int(body.get("instances", 1)),
                protocol=(int(version[0]), int(version[1])),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise RemoteProtocolError(f"invalid hello: {exc!r}") from None


@dataclass(frozen=True, slots=True)
class Request:
    """One request: any of config, reset, action and observation, applied in that order.

    ``None`` means the part is absent. ``repeat_action`` overrides, for this action only, how
    many physics ticks the action runs. ``token`` authenticates the first request to a server
    whose hello says ``token_required``. ``snapshot`` asks for the environment's state as data
    (in ``info["snapshot"]``); ``restore`` rebuilds a state from such data; ``inspect`` reads the
    node tree or gets / sets an exported property (see :mod:`rlenv.inspector`). ``batch``
    carries one request per environment instance
    of a server that hosts several (``None`` leaves an instance alone); it is answered with one
    :class:`BatchResponse`. ``steps`` steps all of them in columns (see :class:`Steps`); it is
    answered with one :class:`StepsResponse`.
    """

    id: int
    config: Mapping[str, Any] | None = None
    reset: Mapping[str, Any] | None = None
    action: Any = None
    observation: Mapping[str, Any] | None = None
    repeat_action: int | None = None
    token: str | None = None
    batch: tuple[Request | None, ...] | None = None
    snapshot: Mapping[str, Any] | None = None
    restore: Mapping[str, Any] | None = None
    inspect: Mapping[str, Any] | None = None
    steps: Steps | None = None

    @property
    def asks_nothing(self) -> bool:
        """Whether no part asks anything of an environment (e.g. it only carries the token)."""
        return all(getattr(self, name) is None for name in _ENVIRONMENT_PARTS)

    def to_wire(self) -> dict[str, Any]:
        """The message as a msgpack-ready map (absent parts left out)."""
        wire = self._parts()
        if self.batch is not None:
            wire["batch"] = [None if part is None else part._parts() for part in self.batch]
        if self.steps is not None:
            wire["steps"] = self.steps.to_wire()
        wire["id"] = self.id
        return wire

    def _parts(self) -> dict[str, Any]:
        wire: dict[str, Any] = {}
        if self.config is not None:
            wire["config"] = self.config
        if self.reset is not None:
            wire["reset"] = self.reset
        if self.action is not None:
            wire["action"] = self.action
        if self.observation is not None:
            wire["observation"] = self.observation
        if self.repeat_action is not None:
            wire["repeat_action"] = self.repeat_action
        if self.token is not None:
            wire["token"] = self.token
        if self.snapshot is not None:
            wire["snapshot"] = self.snapshot
        if self.restore is not None:
            wire["restore"] = self.restore
        if self.inspect is not None:
            wire["inspect"] = self.inspect
        return wire

    @classmethod
    def from_wire(cls, wire: Mapping[str, Any]) -> Request:
        """Read and validate a request map.

        Raises:
            RemoteProtocolError: with code ``bad_request`` and a message naming the field.
        """
        request_id = wire.get("id")
        if type(request_id) is not int:
            raise _bad_request(None, f"request 'id' must be an integer, got {request_id!r:.40}")
        request = _parse_parts(cls, request_id, wire, "")
        for alone in ("batch", "steps"):
            if alone in wire and len(wire) > 2 + ("token" in wire):
                raise _bad_request(request_id,
                                   f"a {alone!r} request carries nothing else but its id")
        if "steps" in wire:
            return replace(request, steps=Steps.from_wire(request_id, wire["steps"]))
        batch = wire.get("batch")
        if batch is None:
            return request
        if not isinstance(batch, list) or not batch:
            raise _bad_request(request_id, "'batch' must be a non-empty list of requests or nil")
        parts = []
        for index, part in enumerate(batch):
            if part is not None and not isinstance(part, Mapping):
                raise _bad_request(request_id, f"batch[{index}] must be a map or nil")
            parts.append(None if part is None else
                         _parse_parts(cls, request_id, part, f"batch[{index}]."))
        return replace(request, batch=tuple(parts))

    def __repr__(self) -> str:  # never show a token in logs
        parts = ", ".join(f"{part.name}={getattr(self, part.name)!r:.80}" for part in fields(self)
                          if part.name != "token" and getattr(self, part.name) is not None)
        return f"Request({parts}{', token=...' if self.token is not None else ''})"


_STATE_KEYS = ("snapshot", "restore", "inspect")
_ENVIRONMENT_PARTS = REQUEST_KEYS + _STATE_KEYS
_REQUEST_WIRE_KEYS = frozenset(("id", "repeat_action", "token", "batch", "steps")
                               + REQUEST_KEYS + _STATE_KEYS)
_PART_KEYS = frozenset(("repeat_action",) + REQUEST_KEYS + _STATE_KEYS)


def _parse_parts(cls: type[Request], request_id: int, wire: Mapping[str, Any],
                 where: str) -> Request:
    """Validate the parts of a request (or of one request of a batch)."""
    allowed = _PART_KEYS if where else _REQUEST_WIRE_KEYS
    unknown = wire.keys() - allowed
    if unknown:
        raise _bad_request(
            request_id,
            f"unknown request key {where}{sorted(map(str, unknown))[0]!r}; expected any of "
            + ", ".join(REQUEST_KEYS + ("repeat_action",) + _STATE_KEYS
                        + (() if where else ("token", "batch", "steps"))),
        )
    for key in ("config", "reset", "observation") + _STATE_KEYS:
        if key in wire and not isinstance(wire[key], Mapping):
            raise _bad_request(request_id, f"request {where}{key!r} must be a map")
    repeat = wire.get("repeat_action")
    if repeat is not None:
        if type(repeat) is not int or repeat < 1:
            raise _bad_request(
                request_id, f"{where}'repeat_action' must be an integer >= 1, got {repeat!r:.40}"
            )
        if wire.get("action") is None:
            raise _bad_request(request_id, f"{where}'repeat_action' given without an 'action'")
    token = wire.get("token")
    if token is not None and not isinstance(token, str):
        raise _bad_request(request_id, "'token' must be a string")
    return cls(
        id=request_id,
        config=wire.get("config"),
        reset=wire.get("reset"),
        action=wire.get("action"),
        observation=wire.get("observation"),
        repeat_action=repeat,
        token=token,
        snapshot=wire.get("snapshot"),
        restore=wire.get("restore"),
        inspect=wire.get("inspect"),
    )


def _bad_request(request_id: int | None, message: str) -> RemoteProtocolError:
    return RemoteProtocolError(message, ErrorCode.BAD_REQUEST, request_id=request_id)


@dataclass(frozen=True, slots=True)
class Steps:
    """One step of every instance of a multi-instance server, in columns.

    ``action`` holds one action per instance, stacked as gymnasium's ``batch_space`` of the
    action space lays them out (a ``(K, ...)`` array for a Box, a map of such for a Dict ...).
    ``reset`` (K bools, or ``None`` for none) marks the instances to reset instead of step
    (their action is ignored): gymnasium's ``NEXT_STEP`` autoreset. ``repeat_action``
    overrides the ticks per action for this step.
    """

    action: Any
    reset: np.ndarray | None = None
    repeat_action: int | None = None

    def to_wire(self) -> dict[str, Any]:
        """The ``steps`` part as a msgpack-ready map."""
        wire: dict[str, Any] = {"action": self.action}
        if self.reset is not None:
            wire["reset"] = self.reset
        if self.repeat_action is not None:
            wire["repeat_action"] = self.repeat_action
        return wire

    @classmethod
    def from_wire(cls, request_id: int, wire: Any) -> Steps:
        """Read and validate a ``steps`` map (the action is checked against the space later).

        Raises:
            RemoteProtocolError: ``bad_request`` naming the field.
        """
        if not isinstance(wire, Mapping):
            raise _bad_request(request_id, "'steps' must be a map")
        unknown = wire.keys() - _STEPS_KEYS
        if unknown:
            raise _bad_request(request_id, f"unknown key {sorted(map(str, unknown))[0]!r} in "
                               f"steps; expected any of {', '.join(sorted(_STEPS_KEYS))}")
        if wire.get("action") is None:
            raise _bad_request(request_id, "'steps' needs an 'action' (one per instance)")
        reset = wire.get("reset")
        if reset is not None:
            if isinstance(reset, list) and all(type(flag) is bool for flag in reset):
                reset = np.array(reset, dtype=np.bool_)
            if not (isinstance(reset, np.ndarray) and reset.dtype == np.bool_
                    and reset.ndim == 1):
                raise _bad_request(request_id, "steps.reset must be a list of booleans, one "
                                   "per instance")
        repeat = wire.get("repeat_action")
        if repeat is not None and (type(repeat) is not int or repeat < 1):
            raise _bad_request(request_id, f"steps.repeat_action must be an integer >= 1, got "
                               f"{repeat!r:.40}")
        return cls(action=wire["action"], reset=reset, repeat_action=repeat)


_STEPS_KEYS = frozenset(("action", "reset", "repeat_action"))


@dataclass(frozen=True, slots=True)
class StepsResponse:
    """The answer to a :class:`Steps` request: one column per field, one row per instance.

    ``observation`` is stacked like ``Steps.action`` (the agent observation of every
    instance); ``reward`` (float64), ``terminated``, ``truncated`` (bool) and ``frames``
    (int64) are arrays of length K; ``info`` holds one map per instance (``agents`` in it for
    a multi-agent environment). ``errors`` is ``None`` when every instance succeeded, else one
    entry per instance: ``None`` or the :class:`ErrorReply` of an instance that failed (whose
    row of the other columns is meaningless).
    """

    id: int
    observation: Any
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    frames: np.ndarray
    info: tuple[Mapping[str, Any], ...]
    errors: tuple[ErrorReply | None, ...] | None = None

    def to_wire(self) -> dict[str, Any]:
        """The message as a msgpack-ready map."""
        columns: dict[str, Any] = {
            "observation": self.observation, "reward": self.reward,
            "terminated": self.terminated, "truncated": self.truncated, "frames": self.frames,
            "info": list(self.info),
        }
        if self.errors is not None:
            columns["errors"] = [None if error is None else error.to_wire()["error"]
                                 for error in self.errors]
        return {"id": self.id, "steps": columns}

    @classmethod
    def from_wire(cls, wire: Mapping[str, Any]) -> StepsResponse:
        """Read a steps response map.

        Raises:
            RemoteProtocolError: a column is missing or has the wrong type or length.
        """
        columns = wire["steps"]
        try:
            reward = np.asarray(columns["reward"], dtype=np.float64)
            size = len(reward)
            flags = [np.asarray(columns[name], dtype=np.bool_)
                     for name in ("terminated", "truncated")]
            frames = np.asarray(columns["frames"], dtype=np.int64)
            info = tuple(columns["info"])
            errors = columns.get("errors")
            if errors is not None:
                errors = tuple(None if error is None else
                               ErrorReply.from_wire({"id": wire["id"], "error": error})
                               for error in errors)
            if any(len(column) != size for column in (*flags, frames, info, errors or info)) \
                    or not all(isinstance(item, Mapping) for item in info):
                raise ValueError("columns of different lengths, or an info that is not a map")
            return cls(id=wire["id"], observation=columns["observation"], reward=reward,
                       terminated=flags[0], truncated=flags[1], frames=frames, info=info,
                       errors=errors)
        except (KeyError, TypeError, ValueError, RemoteProtocolError) as exc:
            raise RemoteProtocolError(f"invalid steps response: {exc!r}") from None


@dataclass(frozen=True, slots=True)
class Response:
    """The answer to a request that succeeded."""

    id: int
    observation: Mapping[str, Any] | None = None
    reward: float = 0.0
    terminated: bool = False
    truncated: bool = False
    info: Mapping[str, Any] = field(default_factory=dict)
    frames: int = 0
    agents: Mapping[str, Mapping[str, Any]] | None = None
    """Per agent of a multi-agent environment: ``{"reward", "terminated", "truncated"}``."""

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
            return cls(
                id=wire["id"],
                observation=wire["observation"],
                reward=float(wire["reward"]),
                terminated=bool(wire["terminated"]),
                truncated=bool(wire["truncated"]),
                info=wire["info"],
                frames=int(wire["frames"]),
                agents=wire.get("agents"),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise RemoteProtocolError(f"invalid response: {exc!r}") from None


@dataclass(frozen=True, slots=True)
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


@dataclass(frozen=True, slots=True)
class BatchResponse:
    """The answer to a batch request: one reply per instance (``None`` where none was asked)."""

    id: int
    replies: tuple[Response | ErrorReply | None, ...]

    def to_wire(self) -> dict[str, Any]:
        """The message as a msgpack-ready map."""
        return {"id": self.id,
                "batch": [None if reply is None else reply.to_wire() for reply in self.replies]}

    @classmethod
    def from_wire(cls, wire: Mapping[str, Any]) -> BatchResponse:
        """Read a batch response map.

        Raises:
            RemoteProtocolError: a reply is malformed.
        """
        batch = wire["batch"]
        if not isinstance(batch, list):
            raise RemoteProtocolError("invalid batch response: 'batch' is not a list")
        replies: list[Response | ErrorReply | None] = []
        for reply in batch:
            if reply is None:
                replies.append(None)
            elif not isinstance(reply, Mapping):
                raise RemoteProtocolError("invalid batch response: a reply is not a map")
            else:
                replies.append(ErrorReply.from_wire(reply) if "error" in reply
                               else Response.from_wire(reply))
        return cls(id=wire["id"], replies=tuple(replies))


Message = Hello | Request | Response | BatchResponse | StepsResponse | ErrorReply
Reply = Response | BatchResponse | StepsResponse | ErrorReply
"""Any answer a server sends to a request."""


# --- connection state machine --------------------------------------------------------------


class Role(Enum):
    """Which end of the connection a :class:`Connection` plays."""

    CLIENT = "client"
    SERVER = "server"


class State(Enum):
    """Connection states; see the module docstring for the transitions."""

    AWAIT_HELLO = "await_hello"
    READY = "ready"
    CLOSED = "closed"


class Connection:
    """One end of an rlenv connection, with no I/O of its own (like h11's ``Connection``).

    Feed received bytes to :meth:`receive_data` and pull messages with :meth:`next_message`;
    turn messages into bytes to write with :meth:`send`. The connection checks what each side
    may send when, and pairs responses with requests (one response per request, in order).

    Args:
        role: which end this is.
        max_frame_size: largest frame body accepted; a larger length prefix is refused before
            any of the body is buffered.
    """

    def __init__(self, role: Role, max_frame_size: int = DEFAULT_MAX_FRAME_SIZE) -> None:
        self.role = role
        self.max_frame_size = max_frame_size
        self.state = State.AWAIT_HELLO
        self._buffer = bytearray()
        self._eof = False
        self._broken = False
        self._outstanding: deque[int] = deque()

    @property
    def outstanding(self) -> tuple[int, ...]:
        """Ids of the requests that have not been answered yet, oldest first."""
        return tuple(self._outstanding)

    @property
    def buffered(self) -> int:
        """Bytes received that do not form a whole frame yet."""
        return len(self._buffer)

    @property
    def peer_closed(self) -> bool:
        """Whether the peer closed its end of the stream (``receive_data(b"")`` was called)."""
        return self._eof

    def receive_data(self, data: bytes) -> None:
        """Buffer bytes read from the peer; ``b""`` means the peer closed its end."""
        if data:
            self._buffer += data
        else:
            self._eof = True

    def next_message(self) -> Message | _Sentinel:
        """Return the next whole message, :data:`NEED_DATA` or :data:`CONNECTION_CLOSED`.

        Raises:
            RemoteProtocolError: the peer broke the protocol. ``error.fatal`` says the framing
                itself is broken (the stream cannot be resynchronised): nothing more is read, and
                this side may send one last fatal :class:`ErrorReply`. Otherwise the bad frame
                is consumed and the connection goes on. A request that could be read far enough
                carries its id in ``error.request_id``.
            ProtocolVersionError: the hello names another major version.
        """
        if self.state is State.CLOSED or self._broken:
            return CONNECTION_CLOSED
        body = self._next_frame()
        if body is NEED_DATA or body is CONNECTION_CLOSED:
            return body
        wire = unpack(body, self.max_frame_size)
        if not isinstance(wire, dict):
            raise RemoteProtocolError(f"a frame must hold a map, got {type(wire).__name__}")
        if self.role is Role.SERVER:
            try:
                request = Request.from_wire(wire)
            except RemoteProtocolError as error:
                if error.request_id is not None:
                    self._outstanding.append(error.request_id)  # the error reply answers it
                raise
            self._outstanding.append(request.id)
            return request
        return self._client_message(wire)

    def send(self, message: Message) -> bytes:
        """Return the frame that carries ``message``.

        Raises:
            LocalProtocolError: this side may not send ``message`` now.
            TypeError: the message holds a value that cannot travel on the wire.
        """
        self._check_send(message)
        body = pack(message.to_wire())
        if len(body) > self.max_frame_size:
            raise LocalProtocolError(
                f"message of {len(body)} bytes exceeds the frame limit of {self.max_frame_size}"
            )
        if isinstance(message, Hello):
            self.state = State.READY
        elif isinstance(message, Request):
            self._outstanding.append(message.id)
        elif isinstance(message, Reply) and message.id is not None:
            self._outstanding.popleft()
        if isinstance(message, ErrorReply) and message.fatal:
            self.state = State.CLOSED
        return _HEADER.pack(len(body)) + body

    # -- internals --

    def _next_frame(self) -> bytes | _Sentinel:
        buffered = len(self._buffer)
        if buffered >= _HEADER.size:
            (length,) = _HEADER.unpack_from(self._buffer)
            if length > self.max_frame_size:
                self._broken = True
                raise RemoteProtocolError(
                    f"frame length {length} exceeds the limit of {self.max_frame_size} bytes "
                    "(is the peer speaking the rlenv protocol?)",
                    fatal=True,
                )
            end = _HEADER.size + length
            if buffered >= end:
                body = bytes(self._buffer[_HEADER.size : end])
                del self._buffer[:end]
                return body
        if not self._eof:
            return NEED_DATA
        self.state = State.CLOSED
        if buffered:
            raise RemoteProtocolError(
                f"connection closed in the middle of a frame ({buffered} bytes buffered)",
                fatal=True,
            )
        return CONNECTION_CLOSED

    def _client_message(self, wire: dict[str, Any]) -> Message:
        if "error" in wire:
            reply = ErrorReply.from_wire(wire)
            if reply.id is not None:
                self._pop_outstanding(reply.id)
            if reply.fatal or self.state is State.AWAIT_HELLO:
                self.state = State.CLOSED
            return reply
        if self.state is State.AWAIT_HELLO:
            if "hello" not in wire:
                self.state = State.CLOSED
                raise RemoteProtocolError("the server did not start with a hello", fatal=True)
            hello = Hello.from_wire(wire)
            self.state = State.READY
            return hello
        if "steps" in wire:
            response: Message = StepsResponse.from_wire(wire)
        elif "batch" in wire:
            response = BatchResponse.from_wire(wire)
        else:
            response = Response.from_wire(wire)
        self._pop_outstanding(response.id)
        return response

    def _pop_outstanding(self, reply_id: int) -> None:
        if not self._outstanding or self._outstanding[0] != reply_id:
            self.state = State.CLOSED
            expected = self._outstanding[0] if self._outstanding else "none"
            raise RemoteProtocolError(
                f"reply to request {reply_id}, expected {expected}", fatal=True
            )
        self._outstanding.popleft()

    def _check_send(self, message: Message) -> None:
        if self.state is State.CLOSED:
            raise LocalProtocolError("cannot send on a closed connection")
        if self.role is Role.SERVER:
            if isinstance(message, Request):
                raise LocalProtocolError("a server does not send requests")
            if isinstance(message, Hello) and self.state is not State.AWAIT_HELLO:
                raise LocalProtocolError("the hello is sent once, first")
            if isinstance(message, Reply) and not isinstance(message, ErrorReply) and \
                    self.state is not State.READY:
                raise LocalProtocolError("send the hello before any response")
            if isinstance(message, Reply) and message.id is not None:
                if not self._outstanding or self._outstanding[0] != message.id:
                    raise LocalProtocolError(
                        f"reply to request {message.id} out of order; outstanding: "
                        f"{list(self._outstanding)}"
                    )
        else:
            if not isinstance(message, Request):
                raise LocalProtocolError(f"a client only sends requests, not {message!r:.60}")
            if self.state is not State.READY:
                raise LocalProtocolError("wait for the server's hello before sending requests")
