"""The shared-memory lane's slots, sans-IO: which requests and answers fit, and where they go.

A client on the same machine as its server may move its steps off the socket (protocol 2.3,
``docs/protocol.md``): both map one block of memory, the client writes a request into fixed
slots, the server writes the answer into others, and a byte on a local socket wakes whoever
sleeps (:mod:`rlenv.transport.lanes` does that I/O). The requests and answers are the
protocol's own messages; only how they travel changes. Two kinds of request fit:

- **step**: a plain step of the (first) agent, ``{"action", "observation": {"agent": {}}}``
  with an optional ``repeat_action``; its answer, a :class:`Response` with the agent's
  observation and an empty ``info``;
- **steps**: ``{"steps": {"action", "reset", "repeat_action"}}`` for the server's K
  instances; its answer, a :class:`StepsResponse` with no error and empty infos.

Anything else travels on the socket as before; so does an answer that does not fit the slots
(an error, an ``info``): it comes as a frame on the socket, as any answer, and the slots stay as
they were. The block is laid out by :class:`Layout`, from the hello alone, so both ends compute
the same offsets:

- at 0, the request's header: 4 little-endian int64, sequence, id, kind, repeat_action;
- at 64, the answer's header: 4 little-endian int64, sequence, id, 0, 0;
- at 128, the actions: K packed actions (a step uses the first; Discrete ones in the dtype);
- then the reset flags (K bytes of 0 or 1, for steps), the observations (K packed ones), the
  rewards (K float64), frames (K int64), terminated and truncated flags (K bytes each).

Every region but the two flag columns starts on a multiple of 8 bytes. A writer fills its slots
first and its sequence number last; the reader reads the sequence first. The lane is only
offered where stores become visible to other cores in program order (x86-64): see
:func:`lane_unavailable`.
"""

from __future__ import annotations

import platform
import sys
from dataclasses import dataclass
from typing import Any, Final, cast

import numpy as np
from gymnasium import spaces

from rlenv.protocol.messages import Hello, Reply, Request, Response, StepsResponse

__all__ = ["STEP", "STEPS", "Layout", "Slots", "lane_unavailable"]

STEP: Final = 1
"""Request kind: a plain step of the first agent."""
STEPS: Final = 2
"""Request kind: a ``steps`` request for every instance."""

_ANSWER = 64
_ACTIONS = 128
_RAW_BYTES = (spaces.Box, spaces.MultiDiscrete, spaces.MultiBinary)
_AGENT_ONLY: Final[dict[str, dict[str, Any]]] = {"agent": {}}
_STEP_KEYS = frozenset({"action", "observation", "repeat_action"})
_STEPS_KEYS = frozenset({"action", "reset", "repeat_action"})
_REWARD = np.dtype("<f8")
_FRAMES = np.dtype("<i8")
_FLAG = np.dtype("|u1")
_NO_INFO: dict[str, Any] = {}


def _columns(buffer: Any, offset: int, count: int, space: spaces.Space) -> np.ndarray:
    """The K values of ``space`` packed from ``offset`` in ``buffer``, as one array."""
    shape: tuple[int, ...] = space.shape or ()
    size = count * int(np.prod(shape, dtype=np.int64))
    return np.frombuffer(buffer, space.dtype, size, offset).reshape(count, *shape)


def _repeat(repeat: Any) -> int:
    """``repeat_action`` as the slot holds it: 0 when absent, -1 when it does not fit."""
    if repeat is None:
        return 0
    return repeat if repeat.__class__ is int and 1 <= repeat < 2**62 else -1


def _read_only(array: np.ndarray) -> np.ndarray:
    view = array.view()
    view.flags.writeable = False
    return view


def lane_unavailable(hello: Hello) -> str | None:
    """Why a lane cannot carry this server's steps on this machine; ``None`` if it can."""
    if not sys.platform.startswith("linux"):
        return f"shared memory lanes need Linux (this is {sys.platform})"
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return f"shared memory lanes need x86-64 (this is {platform.machine()})"
    for name, space in (("action", hello.action_space), ("observation", hello.observation_space)):
        if not isinstance(space, _RAW_BYTES) and not (
            name == "action" and isinstance(space, spaces.Discrete)
        ):
            return f"the {name} space ({type(space).__name__}) has no fixed-size packed form"
    if len(hello.agents) != 1:
        return f"the environment has {len(hello.agents)} agents (a lane carries one's steps)"
    return None


def _packed_size(space: spaces.Space[Any]) -> int:
    # Only spaces that lane_unavailable admits come here: each has a fixed dtype and shape.
    dtype, shape = cast(np.dtype, space.dtype), cast(tuple[int, ...], space.shape)
    return dtype.itemsize * int(np.prod(shape, dtype=np.int64))


def _aligned(offset: int) -> int:
    return (offset + 7) // 8 * 8


@dataclass(frozen=True)
class Layout:
    """Where each slot of a lane lies, for a server's hello (see the module docstring).

    Attributes:
        instances: K, the server's instances.
        action_size: bytes of one packed action.
        observation_size: bytes of one packed observation.
        reset, observation, reward, frames, terminated, truncated: offsets of those regions.
        size: bytes of the whole block.
    """

    instances: int
    action_size: int
    observation_size: int
    reset: int
    observation: int
    reward: int
    frames: int
    terminated: int
    truncated: int
    size: int

    @classmethod
    def for_hello(cls, hello: Hello) -> Layout:
        """The layout of a lane to the server that said ``hello``.

        Raises:
            ValueError: no lane can carry its steps (:func:`lane_unavailable` says why).
        """
        why = lane_unavailable(hello)
        if why is not None:
            raise ValueError(why)
        count = hello.instances
        action, observation = hello.action_space, hello.observation_space
        action_size, observation_size = _packed_size(action), _packed_size(observation)
        reset = _aligned(_ACTIONS + count * action_size)
        observations = _aligned(reset + count)
        reward = _aligned(observations + count * observation_size)
        frames = reward + 8 * count
        terminated = frames + 8 * count
        truncated = terminated + count
        size = (truncated + count + 63) // 64 * 64
        return cls(
            count,
            action_size,
            observation_size,
            reset,
            observations,
            reward,
            frames,
            terminated,
            truncated,
            size,
        )

    def to_wire(self) -> dict[str, int]:
        """The layout as the server's answer to ``shared_memory`` carries it."""
        return {
            "size": self.size,
            "instances": self.instances,
            "action_size": self.action_size,
            "observation_size": self.observation_size,
            "actions": _ACTIONS,
            "reset": self.reset,
            "observation": self.observation,
            "reward": self.reward,
            "frames": self.frames,
            "terminated": self.terminated,
            "truncated": self.truncated,
        }


class Slots:
    """A lane's block of memory, seen through its layout; one per end.

    Args:
        buffer: the shared block (an ``mmap``), at least ``layout.size`` bytes.
        layout: where the slots lie.
        hello: the server's hello (the action space's dtype and bounds).
    """

    def __init__(self, buffer: Any, layout: Layout, hello: Hello) -> None:
        self.layout = layout
        count = layout.instances
        self._buffer = memoryview(buffer)
        self._request = self._buffer[:32].cast("q")
        self._answer = self._buffer[_ANSWER : _ANSWER + 32].cast("q")
        action = hello.action_space
        self._discrete = isinstance(action, spaces.Discrete)
        self._action_dtype = action.dtype
        if isinstance(action, spaces.Discrete):
            self._first, self._end = int(action.start), int(action.start + action.n)
        self._actions = self._buffer[_ACTIONS : _ACTIONS + count * layout.action_size]
        self._reset = self._buffer[layout.reset : layout.reset + count]
        self._observations = self._buffer[
            layout.observation : layout.observation + count * layout.observation_size
        ]
        self._rewards = np.frombuffer(buffer, _REWARD, count, layout.reward)
        self._frames = np.frombuffer(buffer, _FRAMES, count, layout.frames)
        self._terminated = np.frombuffer(buffer, _FLAG, count, layout.terminated)
        self._truncated = np.frombuffer(buffer, _FLAG, count, layout.truncated)
        self._no_infos = (_NO_INFO,) * count
        # The steps slots as arrays, for clients that write and read columns in place.
        self._action_columns = _columns(buffer, _ACTIONS, count, action)
        self._reset_flags = np.frombuffer(buffer, np.bool_, count, layout.reset)
        self._answer_views = tuple(
            _read_only(view)
            for view in (
                _columns(buffer, layout.observation, count, hello.observation_space),
                self._rewards,
                self._terminated.view(np.bool_),
                self._truncated.view(np.bool_),
                self._frames,
            )
        )

    # --- the request (the client writes, the server reads) ----------------------------------

    @property
    def request_sequence(self) -> int:
        """How many requests the client has written."""
        return self._request[0]

    def write_request(self, request: Request) -> int:
        """Write ``request`` into the slots if it fits; its kind, or 0 (it goes on the socket).

        The sequence number is written last: the request is then the server's.
        """
        if request.token is not None:
            return 0
        parts = request.parts
        if "steps" in parts:
            kind = self._write_steps(parts)
        elif "action" in parts:
            kind = self._write_step(parts)
        else:
            return 0
        if kind:
            self._post(request.id, kind)
        return kind

    def _write_step(self, parts: dict[str, Any]) -> int:
        if not parts.keys() <= _STEP_KEYS or parts.get("observation") != _AGENT_ONLY:
            return 0
        repeat = _repeat(parts.get("repeat_action"))
        action = parts["action"]
        size = self.layout.action_size
        if self._discrete:
            if action.__class__ is not int or not self._first <= action < self._end:
                return 0
            self._actions[:size] = np.array(action, self._action_dtype).tobytes()
        elif action.__class__ is bytes and len(action) == size:
            self._actions[:size] = action
        else:
            return 0
        if repeat < 0:
            return 0
        self._request[3] = repeat
        return STEP

    def _write_steps(self, parts: dict[str, Any]) -> int:
        steps = parts["steps"]
        if len(parts) != 1 or steps.__class__ is not dict or not steps.keys() <= _STEPS_KEYS:
            return 0
        action, reset = steps.get("action"), steps.get("reset")
        repeat = _repeat(steps.get("repeat_action"))
        count = self.layout.instances
        if (
            action.__class__ is not bytes
            or len(action) != count * self.layout.action_size
            or repeat < 0
        ):
            return 0
        if reset is None:
            flags = bytes(count)
        elif reset.__class__ is bytes and len(reset) == count:
            flags = reset
        else:
            return 0
        self._actions[:] = action
        self._reset[:] = flags
        self._request[3] = repeat
        return STEPS

    def write_step(self, request_id: int, action: Any, repeat_action: int | None) -> bool:
        """Write a plain step of ``action`` in place; whether it fit.

        ``action`` must be an array of exactly the action space's dtype and shape, or, for a
        ``Discrete`` space, an integer (Python's or numpy's) within it; anything else is left to
        :meth:`write_request` (the slots unchanged). The request is the one ``{"action",
        "observation": {"agent": {}}, "repeat_action"}`` would be, read back by
        :meth:`read_request` as such.
        """
        repeat = _repeat(repeat_action)
        if repeat < 0:
            return False
        slot = self._action_columns
        if self._discrete:
            if action.__class__ is not int and not isinstance(action, np.integer):
                return False
            if not self._first <= action < self._end:
                return False
        elif (
            action.__class__ is not np.ndarray
            or action.dtype != slot.dtype
            or action.shape != slot.shape[1:]
        ):
            return False
        slot[0] = action
        self._request[3] = repeat
        self._post(request_id, STEP)
        return True

    def write_steps(
        self, request_id: int, action: Any, reset: Any, repeat_action: int | None
    ) -> bool:
        """Write a ``steps`` request given as columns, in place; whether it fit.

        ``action`` must be an array of exactly the K actions' dtype and shape and ``reset``
        ``None`` or K booleans; anything else is left to :meth:`write_request` (the slots
        unchanged). The request is the one ``{"steps": {"action", "reset", "repeat_action"}}``
        would be, read back by :meth:`read_request` as such.
        """
        actions, flags = self._action_columns, self._reset_flags
        if (
            action.__class__ is not np.ndarray
            or action.dtype != actions.dtype
            or action.shape != actions.shape
        ):
            return False
        if reset is not None and (
            reset.__class__ is not np.ndarray
            or reset.dtype != np.bool_
            or reset.shape != flags.shape
        ):
            return False
        repeat = _repeat(repeat_action)
        if repeat < 0:
            return False
        actions[...] = action
        flags[...] = False if reset is None else reset
        self._request[3] = repeat
        self._post(request_id, STEPS)
        return True

    def _post(self, request_id: int, kind: int) -> None:
        """The slots and ``repeat_action`` are written: the header's id, kind, then sequence."""
        header = self._request
        header[1] = request_id
        header[2] = kind
        header[0] += 1

    def read_request(self) -> Request:
        """The request the client wrote last, as it would have come off the socket.

        Raises:
            ValueError: its kind is neither :data:`STEP` nor :data:`STEPS` (the message says
                so; the request's id is :attr:`request_id`).
        """
        header = self._request
        request_id, kind, repeat = header[1], header[2], header[3]
        if kind != STEP and kind != STEPS:
            raise ValueError(
                f"the lane's request {request_id} is of kind {kind}; a lane carries "
                f"kinds {STEP} (step) and {STEPS} (steps)"
            )
        size = self.layout.action_size
        if kind == STEP:
            action: Any = bytes(self._actions[:size])
            if self._discrete:
                action = int(np.frombuffer(action, self._action_dtype)[0])
            parts: dict[str, Any] = {"action": action, "observation": {"agent": {}}}
            if repeat:
                parts["repeat_action"] = repeat
            return Request(request_id, parts)
        steps: dict[str, Any] = {"action": bytes(self._actions), "reset": bytes(self._reset)}
        if repeat:
            steps["repeat_action"] = repeat
        return Request(request_id, {"steps": steps})

    @property
    def request_id(self) -> int:
        """The id of the request written last."""
        return self._request[1]

    @property
    def request_kind(self) -> int:
        """The kind of the request written last (:data:`STEP` or :data:`STEPS`)."""
        return self._request[2]

    # --- the answer (the server writes, the client reads) -----------------------------------

    @property
    def answer_sequence(self) -> int:
        """How many answers the server has written into the slots."""
        return self._answer[0]

    def write_answer(self, reply: Reply, kind: int) -> bool:
        """Write the answer to a request of ``kind`` into the slots, if it fits; whether it did.

        The sequence number is written last: the answer is then the client's. An answer that
        does not fit leaves the slots as they were (send it on the socket).
        """
        if not (self._fill_steps(reply) if kind == STEPS else self._fill_step(reply)):
            return False
        header = self._answer
        header[1] = reply.id  # type: ignore[assignment]
        header[0] += 1
        return True

    def _fill_step(self, reply: Reply) -> bool:
        if reply.__class__ is not Response or reply.info or reply.agents is not None:
            return False
        observation = reply.observation
        if observation is None or len(observation) != 1:
            return False
        agent = observation.get("agent")
        size = self.layout.observation_size
        if agent.__class__ is not bytes or len(agent) != size:
            return False
        self._observations[:size] = agent
        self._rewards[0] = reply.reward
        self._frames[0] = reply.frames
        self._terminated[0] = reply.terminated
        self._truncated[0] = reply.truncated
        return True

    def _fill_steps(self, reply: Reply) -> bool:
        if reply.__class__ is not StepsResponse or reply.errors is not None or any(reply.info):
            return False
        observation = reply.observation
        if observation.__class__ is not bytes or len(observation) != len(self._observations):
            return False
        self._observations[:] = observation
        self._rewards[:] = reply.reward
        self._frames[:] = reply.frames
        self._terminated[:] = reply.terminated
        self._truncated[:] = reply.truncated
        return True

    def read_answer(self, kind: int, copy: bool = True) -> Reply:
        """The answer in the slots to the request of ``kind`` written last.

        Its own copy; or, for a ``steps`` answer without ``copy``, read-only views of the
        slots (its observations as an array of K): valid until the next request is written.
        """
        reply_id = self._answer[1]
        if kind == STEP:
            size = self.layout.observation_size
            return Response(
                reply_id,
                {"agent": bytes(self._observations[:size])},
                float(self._rewards[0]),
                bool(self._terminated[0]),
                bool(self._truncated[0]),
                {},
                int(self._frames[0]),
            )
        if not copy:
            observation, reward, terminated, truncated, frames = self._answer_views
            return StepsResponse(
                reply_id, observation, reward, terminated, truncated, frames, self._no_infos
            )
        return StepsResponse(
            reply_id,
            bytes(self._observations),
            self._rewards.copy(),
            self._terminated.astype(np.bool_),
            self._truncated.astype(np.bool_),
            self._frames.copy(),
            self._no_infos,
        )

    def release(self) -> None:
        """Let go of the block (before it is unmapped)."""
        for view in (self._request, self._answer, self._actions, self._reset, self._observations):
            view.release()
        self._buffer.release()
        del (
            self._rewards,
            self._frames,
            self._terminated,
            self._truncated,
            self._action_columns,
            self._reset_flags,
            self._answer_views,
        )
