"""Protocol test vectors: real exchanges with real servers, recorded byte for byte.

Every vector file in ``docs/protocol/vectors/`` is produced here, by driving ``rlenv serve``
subprocesses over loopback with raw sockets: the bytes recorded are exactly those that went over
the wire, both ways. Regenerate them from the repository root with ``make vectors``,
``python -m tests.protocol_vectors`` or ``python tests/protocol_vectors.py``;
``tests/test_protocol_vectors.py`` checks that the committed files are self-consistent and that
regenerating them gives the same files.

The JSON notation for msgpack values (``to_tagged`` / ``from_tagged``) and the file format are
described in ``docs/protocol/vectors/README.md``. Each file is one *scenario*: a freshly started
server (``target`` and command-line options) and what one or more raw connections sent and
received. This module also defines :class:`SpacesEnvironment`, an environment whose spaces use
every kind of space the protocol carries (served as ``protocol_vectors:SpacesEnvironment`` with
``tests/`` on ``PYTHONPATH``).
"""

from __future__ import annotations

import json
import math
import os
import socket
import struct
import sys
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import msgpack
import numpy as np
from gymnasium import spaces

from rlenv import RLAgent, RLEnvironment, RLEnvWorld
from rlenv.protocol.codec import HEADER, NDARRAY_EXT, decode_ndarray, encode_ndarray, pack
from rlenv_client import ServerProcess

__all__ = [
    "SCENARIOS",
    "VECTORS_DIR",
    "Scenario",
    "SpacesEnvironment",
    "decode_value",
    "dumps",
    "encode_value",
    "from_tagged",
    "generate",
    "mask",
    "to_tagged",
    "write",
]

TESTS_DIR: Final = Path(__file__).resolve().parent
VECTORS_DIR: Final = TESTS_DIR.parent / "docs" / "protocol" / "vectors"
CARTPOLE: Final = "examples.cartpole:CartPoleEnvironment"
FAULTY: Final = "examples.faulty:FaultyEnvironment"
PLINKO: Final = "examples.plinko:PlinkoEnvironment"
SPACES: Final = "protocol_vectors:SpacesEnvironment"
CHASE: Final = "per_agent_envs:ChaseEnvironment"
TAG: Final = "examples.tag:TagEnvironment"
COME_AND_GO: Final = "come_and_go_envs:ComeAndGoEnvironment"
SWARM: Final = "swarm_envs:SwarmEnvironment"
VARIES: Final = "<varies>"
"""What a path listed in an exchange's ``varies`` is replaced with before comparing."""

_READ_TIMEOUT = 10.0  # seconds a socket read may block: a deadline, never a sleep
_WIDTH = 100  # JSON lines are broken when longer than this


# --- the JSON notation for msgpack values ------------------------------------------------------


@dataclass(frozen=True)
class RawExt:
    """A msgpack ext value kept as it came: its type code and payload."""

    code: int
    data: bytes


def decode_value(body: bytes) -> Any:
    """The one msgpack value ``body`` holds, keeping every ext type (:class:`RawExt`).

    Unlike :func:`rlenv.protocol.codec.unpack` it refuses no ext type: it is how a vector's
    ``value`` is read from its bytes, whatever the server thinks of them.

    Raises:
        ValueError: ``body`` is not exactly one msgpack value.
    """
    try:
        value = msgpack.unpackb(body, ext_hook=RawExt, strict_map_key=False)
    except Exception as exc:  # msgpack raises several types, ExtraData among them
        raise ValueError(f"not one msgpack value: {exc}") from None
    return value


def to_tagged(value: Any) -> Any:
    """``value`` (decoded msgpack) in the vectors' JSON notation.

    Maps become objects (a key starting with ``$`` gets one more ``$``), arrays lists, bin
    ``{"$bin": hex}``, ext ``{"$ext": code, "hex": payload}`` (ext type 1 also gives ``dtype``,
    ``shape`` and ``data``); everything else is itself.

    Raises:
        TypeError: a value the notation has no form for (a map with a non-string key, a NaN).
    """
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            raise TypeError(f"{value} has no JSON form outside an array's data")
        return value
    if isinstance(value, bytes):
        return {"$bin": value.hex()}
    if isinstance(value, list | tuple):
        return [to_tagged(item) for item in value]
    if isinstance(value, dict):
        tagged = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise TypeError(f"map key {key!r} is not a string")
            tagged["$" + key if key.startswith("$") else key] = to_tagged(item)
        return tagged
    if isinstance(value, np.ndarray):
        return _tagged_ext(NDARRAY_EXT, encode_ndarray(value).data)
    if isinstance(value, RawExt):
        return _tagged_ext(value.code, value.data)
    if isinstance(value, msgpack.Timestamp):
        return _tagged_ext(-1, value.to_bytes())
    raise TypeError(f"no JSON form for {type(value).__name__}")


def _tagged_ext(code: int, data: bytes) -> dict[str, Any]:
    tagged: dict[str, Any] = {"$ext": code, "hex": data.hex()}
    if code == NDARRAY_EXT:
        try:
            array = decode_ndarray(data)
        except ValueError:  # a malformed array: the payload alone
            return tagged
        tagged.update(dtype=array.dtype.str, shape=list(array.shape), data=_elements(array))
    return tagged


def _elements(array: np.ndarray) -> Any:
    """An array's elements as nested lists; non-finite floats as strings, complex as pairs."""
    if array.ndim:
        return [_elements(item) for item in array]
    item = array.item()
    if isinstance(item, complex):
        return [_finite(item.real), _finite(item.imag)]
    return _finite(item) if isinstance(item, float) else item


def _finite(number: float) -> float | str:
    if math.isnan(number):
        return "NaN"
    if math.isinf(number):
        return "Infinity" if number > 0 else "-Infinity"
    return number


def from_tagged(tagged: Any) -> Any:
    """The msgpack-ready value a tagged JSON value stands for (the inverse of :func:`to_tagged`).

    bin gives ``bytes``, ext ``msgpack.ExtType`` (type -1: ``msgpack.Timestamp``); an ext's
    ``dtype``, ``shape`` and ``data`` are ignored (its ``hex`` is the payload).
    """
    if isinstance(tagged, list):
        return [from_tagged(item) for item in tagged]
    if not isinstance(tagged, dict):
        return tagged
    if "$bin" in tagged:
        return bytes.fromhex(tagged["$bin"])
    if "$ext" in tagged:
        code, data = tagged["$ext"], bytes.fromhex(tagged["hex"])
        return msgpack.Timestamp.from_bytes(data) if code == -1 else msgpack.ExtType(code, data)
    return {
        key[1:] if key.startswith("$") else key: from_tagged(item) for key, item in tagged.items()
    }


def encode_value(tagged: Any) -> bytes:
    """The canonical msgpack encoding of a tagged value, as the Python client encodes."""
    return pack(from_tagged(tagged))


def mask(tagged: Any, paths: Sequence[str]) -> Any:
    """A copy of ``tagged`` with the value at each dotted path (``"error.message"``,
    ``"steps.errors.1.message"``: list indexes as numbers) replaced by :data:`VARIES`."""
    tagged = json.loads(json.dumps(tagged))
    for path in paths:
        *parents, last = path.split(".")
        node = tagged
        for key in parents:
            node = node[int(key)] if isinstance(node, list) else node[key]
        if isinstance(node, list):
            node[int(last)] = VARIES
        else:
            node[last] = VARIES
    return tagged


def dumps(document: Any) -> str:
    """``document`` as JSON: indented, but short objects and lists on one line."""
    return _dumps(document, 0) + "\n"


def _dumps(value: Any, indent: int, before: int = 0) -> str:
    """``value`` at ``indent``, after ``before`` characters of its line (a key)."""
    inline = json.dumps(value, ensure_ascii=False, allow_nan=False)
    if not isinstance(value, dict | list) or not value or indent + before + len(inline) <= _WIDTH:
        return inline
    pad = " " * (indent + 2)
    if isinstance(value, dict):
        items = []
        for key, item in value.items():
            name = json.dumps(key, ensure_ascii=False) + ": "
            items.append(pad + name + _dumps(item, indent + 2, len(name)))
        return "{\n" + ",\n".join(items) + "\n" + " " * indent + "}"
    if all(not isinstance(item, dict | list) for item in value):  # a long list of scalars
        return _wrapped(value, indent)
    items = [pad + _dumps(item, indent + 2) for item in value]
    return "[\n" + ",\n".join(items) + "\n" + " " * indent + "]"


def _wrapped(values: list[Any], indent: int) -> str:
    """A list of scalars, as many per line as fit."""
    pad = " " * (indent + 2)
    lines, line = [], ""
    for text in (json.dumps(value, ensure_ascii=False, allow_nan=False) for value in values):
        if line and len(pad) + len(line) + len(text) + 3 > _WIDTH:  # ", " + text + ","
            lines.append(line + ",")
            line = ""
        line = f"{line}, {text}" if line else text
    lines.append(line)
    return "[\n" + "\n".join(pad + text for text in lines) + "\n" + " " * indent + "]"


# --- recording ---------------------------------------------------------------------------------


class Recording:
    """The exchanges of one scenario, in the order they happened, over one or more links."""

    def __init__(self, host: str, port: int) -> None:
        self.address = (host, port)
        self.exchanges: list[dict[str, Any]] = []
        self.links: list[Link] = []

    def connect(self) -> Link:
        """A new raw connection to the server (nothing read yet: call :meth:`Link.hello`)."""
        sock = socket.create_connection(self.address, timeout=_READ_TIMEOUT)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        link = Link(self, sock, len(self.links) + 1)
        self.links.append(link)
        return link

    def close(self) -> None:
        """Close every link."""
        for link in self.links:
            link.sock.close()

    def document(self, title: str, server: str) -> dict[str, Any]:
        """The vector file's content (``connection`` only where several were opened)."""
        if len(self.links) == 1:
            for exchange in self.exchanges:
                del exchange["connection"]
        return {"title": title, "server": server, "exchanges": self.exchanges}

    def record(
        self,
        link: Link,
        sender: str,
        note: str,
        data: bytes,
        *,
        varies: Sequence[str] = (),
        closes: bool = False,
    ) -> dict[str, Any]:
        """Add one frame (or a deliberately broken one) to the recording."""
        exchange: dict[str, Any] = {"from": sender, "connection": link.number, "note": note}
        exchange["hex"] = data.hex()
        body = data[HEADER.size :]
        if len(data) >= HEADER.size and HEADER.unpack_from(data)[0] == len(body):
            try:
                exchange["value"] = to_tagged(decode_value(body))
            except (ValueError, TypeError):  # not msgpack, or no JSON form (a bin key, a NaN)
                pass
            else:
                if encode_value(exchange["value"]) != body:
                    exchange["canonical"] = False
        if varies:
            exchange["varies"] = list(varies)
        if closes:
            exchange["closes"] = True
        self.exchanges.append(exchange)
        return exchange


class Link:
    """One raw connection of a recording: what it sends and receives is recorded."""

    def __init__(self, recording: Recording, sock: socket.socket, number: int) -> None:
        self.recording = recording
        self.sock = sock
        self.number = number

    def send(self, message: Any = None, note: str = "", *, raw: bytes | None = None) -> None:
        """Send ``message`` as one frame (or the bytes ``raw`` as they are) and record it."""
        data = raw if raw is not None else HEADER.pack(len(body := pack(message))) + body
        self.sock.sendall(data)
        self.recording.record(self, "client", note, data)

    def receive(self, note: str, *, varies: Sequence[str] = (), closes: bool = False) -> Any:
        """Read one frame from the server, record it and return its value, ready to be sent
        back (see :func:`from_tagged`).

        ``closes``: the server must close the connection right after it (checked).
        """
        header = self._read(HEADER.size)
        body = self._read(HEADER.unpack(header)[0])
        if closes:
            self.expect_closed()
        exchange = self.recording.record(
            self, "server", note, header + body, varies=varies, closes=closes
        )
        assert "value" in exchange, f"the server sent a frame that is not msgpack: {body!r:.200}"
        return from_tagged(exchange["value"])

    def request(
        self,
        message: Any,
        note: str,
        answer: str = "",
        *,
        varies: Sequence[str] = (),
        closes: bool = False,
    ) -> Any:
        """Send ``message``, then receive the answer (noted ``answer``); returns the answer."""
        self.send(message, note)
        return self.receive(answer, varies=varies, closes=closes)

    def hello(self, note: str | None = None) -> Any:
        """Read the hello; record it only with a ``note``."""
        if note is not None:
            value = self.receive(note)
        else:
            value = decode_value(self._read(HEADER.unpack(self._read(HEADER.size))[0]))
        assert isinstance(value, dict) and "hello" in value, f"not a hello: {value!r:.200}"
        return value

    def expect_closed(self) -> None:
        """Wait (up to the read timeout) for the server to close the connection.

        Raises:
            AssertionError: the server sent more, or kept the connection open.
        """
        try:
            extra = self.sock.recv(1)
        except ConnectionResetError:
            extra = b""
        except TimeoutError:
            raise AssertionError("the server kept the connection open") from None
        assert extra == b"", f"the server sent more after a fatal error: {extra!r}"

    def _read(self, size: int) -> bytes:
        data = bytearray()
        while len(data) < size:
            chunk = self.sock.recv(size - len(data))
            assert chunk, "the server closed the connection before a whole frame"
            data += chunk
        return bytes(data)


# --- scenarios ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Scenario:
    """One vector file: a fresh server and what the clients exchange with it."""

    file: str
    title: str
    target: str
    args: tuple[str, ...]
    run: Callable[[Recording], None] = field(compare=False)
    shared: bool = False
    """It changes nothing on the server (no request of it is accepted that takes control):
    it may share a server with the other such scenarios of the same server, concurrently."""

    @property
    def server(self) -> str:
        """The server, as ``rlenv serve`` takes it."""
        return " ".join([self.target, *self.args])


SCENARIOS: list[Scenario] = []


def scenario(
    file: str,
    title: str,
    target: str = CARTPOLE,
    *args: str,
    shared: bool = False,
) -> Callable[[Callable[[Recording], None]], Callable[[Recording], None]]:
    """Declare the function below as the scenario of ``file`` (see :class:`Scenario`)."""

    def declare(run: Callable[[Recording], None]) -> Callable[[Recording], None]:
        SCENARIOS.append(Scenario(file, title, target, args, run, shared))
        return run

    return declare


def f4(*values: float) -> bytes:
    """``values`` as packed little-endian float32 (a Box action of CartPole is one)."""
    return np.array(values, dtype="<f4").tobytes()


AGENT = {"agent": {}}


@scenario("hello.json", "The hello of CartPole", shared=True)
def _hello(recording: Recording) -> None:
    link = recording.connect()
    link.hello("the server speaks first: the hello, before any request")


@scenario(
    "spaces.json",
    "Every kind of space: hello, packed Dict and Tuple values, steps",
    SPACES,
    "--instances",
    "2",
)
def _spaces(recording: Recording) -> None:
    link = recording.connect()
    link.hello(
        "action space: a Dict of Discrete (start 1), MultiDiscrete, MultiBinary and a Tuple"
        " of Discrete and Box; observation space: a Tuple of Discrete, MultiBinary and a "
        "Dict"
    )
    link.request(
        {"id": 1, "batch": [{"reset": {"seed": 3}, "observation": AGENT}, {"reset": {"seed": 4}}]},
        "reset both instances; the first one's observation too",
        "the packed Tuple: an integer, a bin of int8, a map",
    )
    action = {
        "dial": np.array([1, 2], "<i8").tobytes(),
        "gear": 3,
        "lights": np.array([1, 0, 1], "|i1").tobytes(),
        "pair": [1, f4(0.5, -0.25)],
    }
    link.request(
        {"id": 2, "action": action, "observation": AGENT},
        "a packed Dict action (to instance 0): Discrete as an integer, MultiDiscrete as "
        "a bin of <i8, MultiBinary as a bin of int8, the Tuple as an array",
        "the observation after 2 ticks",
    )
    actions = {
        "dial": np.array([[0, 1], [1, 0]], "<i8").tobytes(),
        "gear": np.array([2, 1], "<i8").tobytes(),
        "lights": np.array([[0, 1, 1], [1, 1, 1]], "|i1").tobytes(),
        "pair": [np.array([0, 1], "<i8").tobytes(), f4(0.0, 1.0, -1.0, 0.5)],
    }
    link.request(
        {"id": 3, "steps": {"action": actions, "reset": [False, True]}},
        "steps: 2 actions packed as batch_space(action_space, 2): Discrete as a bin of "
        "2 × <i8, each array with a leading dimension 2; instance 1 resets instead",
        "columns: the observations packed as batch_space(observation_space, 2)",
    )


@scenario("reset_step.json", "Reset and step CartPole")
def _reset_step(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request(
        {"id": 1, "reset": {"seed": 0}, "observation": AGENT},
        "reset with a seed, asking for the agent observation",
        "the observation: 5 × <f4, packed",
    )
    link.request(
        {"id": 2, "action": f4(0.5), "observation": AGENT},
        "a packed action: 4 bytes, one <f4 (0.5)",
        "4 ticks ran (repeat_action 4)",
    )
    link.request(
        {"id": 3, "action": [-0.5], "observation": AGENT},
        "the action as a list of numbers",
        "converted to the space's dtype",
    )
    link.request(
        {"id": 4, "action": f4(0.0), "repeat_action": 1},
        "one tick only, and no observation asked",
        "observation nil, frames 1",
    )
    body = (
        b"\x83"
        + pack("id")
        + b"\xce\x00\x00\x00\x05"
        + pack("action")
        + b"\x91\xca"
        + struct.pack(">f", 0.25)
        + pack("observation")
        + pack(AGENT)
    )
    link.send(
        raw=HEADER.pack(len(body)) + body,
        note="the same map may use other valid encodings: id 5 as a uint 32 and the "
        "action [0.25] as a float 32",
    )
    link.receive("accepted as any other encoding of the same value")


@scenario("observation.json", "Observation: agent, world and a small render")
def _observation(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request({"id": 1, "reset": {"seed": 0}}, "reset", "observation nil: none was asked")
    link.request(
        {"id": 2, "observation": {"agent": {}, "world": {}, "render": {"width": 4, "height": 3}}},
        "every observation: agent, world data and a 4 × 3 render",
        "the render: an ext type 1 array, |u1 of shape (3, 4, 3)",
    )


@scenario("config.json", "Configuration")
def _config(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request(
        {
            "id": 1,
            "config": {
                "environment": {"repeat_action": 2},
                "agent": {"max_force": 5.0},
                "world": {"damping": 0.5},
            },
        },
        "configure the environment, every agent and the world",
        "an empty response",
    )
    link.request(
        {"id": 2, "reset": {"seed": 0}, "action": f4(1.0), "observation": AGENT},
        "reset and act in one request",
        "2 ticks: the configured repeat_action",
    )


@scenario(
    "agent_settings.json",
    "Settings per agent (protocol 2.6): every agent, a class, one agent",
    CHASE,
)
def _agent_settings(recording: Recording) -> None:
    link = recording.connect()
    link.hello(
        "three agents of two classes: Chaser (ChaserAgent), Runner1 and Runner2 (RunnerAgent)"
    )
    link.request(
        {
            "id": 1,
            "config": {
                "agent": {
                    "max_force": 9.0,
                    "RunnerAgent": {"sight": 3.0},
                    "Runner1": {"max_force": 6.0},
                }
            },
        },
        "a setting for every agent, one for a class, one for an agent: the more precise wins",
        "an empty response",
    )
    link.request({"id": 2, "reset": {"seed": 0}}, "reset")
    link.request(
        {"id": 3, "snapshot": {}},
        "take a snapshot",
        "info.snapshot.config.agent: each agent's settings, by name",
    )
    link.request(
        {"id": 4, "config": {"agent": {"Runner3": {"max_force": 1.0}}}},
        "a key that is neither a setting nor an agent",
        "invalid_config naming the settings, the agents and their classes",
    )


@scenario(
    "come_and_go.json",
    "Agents that come and go (protocol 2.6): a join, a departure, the end when none is left",
    COME_AND_GO,
)
def _come_and_go(recording: Recording) -> None:
    link = recording.connect()
    link.hello("possible_agents: A, B, C, D (Walker); agents lists the same names")
    link.request({"id": 1, "reset": {"seed": 0}, "observation": AGENT}, "A and B start")
    every = {"A": 2, "B": 2}
    link.request({"id": 2, "action": every, "observation": AGENT}, "ticks 1 to 4")
    link.request(
        {"id": 3, "action": every, "observation": AGENT},
        "ticks 5 to 8",
        "C joined at tick 6: in the answer, its reward nil",
    )
    link.request(
        {"id": 4, "action": {**every, "C": 2}, "observation": AGENT},
        "ticks 9 to 12",
        "B left at tick 10: its last observation, reward and terminated, once",
    )
    link.request(
        {"id": 5, "action": {"A": 2, "B": 2, "C": 0}, "observation": AGENT},
        "an entry for B, who left: ignored",
        "A and C",
    )
    link.request(
        {"id": 6, "action": {"A": 2}, "observation": AGENT},
        "no entry for C, who is due",
        "invalid_action naming C",
    )


@scenario(
    "swarm.json",
    "A group of agents (protocol 2.7): one array per group, members that join and leave",
    SWARM,
    "--instances",
    "2",
)
def _swarm(recording: Recording) -> None:
    link = recording.connect()
    link.hello("groups: Discs, 8 members of Box (4,) observations and Box (2,) actions")
    link.request({"id": 1, "reset": {"seed": 0}, "observation": AGENT}, "6 members start")
    push = {"Discs": f4(*[1.0, 0.3] * 8)}  # one array of (8, 2): every row, in play or not
    link.request({"id": 2, "action": push, "observation": AGENT}, "ticks 1 to 4")
    link.request({"id": 3, "action": push, "observation": AGENT}, "ticks 5 to 8")
    link.request(
        {"id": 4, "action": push, "observation": AGENT},
        "ticks 9 to 12",
        "member 6 joined at tick 10: its joined row set, its reward 0",
    )
    link.request({"id": 5, "action": push, "observation": AGENT}, "ticks 13 to 16")
    link.request(
        {"id": 6, "action": push, "observation": AGENT},
        "ticks 17 to 20",
        "member 3 left at the edge: its final row, terminated, once; the step goes on",
    )
    link.request(
        {"id": 7, "action": push, "observation": AGENT},
        "ticks 21 to 24",
        "member 3 is out of play: zeros, active false",
    )
    link.request(
        {"id": 8, "action": {"Discs": f4(*[1.0, 0.3] * 7)}, "observation": AGENT},
        "an action of 7 rows for a group of 8",
        "invalid_action naming the group",
    )
    link.request(
        {"id": 9, "steps": {"action": {"Discs": f4(*[0.0] * 32)}, "reset": [True, True]}},
        "steps: both instances reset",
        "the group's column (2, 8, 4); each row's info.agents holds its arrays",
    )


@scenario(
    "claim.json", "An observer plays one agent beside the controller: claims (protocol 2.6)", TAG
)
def _claim(recording: Recording) -> None:
    controller = recording.connect()
    controller.hello("three agents: Chaser, Runner1 and Runner2, each a Box(-1, 1, (2,))")
    controller.request({"id": 1, "reset": {"seed": 0}}, "the controller starts an episode")
    person = recording.connect()
    person.hello()
    person.request(
        {"id": 1, "claim": {"agent": "Runner1", "action": f4(1.0, -0.5)}},
        "claim Runner1, holding an action for it: no control taken",
        "info.claimed: the agents claimed now",
    )
    whole = {"Chaser": f4(0.0, 1.0), "Runner1": f4(-1.0, 0.0), "Runner2": f4(0.0, 0.0)}
    controller.request(
        {"id": 2, "action": whole, "observation": AGENT},
        "a whole action, as ever",
        "info.claimed: Runner1 moved by the held action, not by this entry",
    )
    person.request(
        {"id": 2, "claim": {"agent": "Runner2", "action": f4(0.0, 0.0)}},
        "a second agent",
        "bad_request: one claim per client",
    )
    controller.request(
        {"id": 3, "claim": {"agent": "Runner2", "action": f4(0.0, 0.0)}},
        "the controller claims",
        "bad_request: it acts for every agent already",
    )
    person.request({"id": 3, "claim": None}, "release the claim", "an empty response")
    controller.request(
        {"id": 4, "action": whole, "observation": AGENT},
        "Runner1 is the controller's again",
        "no claimed in info",
    )


@scenario("snapshot.json", "Snapshot and restore")
def _snapshot(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request({"id": 1, "reset": {"seed": 0}}, "reset")
    link.request({"id": 2, "action": f4(0.5), "repeat_action": 2}, "a packed action, 2 ticks")
    link.request({"id": 3, "action": [-1.0]}, "an action as a list")
    answer = link.request(
        {"id": 4, "snapshot": {}, "observation": AGENT},
        "take a snapshot",
        "info.snapshot: the configuration, the generator's state, the events",
    )
    link.request({"id": 5, "reset": {"seed": 1}}, "another episode")
    link.request(
        {"id": 6, "restore": answer["info"]["snapshot"], "observation": AGENT},
        "restore the snapshot as it came",
        "the same observation as at the snapshot",
    )


@scenario("inspect.json", "Introspection: tree, get, set")
def _inspect(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request({"id": 1, "reset": {"seed": 0}}, "reset")
    link.request(
        {"id": 2, "inspect": {"tree": {}}},
        "the node tree",
        "info.tree: every node with its exported properties",
    )
    link.request(
        {"id": 3, "inspect": {"get": {"path": "Agent", "property": "max_force"}}},
        "read one property (a path relative to the environment)",
        "info.value",
    )
    link.request(
        {
            "id": 4,
            "inspect": {
                "set": {"path": "/root/CartPole/World", "property": "damping", "value": 0.5}
            },
        },
        "set one (an absolute path)",
    )
    link.request(
        {"id": 5, "inspect": {"get": {"path": "World", "property": "damping"}}}, "read it back"
    )
    link.request({"id": 6, "reset": {"seed": 0}}, "a new episode")
    link.request(
        {"id": 7, "inspect": {"get": {"path": "World", "property": "damping"}}},
        "a set lasts one episode",
        "the value from before the set again",
    )


@scenario(
    "inspector.json",
    "An inspector beside the controller: draw lists, statistics, edits (protocol 2.2)",
)
def _inspector(recording: Recording) -> None:
    controller = recording.connect()
    controller.hello()
    controller.request({"id": 1, "reset": {"seed": 0}}, "the controller starts an episode")
    controller.request({"id": 2, "action": f4(0.0)}, "and steps once", "reward 4.0, frames 4")
    inspector = recording.connect()
    inspector.hello()
    inspector.request(
        {"id": 1, "observation": {"draw": {}}},
        "the scene as a draw list",
        "observation.draw: the view, then segment (track), polygon (cart), "
        "segment (pole); colours 0xRRGGBB",
    )
    inspector.request(
        {"id": 2, "inspect": {"node": {"path": "World"}}},
        "one node",
        "info.node: the world, with its config section and configurable names",
    )
    inspector.request(
        {
            "id": 3,
            "inspect": {
                "set": {"path": "World/Physics/Pole", "property": "angular_velocity", "value": 1.0}
            },
        },
        "an edit for this episode: no control taken",
        "an empty answer",
    )
    inspector.request(
        {"id": 4, "inspect": {"configure": {"world": {"gravity": [0.0, -5.0]}}}},
        "an edit of a setting: it lasts across episodes",
        "an empty answer",
    )
    controller.request(
        {"id": 3, "action": f4(0.0)},
        "the controller steps on, in the edited world",
        "its reward is its own (the inspector's answers carried 0.0)",
    )
    controller.request(
        {"id": 4, "snapshot": {}},
        "the controller's snapshot",
        "events: both actions, the set and the config, in order",
    )
    controller.request(
        {"id": 5, "reset": {"seed": 1}},
        "a new episode ends the first (its return is the controller's rewards)",
    )
    inspector.request(
        {"id": 5, "inspect": {"stats": {}}},
        "the episodes so far",
        "info.stats: episode 0 ended by a reset after 2 actions; the new one under way",
    )
    inspector.request(
        {"id": 6, "inspect": {"stats": {"since": 1}}},
        "only the episodes numbered 1 and later",
        "none yet",
    )


@scenario(
    "episodes.json",
    "Recent episodes, fetched by an observer (protocol 2.5)",
    CARTPOLE,
    "--keep-episodes",
    "2",
)
def _episodes(recording: Recording) -> None:
    controller = recording.connect()
    controller.hello()
    controller.request({"id": 1, "reset": {"seed": 0}}, "the controller starts an episode")
    controller.request({"id": 2, "action": f4(0.5)}, "and steps once")
    controller.request({"id": 3, "reset": {"seed": 1}}, "a reset finishes it (cut short)")
    controller.request({"id": 4, "action": f4(-0.5)}, "one step")
    controller.request({"id": 5, "action": f4(0.5), "repeat_action": 2}, "another, 2 ticks")
    controller.request({"id": 6, "reset": {"seed": 2}}, "the second finished")
    controller.request({"id": 7, "action": f4(0.0)}, "one step")
    controller.request(
        {"id": 8, "reset": {"seed": 3}},
        "the third finished: the server keeps 2 (--keep-episodes 2), the first is dropped",
    )
    observer = recording.connect()
    observer.hello()
    observer.request(
        {"id": 1, "episodes": {}},
        "the kept episodes: no control taken",
        "info.episodes: the second and third, oldest first, each a snapshot and how it ended",
    )
    observer.request({"id": 2, "episodes": {"last": 1}}, "only the most recent one")
    observer.request({"id": 3, "episodes": {"last": 0}}, "a bad argument", "bad_request")


@scenario("empty_request.json", "An empty request and a nil action", shared=True)
def _empty(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request({"id": 1}, "a request with only an id", "an empty response")
    link.request(
        {"id": 2, "action": None},
        "action nil: no action, no episode needed",
        "an ordinary (empty) response",
    )


@scenario("batch_steps.json", "Several instances: batch and steps", CARTPOLE, "--instances", "2")
def _batch_steps(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request(
        {"id": 1, "batch": [{"reset": {"seed": 1}}, {"reset": {"seed": 2}}]},
        "reset both instances",
        "one response per instance, each with the batch's id",
    )
    link.request(
        {"id": 2, "steps": {"action": f4(0.5, -0.5), "reset": [False, True]}},
        "steps: instance 0 acts, instance 1 resets (its action is checked, then "
        "ignored); the actions packed as one bin of shape (2, 1)",
        "columns: observation (2, 5) <f4, reward 2 × <f8, terminated and truncated 2 "
        "bytes, frames 2 × <i8, info a list",
    )
    link.request(
        {"id": 3, "steps": {"action": [[0.25], [0.0]], "reset": b"\x00\x00", "repeat_action": 1}},
        "steps with the actions as nested lists and the flags as a bin, one tick",
    )
    link.request(
        {"id": 4, "batch": [None, {"action": [2.0], "observation": AGENT}]},
        "a batch leaving instance 0 alone; instance 1's action is refused",
        "nil for instance 0, an error in instance 1's slot",
    )
    link.request(
        {"id": 5, "batch": [{"observation": AGENT}, {"observation": AGENT}]}, "observe both"
    )
    link.request(
        {"id": 6, "batch": [{"observation": AGENT}]},
        "a batch shorter than K leaves the instances beyond its end alone",
        "one slot",
    )


@scenario("token.json", "A server that requires a token", CARTPOLE, "--token", "s3cret")
def _token(recording: Recording) -> None:
    link = recording.connect()
    link.hello("token_required is true")
    link.request(
        {"id": 1, "token": "s3cret"},
        "the token alone, as the Python client sends it",
        "an empty response",
    )
    link.request({"id": 2, "reset": {"seed": 0}}, "later requests need no token")
    wrong = recording.connect()
    wrong.hello()
    wrong.request(
        {"id": 1, "token": "guess", "reset": {"seed": 0}},
        "a wrong token",
        "unauthorized, fatal: the server closes the connection",
        closes=True,
    )
    missing = recording.connect()
    missing.hello()
    missing.request({"id": 1, "observation": AGENT}, "no token", closes=True)
    late = recording.connect()
    late.hello()
    late.request(
        {"id": "one", "observation": AGENT},
        "a frame that is not read as a request (no integer id) does not count",
        "non-fatal bad_request",
    )
    late.request(
        {"id": 2, "token": "s3cret", "observation": AGENT},
        "the next request must carry the token",
        "observing is open to every client",
    )


@scenario("error_bad_frame.json", "bad_frame: frames that are not a request map", shared=True)
def _bad_frame(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    raw = bytes.fromhex("c1")
    link.send(raw=HEADER.pack(len(raw)) + raw, note="invalid msgpack: 0xc1 is never used")
    link.receive("non-fatal; the frame is consumed and the connection goes on")
    link.request(
        {"id": 2, "action": msgpack.ExtType(5, b"\x00")}, "a foreign ext type (5) inside a request"
    )
    timestamp = pack({"id": 3, "action": msgpack.Timestamp(0)})
    assert bytes.fromhex("d6ff00000000") in timestamp  # fixext 4, type -1, 4 bytes
    link.send(
        raw=HEADER.pack(len(timestamp)) + timestamp,
        note="a msgpack timestamp (ext type -1, fixext 4: d6 ff + 4 bytes) inside a request",
    )
    link.receive("")
    raw = pack({"id": 4}) + b"\xc0"
    link.send(raw=HEADER.pack(len(raw)) + raw, note="trailing bytes: the map {id: 4}, then nil")
    link.receive("")
    link.request([1, 2], "not a map: an array")
    bad_dtype = b"\x03\x01<O8" + struct.pack("<Q", 1) + bytes(8)
    link.request(
        {"id": 6, "action": msgpack.ExtType(NDARRAY_EXT, bad_dtype)},
        "a malformed array: ext type 1 of dtype <O8 (objects)",
    )
    other_spelling = b"\x03\x01=f4" + struct.pack("<Q", 1) + f4(0.5)
    link.request(
        {"id": 7, "action": msgpack.ExtType(NDARRAY_EXT, other_spelling)},
        "an ext type 1 array whose dtype is not spelled as numpy's dtype.str (=f4, not <f4)",
    )
    for raw, note in [
        (pack({"id": 9, b"reset": {}}), "a bin map key (b'reset'): every map key is a str"),
        (pack({b"id": 10}), "a bin key where the id belongs"),
        (
            pack({"id": 11, "reset": {"seed": 0, "options": {b"k": 1}}}),
            "a bin map key deep inside a part (reset.options)",
        ),
    ]:
        link.send(raw=HEADER.pack(len(raw)) + raw, note=note)
        link.receive("bad_frame with id nil: the frame could not be read as a request")
    link.request({"id": 12}, "the connection goes on", "an empty response")
    too_long = recording.connect()
    too_long.hello()
    too_long.send(
        raw=HEADER.pack(64 * 1024 + 1),
        note="a length prefix over the limit before the first request (64 KiB + 1); "
        "no body follows",
    )
    too_long.receive("fatal, id nil: the stream cannot be resynchronised", closes=True)


@scenario("error_bad_request.json", "bad_request: maps that are not valid requests", shared=True)
def _bad_request(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request({"reset": {}}, "no id", "id nil: it could not be read")
    link.request({"id": "two"}, "an id that is not an integer")
    link.request({"id": 3, "jump": {}}, "an unknown part")
    link.request({"id": 4, "reset": {"seed": -1}}, "a wrong value")
    link.request({"id": 5, "reset": {"seed": 0, "colour": "red"}}, "an unknown key in a part")
    link.request({"id": 6, "snapshot": {}, "reset": {}}, "parts that may not go together")
    link.request({"id": 7, "repeat_action": 2}, "repeat_action without an action")
    link.request({"id": 8, "token": 8}, "a token that is not a string")
    raw = pack(
        {"id": 9, "inspect": {"set": {"path": "World", "property": "damping", "value": math.inf}}}
    )
    link.send(
        raw=HEADER.pack(len(raw)) + raw, note="inspect set of a value that is not finite (infinity)"
    )
    link.receive("refused like a value of the wrong sort")


@scenario(
    "shared_memory.json",
    "shared_memory (protocol 2.3): requests for a lane the server refuses, on the socket",
    shared=True,
)
def _shared_memory(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    key = bytes(range(16))
    link.request(
        {"id": 1, "shared_memory": {"address": "/run/docker.sock", "key": key}},
        "an address that is not a lane's name",
        "only 'rlenv-lane-' and 32 hex digits",
    )
    link.request(
        {"id": 2, "shared_memory": {"address": "rlenv-lane-" + "0" * 32, "key": b"short"}},
        "a key of another size",
    )
    link.request(
        {"id": 3, "shared_memory": {"address": "rlenv-lane-" + "0" * 32, "key": key}},
        "no client listens on that name",
        "the lane cannot be reached",
    )
    link.request(
        {"id": 4, "shared_memory": {"address": "rlenv-lane-" + "0" * 32, "key": key}, "reset": {}},
        "with another part",
        "it goes alone",
    )


def _peg(name: str, x: float) -> dict[str, Any]:
    """A Plinko peg as level data (what ``PackedScene.to_data`` gives)."""
    return {
        "class": "Peg",
        "name": name,
        "properties": {"position": [x, 0.0]},
        "children": [
            {
                "class": "CollisionShape",
                "name": "Skin",
                "properties": {
                    "shape": {"kind": "circle", "radius": 0.1, "offset": [0.0, 0.0]},
                    "friction": 0.2,
                    "elasticity": 0.5,
                },
            }
        ],
    }


TWO_PEGS = {
    "format": "rlenv.PackedScene",
    "version": 1,
    "root": {
        "class": "Node2D",
        "name": "Level",
        "properties": {"position": [0.0, 0.0]},
        "children": [
            {
                "class": "Node2D",
                "name": "Pegs",
                "properties": {"position": [0.0, 6.0]},
                "children": [_peg("Peg", 0.0), _peg("Peg2", 1.0)],
            }
        ],
    },
}
"""A Plinko level of two pegs, as data."""


@scenario("edit_level.json", "edit_level (protocol 2.4): Plinko edits a level of two pegs", PLINKO)
def _edit_level(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request(
        {"id": 1, "edit_level": {"level": TWO_PEGS, "seed": 3, "n_edits": 2}},
        "two edits, with no episode and no control",
        "info.level: the edited level",
    )
    link.request(
        {"id": 2, "edit_level": {"level": TWO_PEGS, "seed": 3, "n_edits": 2}},
        "the same seed",
        "the same edit",
    )
    link.request(
        {"id": 3, "edit_level": {"level": TWO_PEGS, "seed": 3, "n_edits": 0}},
        "n_edits out of [1, 64]",
        "bad_request",
    )
    link.request(
        {"id": 4, "edit_level": {"level": "a level?", "seed": 3}},
        "a level the environment refuses",
        "bad_request naming its _edit_level",
    )
    link.request(
        {"id": 5, "reset": {"seed": 0, "options": {"level": TWO_PEGS}}}, "the level, played"
    )


@scenario("error_invalid_action.json", "invalid_action: actions outside the action space")
def _invalid_action(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request({"id": 1, "reset": {"seed": 0}}, "reset")
    link.request({"id": 2, "action": [1.5]}, "out of the bounds [-1, 1]")
    link.request({"id": 3, "action": b"\x00\x00\x00"}, "packed bytes of the wrong size (3, not 4)")
    link.request({"id": 4, "action": [0.5, 0.5]}, "the wrong shape")
    link.request({"id": 5, "action": f4(math.nan)}, "NaN, packed")
    link.request({"id": 6, "action": 0.5}, "a plain number: nothing is broadcast to shape (1,)")


@scenario(
    "error_invalid_config.json",
    "invalid_config: configuration the environment refuses",
    shared=True,
)
def _invalid_config(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request(
        {"id": 1, "config": {"world": {"gravity": 1.0}}},
        "a key the world does not declare configurable",
    )
    link.request(
        {"id": 2, "config": {"agent": {"max_force": "strong"}}}, "a value of the wrong sort"
    )
    link.request(
        {"id": 3, "config": {"environment": {"repeat_action": 0}}}, "repeat_action below 1"
    )
    link.request(
        {"id": 4, "config": {"physics": {}}}, "a map of the wrong shape is a bad_request instead"
    )
    for request_id, value, name in [(5, math.nan, "NaN"), (6, math.inf, "infinity")]:
        raw = pack({"id": request_id, "config": {"world": {"gravity": [0.0, value]}}})
        link.send(
            raw=HEADER.pack(len(raw)) + raw,
            note=f"a setting holding {name} (gravity [0, {name}]): a configuration "
            "outlives resets, so it is refused",
        )
        link.receive("invalid_config naming the key")


@scenario("error_reset_required.json", "reset_required: no episode running")
def _reset_required(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request({"id": 1, "action": f4(0.0)}, "an action before the first reset")
    link.request({"id": 2, "observation": AGENT}, "an observation before the first reset")
    link.request({"id": 3, "snapshot": {}}, "a snapshot before any episode")
    link.request(
        {"id": 4, "reset": {"seed": 0}, "action": f4(1.0), "repeat_action": 100},
        "reset and push hard for up to 100 ticks",
        "the pole fell: terminated, fewer ticks ran",
    )
    link.request({"id": 5, "action": f4(0.0)}, "an action after the episode ended")
    link.request({"id": 6, "observation": AGENT}, "observing an ended episode is allowed")


@scenario(
    "error_busy.json",
    "busy: another client controls the environment; too many clients",
    CARTPOLE,
    "--max-connections",
    "2",
)
def _busy(recording: Recording) -> None:
    first = recording.connect()
    first.hello()
    first.request({"id": 1, "reset": {"seed": 0}}, "the first client takes control")
    second = recording.connect()
    second.hello()
    second.request(
        {"id": 1, "reset": {"seed": 0}},
        "a second client tries to take control",
        "non-fatal; the message names the controller's address",
        varies=["error.message"],
    )
    second.request({"id": 2, "observation": AGENT}, "observing is open to every client")
    third = recording.connect()
    third.receive(
        "a third client, over --max-connections: fatal busy instead of the hello", closes=True
    )


@scenario(
    "error_timeout.json",
    "timeout: incomplete frames and idle clients",
    CARTPOLE,
    "--idle-timeout",
    "0.5",
    "--frame-deadline",
    "0.2",
)
def _timeout(recording: Recording) -> None:
    slow = recording.connect()
    idle = recording.connect()
    slow.hello()
    idle.hello()
    whole = pack({"id": 1})
    slow.send(
        raw=HEADER.pack(len(whole)) + whole[:2],
        note=f"the start of a frame (its prefix announces {len(whole)} bytes, 2 follow), "
        "then nothing",
    )
    slow.receive("the frame is not complete within 0.2 s (--frame-deadline): fatal", closes=True)
    idle.receive(
        "a client that sends nothing for 0.5 s (--idle-timeout): unsolicited, fatal", closes=True
    )


@scenario(
    "error_environment_error.json",
    "environment_error: user code raises",
    FAULTY,
    "--instances",
    "2",
)
def _environment_error(recording: Recording) -> None:
    link = recording.connect()
    link.hello()
    link.request({"id": 1, "reset": {"seed": 0}, "observation": AGENT}, "reset instance 0")
    link.request(
        {"id": 2, "action": 1},
        "action 1 makes the agent's tick raise",
        "the message names the node and carries the traceback",
        varies=["error.message"],
    )
    link.request({"id": 3, "action": 0}, "the instance needs a reset now")
    link.request(
        {"id": 4, "reset": {"seed": 0}, "action": 0, "observation": AGENT}, "a reset recovers"
    )
    link.request(
        {"id": 5, "batch": [{"reset": {"seed": 0}}, {"reset": {"seed": 1}}]}, "reset both instances"
    )
    link.request(
        {"id": 6, "steps": {"action": np.array([0, 1], "<i8").tobytes()}},
        "steps: instance 1's action raises",
        "errors: nil for instance 0, instance "
        "1's environment_error; its row of the other columns is zeros",
        varies=["steps.errors.1.message"],
    )


# --- the environment whose spaces cover every kind -----------------------------------------------


class SpacesWorld(RLEnvWorld):
    """No physics: draws the agent's starting count from the episode's generator."""

    def __init__(self) -> None:
        super().__init__("World")

    def sample_initial_position(self) -> int:
        """The agent's starting count, 0..3."""
        return int(self.np_random.integers(0, 4))


class SpacesAgent(RLAgent):
    """Its action and observation spaces hold every kind of space; its observation echoes."""

    action_space = spaces.Dict(
        {
            "gear": spaces.Discrete(3, start=1),
            "dial": spaces.MultiDiscrete([2, 3]),
            "lights": spaces.MultiBinary(3),
            "pair": spaces.Tuple((spaces.Discrete(2), spaces.Box(-1.0, 1.0, (2,), np.float32))),
        }
    )
    observation_space = spaces.Tuple(
        (
            spaces.Discrete(4),
            spaces.MultiBinary([2, 2]),
            spaces.Dict(
                {
                    "gear": spaces.Discrete(3, start=1),
                    "level": spaces.Box(-8.0, 8.0, (2,), np.float32),
                }
            ),
        )
    )

    def __init__(self) -> None:
        super().__init__("Agent")
        self.count = 0
        self.action: Mapping[str, Any] | None = None

    def reset(self, arguments: Any) -> None:
        """Start counting from the sampled count; forget the last action."""
        self.count = int(arguments)
        self.action = None

    def set_action(self, action: Any) -> None:
        """Remember the action."""
        self.action = action

    def _after_physics_tick(self, delta: float) -> None:
        self.count += 1
        self.add_reward(0.25)

    def get_data(self, observation_request: Mapping[str, Any]) -> tuple[Any, ...]:
        """(count mod 4, lights and the pair's switch as 2 × 2 bits, gear and 2 × the levels)."""
        action = self.action
        if action is None:
            return (
                self.count % 4,
                np.zeros((2, 2), np.int8),
                {"gear": 1, "level": np.zeros(2, np.float32)},
            )
        bits = [*np.asarray(action["lights"]).tolist(), int(action["pair"][0])]
        level = np.asarray(action["pair"][1], np.float32) * 2
        return (
            self.count % 4,
            np.array(bits, np.int8).reshape(2, 2),
            {"gear": int(action["gear"]), "level": level},
        )


class SpacesEnvironment(RLEnvironment):
    """An agent whose spaces use Discrete, MultiDiscrete, MultiBinary, Box, Tuple and Dict."""

    def __init__(self) -> None:
        super().__init__("Spaces", repeat_action=2)
        self.add_child(SpacesAgent())
        self.add_child(SpacesWorld())


# --- generating --------------------------------------------------------------------------------


def _start(key: tuple[str, tuple[str, ...], int]) -> ServerProcess:
    target, args, _ = key
    path = os.pathsep.join(filter(None, [str(TESTS_DIR), os.environ.get("PYTHONPATH")]))
    return ServerProcess(target, args=args, env={"PYTHONPATH": path})


def _server_key(index: int, item: Scenario) -> tuple[str, tuple[str, ...], int]:
    """Which server a scenario runs against: shared ones share one per target and options."""
    return item.target, item.args, -1 if item.shared else index


def _run(item: Scenario, server: ServerProcess) -> dict[str, Any]:
    recording = Recording(server.host, server.port)
    try:
        item.run(recording)
    finally:
        recording.close()
    return recording.document(item.title, item.server)


def generate(scenarios: Sequence[Scenario] = SCENARIOS) -> dict[str, dict[str, Any]]:
    """Run every scenario against a fresh server; the documents by file name.

    Each scenario has a server of its own, but for the scenarios that change nothing, which
    share one per target and options. The servers start and the scenarios run in parallel;
    every server is closed at the end.
    """
    keys = [_server_key(index, item) for index, item in enumerate(scenarios)]
    with ThreadPoolExecutor(max(1, len(scenarios))) as pool:
        starting = {key: pool.submit(_start, key) for key in dict.fromkeys(keys)}
        try:
            servers = {key: future.result() for key, future in starting.items()}
            documents = list(pool.map(_run, scenarios, [servers[key] for key in keys]))
        finally:
            list(pool.map(ServerProcess.close, _started(starting.values())))
    return {item.file: document for item, document in zip(scenarios, documents, strict=True)}


def _started(futures: Iterable[Future[ServerProcess]]) -> Iterator[ServerProcess]:
    for future in futures:
        if future.exception() is None:
            yield future.result()


def write(documents: Mapping[str, Any], directory: Path = VECTORS_DIR) -> None:
    """Write the documents as files, removing the vector files no scenario produces any more."""
    directory.mkdir(parents=True, exist_ok=True)
    for stale in directory.glob("*.json"):
        if stale.name not in documents:
            stale.unlink()
    for name, document in documents.items():
        (directory / name).write_text(dumps(document), encoding="utf-8")


def main() -> None:
    """Regenerate ``docs/protocol/vectors/*.json``."""
    documents = generate()
    write(documents)
    count = sum(len(document["exchanges"]) for document in documents.values())
    print(f"{len(documents)} files, {count} frames in {VECTORS_DIR}", file=sys.stderr)


if __name__ == "__main__":
    main()
