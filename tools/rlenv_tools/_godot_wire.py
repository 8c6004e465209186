"""Godot RL Agents' wire, as a game speaks it: frames, spaces, observations and actions.

godot-rl's trainer (``godot_rl.core.godot_env.GodotEnv``, 0.8) is a TCP server. Each message is a
4-byte little-endian length, then that many bytes of UTF-8 JSON (Godot's ``put_string``). Every
AIController declares its spaces as maps of named parts:

- observations: ``{"obs": {"space": "box", "size": [4], "low": [...], "high": [...]}}``;
  ``"discrete"`` parts have an integer ``size``; a part whose key contains ``2d`` is an image,
  ``uint8`` of shape ``size``, sent as the hex string of its bytes.
- actions: ``{"action": {"action_type": "continuous" | "discrete", "size": n}}``; godot-rl
  declares every continuous part as ``Box(-1, 1)`` (``low``/``high`` cannot be carried), so a
  bounded Box is rescaled from [-1, 1] to its true bounds here.

godot-rl 0.8.2 reads no ``low``/``high`` of an observation either (its declared Box is [-1, 1]);
later versions do, so they are sent. JSON's numbers stand in for float32, and infinite bounds
travel as ``Infinity``, which Python's ``json`` reads.
"""

from __future__ import annotations

import json
import socket
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

__all__ = [
    "MAX_FRAME",
    "AgentWire",
    "GodotWireError",
    "agent_wire",
    "read_message",
    "send_message",
]

MAX_FRAME = 64 << 20
"""The largest message read from a trainer, in bytes (its actions are small)."""

_LENGTH = 4


class GodotWireError(ValueError):
    """A godot-rl message or space this bridge cannot take, saying what and why."""


def send_message(sock: socket.socket, message: Mapping[str, Any]) -> None:
    """Send ``message`` as one frame: its JSON's length (4 bytes, little-endian), then it."""
    body = json.dumps(message, separators=(",", ":")).encode()
    sock.sendall(len(body).to_bytes(_LENGTH, "little") + body)


def read_message(sock: socket.socket) -> dict[str, Any] | None:
    """The next frame's JSON object, or ``None`` once the trainer closed the connection.

    Raises:
        GodotWireError: the frame is larger than :data:`MAX_FRAME`, is not JSON, is not an
            object with a string ``type``, or the connection ended inside it.
    """
    header = _read_exactly(sock, _LENGTH, at_start=True)
    if header is None:
        return None
    length = int.from_bytes(header, "little")
    if length > MAX_FRAME:
        raise GodotWireError(f"a frame of {length} bytes: the largest taken is {MAX_FRAME}")
    body = _read_exactly(sock, length, at_start=False) or b""
    try:
        message = json.loads(body.decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise GodotWireError(f"a frame that is not JSON: {error}") from None
    if not isinstance(message, dict) or not isinstance(message.get("type"), str):
        raise GodotWireError(f"a message without a string 'type': {body[:80]!r}")
    return message


def _read_exactly(sock: socket.socket, size: int, *, at_start: bool) -> bytes | None:
    """``size`` bytes; ``None`` if the peer closed before the first of a message's bytes."""
    chunks = bytearray()
    while len(chunks) < size:
        chunk = sock.recv(min(size - len(chunks), 1 << 20))
        if not chunk:
            if at_start and not chunks:
                return None
            raise GodotWireError(f"the connection ended inside a frame ({len(chunks)}/{size})")
        chunks += chunk
    return bytes(chunks)


@dataclass(frozen=True)
class AgentWire:
    """How one agent's spaces look on godot-rl's wire, and its values both ways.

    Attributes:
        observation_space: the agent's ``observation_space`` entry of ``env_info``.
        action_space: the agent's ``action_space`` entry of ``env_info``.
        observe: the agent's observation as the JSON map an AIController's ``get_obs`` gives.
        act: the trainer's action map for the agent as a value of the agent's action space.
    """

    observation_space: dict[str, Any]
    action_space: dict[str, Any]
    observe: Callable[[Any], dict[str, Any]]
    act: Callable[[Any], Any]


def agent_wire(observation_space: spaces.Space, action_space: spaces.Space) -> AgentWire:
    """The wire form of an agent with these spaces.

    Raises:
        GodotWireError: a space godot-rl cannot carry (only ``Box``, ``Discrete`` and a
            ``Dict`` of them are), or an observation key containing ``2d`` that is no image.
    """
    observation_parts = _parts(observation_space, "obs")
    action_parts = _parts(action_space, "action")
    observed = {_observation_key(key, space): (key, space) for key, space in observation_parts}
    acted = {key: space for key, space in action_parts}
    keyed_observation = isinstance(observation_space, spaces.Dict)
    keyed_action = isinstance(action_space, spaces.Dict)

    def observe(observation: Any) -> dict[str, Any]:
        return {
            wire_key: _observation_value(
                space, observation[key] if keyed_observation else observation
            )
            for wire_key, (key, space) in observed.items()
        }

    def act(action: Any) -> Any:
        if not isinstance(action, dict):
            raise GodotWireError(f"an agent's action must be a map, got {type(action).__name__}")
        missing = sorted(set(acted) - set(action))
        if missing:
            raise GodotWireError(f"an action without {missing}: it has {sorted(action)}")
        values = {key: _action_value(space, action[key], key) for key, space in acted.items()}
        return values if keyed_action else values["action"]

    return AgentWire(
        {wire_key: _observation_spec(space) for wire_key, (_, space) in observed.items()},
        {key: _action_spec(space, key) for key, space in action_parts},
        observe,
        act,
    )


def _parts(space: spaces.Space, name: str) -> list[tuple[str, spaces.Space]]:
    """A space's named parts: a ``Dict``'s entries, or the space itself as ``name``."""
    parts = list(space.spaces.items()) if isinstance(space, spaces.Dict) else [(name, space)]
    for key, part in parts:
        if not isinstance(part, spaces.Box | spaces.Discrete):
            raise GodotWireError(
                f"{name} part {key!r} is {part}: godot-rl's wire carries only Box and Discrete "
                "(and a Dict of them)"
            )
    return parts


def _is_image(space: spaces.Space) -> bool:
    """Whether godot-rl takes ``space`` as an image: a uint8 Box of 2 or 3 dimensions."""
    return isinstance(space, spaces.Box) and space.dtype == np.uint8 and len(space.shape) in (2, 3)


def _observation_key(key: str, space: spaces.Space) -> str:
    """The part's key on the wire: an image's contains ``2d``, and nothing else's may."""
    if _is_image(space):
        return key if "2d" in key else f"{key}_2d"
    if "2d" in key:
        raise GodotWireError(
            f"observation key {key!r} contains '2d', which godot-rl decodes as an image, but it "
            f"is {space}"
        )
    return key


def _observation_spec(space: spaces.Space) -> dict[str, Any]:
    """The ``env_info`` entry of one observation part."""
    if isinstance(space, spaces.Discrete):
        return {"space": "discrete", "size": int(space.n)}
    assert isinstance(space, spaces.Box)
    spec: dict[str, Any] = {"space": "box", "size": list(space.shape)}
    if not _is_image(space):
        spec["low"] = space.low.astype(float).tolist()
        spec["high"] = space.high.astype(float).tolist()
    return spec


def _observation_value(space: spaces.Space, value: Any) -> Any:
    """One observation part as JSON: a number, nested lists, or an image's hex string."""
    if isinstance(space, spaces.Discrete):
        return int(value)
    array = np.asarray(value)
    if _is_image(space):
        return np.ascontiguousarray(array, dtype=np.uint8).tobytes().hex()
    return array.astype(float).tolist()


def _action_spec(space: spaces.Space, key: str) -> dict[str, Any]:
    """The ``env_info`` entry of one action part."""
    if isinstance(space, spaces.Discrete):
        return {"action_type": "discrete", "size": int(space.n)}
    assert isinstance(space, spaces.Box)
    return {"action_type": "continuous", "size": int(np.prod(space.shape))}


def _action_value(space: spaces.Space, value: Any, key: str) -> Any:
    """One action part from the trainer as a value of ``space`` (a Box rescaled from [-1, 1])."""
    if isinstance(space, spaces.Discrete):
        if isinstance(value, bool) or not isinstance(value, int | float) or value != int(value):
            raise GodotWireError(f"action {key!r} must be an integer, got {value!r:.40}")
        return int(space.start) + int(value)
    assert isinstance(space, spaces.Box)
    try:
        unit = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise GodotWireError(
            f"action {key!r} must be a list of numbers, got {value!r:.40}"
        ) from None
    size = int(np.prod(space.shape))
    if unit.size != size:
        raise GodotWireError(f"action {key!r} has {unit.size} numbers; its size is {size}")
    low, high = space.low.reshape(-1).astype(np.float64), space.high.reshape(-1).astype(np.float64)
    bounded = np.isfinite(low) & np.isfinite(high)
    unit = np.where(bounded, np.clip(unit, -1.0, 1.0), unit)
    scaled = np.where(bounded, low + (unit + 1.0) * 0.5 * (high - low), unit)
    return np.clip(scaled, low, high).astype(space.dtype).reshape(space.shape)
