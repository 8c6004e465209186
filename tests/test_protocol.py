"""Tests of the sans-IO wire protocol (rlenv.protocol), without sockets.

Two :class:`Connection` objects talk by handing each other bytes, like h11's ConnectionPair.
"""

from __future__ import annotations

import re
import struct
from typing import Any

import msgpack
import numpy as np
import pytest
from gymnasium import spaces
from spaces_catalog import TESTING_SPACES

from rlenv.errors import (
    ErrorCode,
    LocalProtocolError,
    ProtocolVersionError,
    RemoteProtocolError,
)
from rlenv.protocol import (
    CONNECTION_CLOSED,
    DEFAULT_MAX_FRAME_SIZE,
    NDARRAY_EXT,
    NEED_DATA,
    PROTOCOL_VERSION,
    Connection,
    ErrorReply,
    Hello,
    Request,
    Response,
    Role,
    State,
    Steps,
    StepsResponse,
    pack,
    unpack,
)
from rlenv.testing import frame as raw_frame

# --- helpers ---------------------------------------------------------------------------------


def frame(obj: Any) -> bytes:
    """A frame holding ``obj`` encoded as msgpack, built by hand (no Connection checks)."""
    return raw_frame(pack(obj))


def drain(conn: Connection) -> list[Any]:
    """Every message ``conn`` can produce now, up to NEED_DATA or CONNECTION_CLOSED (included)."""
    out: list[Any] = []
    while True:
        message = conn.next_message()
        if message is NEED_DATA:
            return out
        out.append(message)
        if message is CONNECTION_CLOSED:
            return out


def make_hello(**overrides: Any) -> Hello:
    fields: dict[str, Any] = {
        "environment": "Test-v0",
        "action_space": spaces.Box(-1.0, 1.0, (2,), np.float32),
        "observation_space": spaces.Dict({"agent": spaces.Box(-np.inf, np.inf, (4,), np.float64)}),
        "agents": ("agent",),
        "physics_ticks_per_second": 120,
        "repeat_action": 2,
        "render_modes": ("rgb_array",),
    }
    fields.update(overrides)
    return Hello(**fields)


class ConnectionPair:
    """A client and a server Connection wired back to back."""

    def __init__(self, max_frame_size: int = DEFAULT_MAX_FRAME_SIZE) -> None:
        self.client = Connection(Role.CLIENT, max_frame_size)
        self.server = Connection(Role.SERVER, max_frame_size)

    def other(self, conn: Connection) -> Connection:
        return self.server if conn is self.client else self.client

    def send(self, sender: Connection, message: Any) -> list[Any]:
        """Send ``message`` from ``sender``; return what the peer receives."""
        data = sender.send(message)
        receiver = self.other(sender)
        receiver.receive_data(data)
        return drain(receiver)

    def handshake(self, hello: Hello | None = None) -> Hello:
        hello = hello or make_hello()
        (received,) = self.send(self.server, hello)
        return received


@pytest.fixture
def pair() -> ConnectionPair:
    return ConnectionPair()


@pytest.fixture
def ready() -> ConnectionPair:
    p = ConnectionPair()
    p.handshake()
    return p


def _root_buffer(array: np.ndarray) -> object:
    base: object = array
    while isinstance(base, np.ndarray):
        base = base.base
    return base


def _assert_bit_exact(decoded: Any, original: np.ndarray) -> None:
    assert isinstance(decoded, np.ndarray)
    assert decoded.dtype == original.dtype
    assert decoded.dtype.str == original.dtype.str  # byte order kept
    assert decoded.shape == original.shape
    assert decoded.tobytes() == original.tobytes()


# --- codec: arrays ---------------------------------------------------------------------------

_DTYPES = [
    "bool",
    "int8",
    "int16",
    "int32",
    "int64",
    "uint8",
    "uint16",
    "uint32",
    "uint64",
    "float16",
    "float32",
    "float64",
    "complex64",
    "complex128",
    ">f4",
    ">i8",
    ">u2",
    ">c8",
]
_SHAPES = [(), (0,), (5,), (2, 3, 4), (3, 0, 2), (1, 1, 1, 1)]


def _random_array(dtype: str, shape: tuple[int, ...], seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    dt = np.dtype(dtype)
    count = int(np.prod(shape, dtype=np.int64))
    if dt.kind == "b":
        return rng.integers(0, 2, size=shape).astype(dt)
    # Random bit patterns: NaN payloads, infinities and denormals must survive untouched.
    return np.frombuffer(rng.bytes(count * dt.itemsize), dtype=dt).reshape(shape).copy()


@pytest.mark.parametrize("shape", _SHAPES, ids=str)
@pytest.mark.parametrize("dtype", _DTYPES)
def test_array_round_trip_is_bit_exact(dtype: str, shape: tuple[int, ...]) -> None:
    original = _random_array(dtype, shape)
    decoded = unpack(pack(original))
    _assert_bit_exact(decoded, original)


def test_float_special_values_round_trip() -> None:
    original = np.array(
        [np.nan, -np.nan, np.inf, -np.inf, -0.0, 0.0, 5e-324, np.finfo(np.float64).max]
    )
    decoded = unpack(pack(original))
    _assert_bit_exact(decoded, original)
    assert np.signbit(decoded[4]) and not np.signbit(decoded[5])


def test_integer_extremes_round_trip() -> None:
    for dtype in (np.int8, np.int64, np.uint64):
        info = np.iinfo(dtype)
        original = np.array([info.min, info.max, 0], dtype=dtype)
        _assert_bit_exact(unpack(pack(original)), original)


@pytest.mark.parametrize(
    "make",
    [
        pytest.param(lambda a: a[::2], id="step-2"),
        pytest.param(lambda a: a[::-1], id="reversed"),
        pytest.param(lambda a: a[1:, ::3], id="2d-slice"),
        pytest.param(lambda a: a.T, id="transposed"),
        pytest.param(lambda a: np.asfortranarray(a), id="fortran"),
        pytest.param(lambda a: a[:, 2], id="column"),
        pytest.param(lambda a: np.broadcast_to(a[0], (3, 6)), id="broadcast-zero-stride"),
    ],
)
def test_non_contiguous_arrays_round_trip(make: Any) -> None:
    base = np.arange(36, dtype=np.float32).reshape(6, 6) * 1.5
    original = make(base)
    assert not original.flags.c_contiguous
    decoded = unpack(pack(original))
    assert decoded.shape == original.shape
    assert decoded.dtype == original.dtype
    np.testing.assert_array_equal(decoded, original)


def test_big_endian_array_keeps_byte_order_and_values() -> None:
    original = np.array([1.0, -2.5, 3.25], dtype=">f4")
    decoded = unpack(pack(original))
    assert decoded.dtype.str == ">f4"
    assert decoded.tolist() == [1.0, -2.5, 3.25]
    assert decoded.tobytes() == original.tobytes()


@pytest.mark.parametrize("dtype", ["float32", "int16", ">f8", "bool"])
def test_decoded_array_is_a_read_only_view_of_the_received_bytes(dtype: str) -> None:
    decoded = unpack(pack(_random_array(dtype, (3, 4))))
    assert decoded.flags.owndata is False
    assert isinstance(_root_buffer(decoded), bytes | bytearray | memoryview)
    assert decoded.flags.writeable is False
    with pytest.raises(ValueError, match="read-only"):
        decoded[0, 0] = 0


def test_arrays_nested_in_maps_and_lists_are_decoded() -> None:
    a = np.arange(6, dtype=np.int32).reshape(2, 3)
    b = np.array(2.5, dtype=np.float64)
    decoded = unpack(pack({"obs": {"agent": a}, "list": [b, 1, "x"]}))
    _assert_bit_exact(decoded["obs"]["agent"], a)
    _assert_bit_exact(decoded["list"][0], b)
    assert decoded["list"][1:] == [1, "x"]
    assert decoded["obs"]["agent"].flags.owndata is False


def test_array_travels_as_the_ndarray_ext_type() -> None:
    encoded = msgpack.unpackb(pack(np.zeros(3, np.uint8)))
    assert isinstance(encoded, msgpack.ExtType)
    assert encoded.code == NDARRAY_EXT
    assert encoded.data.endswith(b"\x00\x00\x00")


@pytest.mark.parametrize(
    "array",
    [
        pytest.param(np.array([object(), 1], dtype=object), id="object"),
        pytest.param(np.zeros(2, dtype="f4,i4"), id="structured"),
        pytest.param(np.zeros(2, dtype="V8"), id="void"),
        pytest.param(np.array(["ab", "c"]), id="unicode"),
        pytest.param(np.array([b"ab"]), id="bytes"),
        pytest.param(np.array(["2020-01-01"], dtype="datetime64[D]"), id="datetime"),
        pytest.param(np.array([1], dtype="timedelta64[s]"), id="timedelta"),
    ],
)
def test_arrays_of_unsupported_dtypes_refuse_to_encode(array: np.ndarray) -> None:
    with pytest.raises(TypeError, match="cannot travel on the wire"):
        pack(array)
    with pytest.raises(TypeError, match="cannot travel on the wire"):
        pack({"nested": [1, array]})


def test_array_with_too_many_dimensions_refuses_to_encode() -> None:
    assert unpack(pack(np.zeros((1,) * 32))).shape == (1,) * 32
    with pytest.raises(TypeError, match="more than 32 dimensions"):
        pack(np.zeros((1,) * 33))


def test_failed_pack_leaves_the_packer_clean() -> None:
    expected = pack({"a": [1, 2, 3]})
    with pytest.raises(TypeError):
        pack({"a": [1, 2, np.array([object()])]})
    assert pack({"a": [1, 2, 3]}) == expected


def test_other_python_objects_refuse_to_encode() -> None:
    with pytest.raises(TypeError, match="objects of type object cannot travel"):
        pack({"x": object()})
    with pytest.raises(TypeError):
        pack({1.5j})


@pytest.mark.parametrize(
    ("scalar", "plain"),
    [
        (np.float32(1.5), 1.5),
        (np.float64(-2.25), -2.25),
        (np.float16(0.5), 0.5),
        (np.int8(-3), -3),
        (np.int64(2**40), 2**40),
        (np.uint8(255), 255),
        (np.uint64(2**64 - 1), 2**64 - 1),
        (np.bool_(True), True),
        (np.bool_(False), False),
    ],
)
def test_numpy_scalars_encode_as_plain_values(scalar: np.generic, plain: object) -> None:
    assert pack(scalar) == pack(plain)
    decoded = unpack(pack(scalar))
    assert decoded == plain
    assert type(decoded) is type(plain)
    assert not isinstance(decoded, np.generic | np.ndarray)


def test_plain_values_round_trip() -> None:
    value = {
        "int": -5,
        "float": 0.1,
        "str": "héllo",
        "bytes": b"\x00\xff",
        "none": None,
        "bool": True,
        "list": [1, [2, {"k": 3}]],
    }
    assert unpack(pack(value)) == value


# --- codec: unpack errors --------------------------------------------------------------------


def _ndarray_ext(
    dtype: bytes, shape: tuple[int, ...], payload: bytes, ndim: int | None = None
) -> bytes:
    ndim = len(shape) if ndim is None else ndim
    header = struct.pack("<BB", len(dtype), ndim) + dtype + struct.pack(f"<{len(shape)}Q", *shape)
    return msgpack.packb(msgpack.ExtType(NDARRAY_EXT, header + payload))


def test_ndarray_ext_helper_builds_decodable_arrays() -> None:
    # Guards the malformed-ext tests below: the helper makes valid arrays when asked to.
    decoded = unpack(_ndarray_ext(b"<i2", (2,), struct.pack("<2h", 7, -1)))
    assert decoded.tolist() == [7, -1]
    assert decoded.dtype == np.int16


@pytest.mark.parametrize(
    ("body", "message"),
    [
        pytest.param(b"\xc1", "frame is not valid msgpack", id="reserved-byte"),
        pytest.param(b"", "frame is not valid msgpack", id="empty"),
        pytest.param(b"\x92\x01", "frame is not valid msgpack", id="truncated-array"),
        pytest.param(b"\xa5abc", "frame is not valid msgpack", id="truncated-str"),
        pytest.param(msgpack.packb({"a": 1}) + b"\x00", "trailing bytes", id="trailing-byte"),
        pytest.param(
            msgpack.packb({"a": 1}) + msgpack.packb({"b": 2}), "trailing bytes", id="two-maps"
        ),
        pytest.param(
            msgpack.packb(msgpack.ExtType(5, b"abc")), "unknown msgpack ext type 5", id="ext-5"
        ),
        pytest.param(
            msgpack.packb({"x": msgpack.ExtType(42, b"")}),
            "unknown msgpack ext type 42",
            id="ext-42-nested",
        ),
        pytest.param(msgpack.packb({1: 2}), "frame is not valid msgpack", id="int-map-key"),
        pytest.param(
            _ndarray_ext(b"<f4", (2,), b"\x00" * 7),
            "ndarray of shape (2,) and dtype float32 needs 8 bytes, the frame holds 7",
            id="too-few-bytes",
        ),
        pytest.param(
            _ndarray_ext(b"<f4", (2,), b"\x00" * 9),
            "needs 8 bytes, the frame holds 9",
            id="too-many-bytes",
        ),
        pytest.param(
            _ndarray_ext(b"<f8", (0, 3), b"\x00"),
            "needs 0 bytes, the frame holds 1",
            id="bytes-for-empty",
        ),
        pytest.param(
            _ndarray_ext(b"|O", (1,), b"\x00" * 8),
            "ndarray dtype object is not allowed on the wire",
            id="object-dtype",
        ),
        pytest.param(
            _ndarray_ext(b"O", (1,), b"\x00" * 8),
            "ndarray dtype object is not allowed on the wire",
            id="object-dtype-short",
        ),
        pytest.param(
            _ndarray_ext(b"V8", (1,), b"\x00" * 8),
            "ndarray dtype |V8 is not allowed on the wire",
            id="void-dtype",
        ),
        pytest.param(
            _ndarray_ext(b"f4,i4", (1,), b"\x00" * 8),
            "is not allowed on the wire",
            id="structured-dtype",
        ),
        pytest.param(
            _ndarray_ext(b"<U2", (1,), b"\x00" * 8),
            "is not allowed on the wire",
            id="unicode-dtype",
        ),
        pytest.param(
            _ndarray_ext(b"<M8[ns]", (1,), b"\x00" * 8),
            "is not allowed on the wire",
            id="datetime-dtype",
        ),
        pytest.param(
            _ndarray_ext(b"nonsense", (1,), b"\x00" * 8),
            "malformed ndarray header",
            id="unknown-dtype",
        ),
        pytest.param(
            _ndarray_ext(b"\xff\xfe", (1,), b"\x00" * 8),
            "malformed ndarray header",
            id="non-ascii-dtype",
        ),
        pytest.param(
            _ndarray_ext(b"<f4", (1,) * 33, b"\x00" * 4),
            "33 dimensions",
            id="33-dims",
        ),
        pytest.param(
            _ndarray_ext(b"<f4", (1,) * 255, b"\x00" * 4),
            "255 dimensions",
            id="255-dims",
        ),
        pytest.param(
            _ndarray_ext(b"<f4", (2,), b"", ndim=3),
            "malformed ndarray header",
            id="shape-cut-short",
        ),
        pytest.param(
            msgpack.packb(msgpack.ExtType(NDARRAY_EXT, b"")),
            "malformed ndarray header",
            id="empty-ext",
        ),
        pytest.param(
            msgpack.packb(msgpack.ExtType(NDARRAY_EXT, b"\x03")),
            "malformed ndarray header",
            id="one-byte-ext",
        ),
        pytest.param(
            _ndarray_ext(b"<f4", (0, 2**64 - 1), b""),
            "frame is not valid msgpack",
            id="huge-empty-shape",
        ),
        pytest.param(
            _ndarray_ext(b"<u1", (2**32, 2**32), b"\x00"),
            "needs",
            id="huge-shape",
        ),
    ],
)
def test_unpack_errors_are_remote_protocol_errors(body: bytes, message: str) -> None:
    with pytest.raises(RemoteProtocolError) as info:
        unpack(body)
    assert message in str(info.value)
    assert info.value.code == ErrorCode.BAD_FRAME
    assert info.value.fatal is False


def test_unpack_enforces_max_size() -> None:
    body = pack({"s": "x" * 100})
    assert unpack(body, max_size=100) == {"s": "x" * 100}
    with pytest.raises(RemoteProtocolError, match="not valid msgpack"):
        unpack(body, max_size=99)
    with pytest.raises(RemoteProtocolError, match="not valid msgpack"):
        unpack(pack(list(range(20))), max_size=10)


# --- handshake -------------------------------------------------------------------------------


def test_connections_start_awaiting_hello(pair: ConnectionPair) -> None:
    assert pair.client.state is State.AWAIT_HELLO
    assert pair.server.state is State.AWAIT_HELLO
    assert pair.client.outstanding == () and pair.server.outstanding == ()
    assert pair.client.next_message() is NEED_DATA
    assert pair.server.next_message() is NEED_DATA


def test_hello_reaches_the_client_intact(pair: ConnectionPair) -> None:
    hello = make_hello(
        agents=("left", "right"),
        physics_ticks_per_second=240,
        repeat_action=8,
        render_modes=("rgb_array", "human"),
    )
    received = pair.send(pair.server, hello)
    assert received == [hello]
    (got,) = received
    assert isinstance(got, Hello)
    assert got.environment == "Test-v0"
    assert got.action_space == hello.action_space
    assert got.observation_space == hello.observation_space
    assert got.agents == ("left", "right")
    assert got.physics_ticks_per_second == 240
    assert got.repeat_action == 8
    assert got.render_modes == ("rgb_array", "human")
    assert got.protocol == PROTOCOL_VERSION
    assert pair.server.state is State.READY
    assert pair.client.state is State.READY


@pytest.mark.parametrize(
    "space", [pytest.param(s, id=re.sub(r"\s+", " ", repr(s))[:50]) for s in TESTING_SPACES]
)
def test_hello_carries_every_catalog_space(space: spaces.Space) -> None:
    pair = ConnectionPair()
    hello = make_hello(action_space=space, observation_space=spaces.Dict({"agent": space}))
    (got,) = pair.send(pair.server, hello)
    assert got.action_space == space
    assert got.observation_space["agent"] == space


def test_client_may_not_send_a_request_before_the_hello(pair: ConnectionPair) -> None:
    with pytest.raises(LocalProtocolError, match="hello"):
        pair.client.send(Request(id=1, reset={}))
    assert pair.client.outstanding == ()
    assert pair.client.state is State.AWAIT_HELLO
    pair.handshake()
    assert pair.send(pair.client, Request(id=1, reset={})) == [Request(id=1, reset={})]


def test_server_may_not_send_a_response_before_the_hello(pair: ConnectionPair) -> None:
    with pytest.raises(LocalProtocolError, match="hello before any response"):
        pair.server.send(Response(id=1))
    assert pair.server.state is State.AWAIT_HELLO


def test_hello_is_sent_only_once(ready: ConnectionPair) -> None:
    with pytest.raises(LocalProtocolError, match="once"):
        ready.server.send(make_hello())
    assert ready.server.state is State.READY


def test_client_only_sends_requests(ready: ConnectionPair) -> None:
    for message in (make_hello(), Response(id=1), ErrorReply(1, "x", "y")):
        with pytest.raises(LocalProtocolError, match="a client only sends requests"):
            ready.client.send(message)


def test_server_does_not_send_requests(ready: ConnectionPair) -> None:
    with pytest.raises(LocalProtocolError, match="a server does not send requests"):
        ready.server.send(Request(id=1))


def test_client_refuses_a_first_message_that_is_not_a_hello(pair: ConnectionPair) -> None:
    pair.client.receive_data(frame(Response(id=1).to_wire()))
    with pytest.raises(RemoteProtocolError, match="did not start with a hello") as info:
        pair.client.next_message()
    assert info.value.fatal is True
    assert pair.client.state is State.CLOSED
    assert pair.client.next_message() is CONNECTION_CLOSED


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        pytest.param(lambda h: h.pop("protocol"), "no protocol version", id="no-protocol"),
        pytest.param(lambda h: h.update(protocol=[1]), "no protocol version", id="short-protocol"),
        pytest.param(lambda h: h.update(protocol="1.0"), "no protocol version", id="str-protocol"),
        pytest.param(lambda h: h.pop("environment"), "invalid hello", id="no-environment"),
        pytest.param(lambda h: h.pop("agents"), "invalid hello", id="no-agents"),
        pytest.param(
            lambda h: h.update(action_space={"type": "Nope"}), "invalid hello", id="bad-space"
        ),
        pytest.param(lambda h: h.update(repeat_action="many"), "invalid hello", id="bad-repeat"),
        pytest.param(lambda h: h.update(agents=3), "invalid hello", id="agents-int"),
    ],
)
def test_invalid_hello_is_a_remote_protocol_error(
    pair: ConnectionPair, mutate: Any, message: str
) -> None:
    wire = make_hello().to_wire()
    mutate(wire["hello"])
    pair.client.receive_data(frame(wire))
    with pytest.raises(RemoteProtocolError, match=message):
        pair.client.next_message()
    assert pair.client.state is not State.READY


def test_hello_that_is_not_a_map_is_a_remote_protocol_error(pair: ConnectionPair) -> None:
    pair.client.receive_data(frame({"hello": [1, 0]}))
    with pytest.raises(RemoteProtocolError, match="hello must be a map"):
        pair.client.next_message()


def test_hello_with_malformed_dict_space_is_a_remote_protocol_error(pair: ConnectionPair) -> None:
    wire = make_hello().to_wire()
    wire["hello"]["observation_space"] = {"type": "Dict", "spaces": ["agent"]}
    pair.client.receive_data(frame(wire))
    with pytest.raises(RemoteProtocolError):
        pair.client.next_message()


# --- version ---------------------------------------------------------------------------------


def test_other_major_version_is_refused(pair: ConnectionPair) -> None:
    major, minor = PROTOCOL_VERSION
    other = (major + 1, 3)
    pair.client.receive_data(pair.server.send(make_hello(protocol=other)))
    with pytest.raises(ProtocolVersionError) as info:
        pair.client.next_message()
    text = str(info.value)
    assert f"{major + 1}.3" in text
    assert f"{major}.{minor}" in text
    assert pair.client.state is not State.READY
    with pytest.raises(LocalProtocolError):
        pair.client.send(Request(id=1))


def test_older_major_version_is_refused(pair: ConnectionPair) -> None:
    major, minor = PROTOCOL_VERSION
    pair.client.receive_data(frame(make_hello(protocol=(major - 1, 9)).to_wire()))
    with pytest.raises(ProtocolVersionError, match=re.escape(f"{major - 1}.9")):
        pair.client.next_message()


def test_other_minor_version_is_accepted(pair: ConnectionPair) -> None:
    major, minor = PROTOCOL_VERSION
    (got,) = pair.send(pair.server, make_hello(protocol=(major, minor + 7)))
    assert isinstance(got, Hello)
    assert got.protocol == (major, minor + 7)
    assert pair.client.state is State.READY


# --- error reply instead of a hello ----------------------------------------------------------


def test_error_reply_instead_of_hello_closes_the_client(pair: ConnectionPair) -> None:
    refusal = ErrorReply(None, ErrorCode.BUSY, "another client controls Test-v0", fatal=True)
    received = pair.send(pair.server, refusal)
    assert pair.server.state is State.CLOSED
    assert len(received) == 2 and received[1] is CONNECTION_CLOSED
    assert received[0] == ErrorReply(None, "busy", "another client controls Test-v0", fatal=True)
    assert received[0].code == ErrorCode.BUSY
    assert pair.client.state is State.CLOSED
    assert pair.client.next_message() is CONNECTION_CLOSED
    with pytest.raises(LocalProtocolError, match="closed"):
        pair.client.send(Request(id=1))
    with pytest.raises(LocalProtocolError, match="closed"):
        pair.server.send(make_hello())


def test_non_fatal_error_reply_instead_of_hello_also_closes_the_client(
    pair: ConnectionPair,
) -> None:
    got, closed = pair.send(pair.server, ErrorReply(None, ErrorCode.BUSY, "no"))
    assert isinstance(got, ErrorReply) and got.fatal is False
    assert closed is CONNECTION_CLOSED
    assert pair.client.state is State.CLOSED


# --- request / response pairing --------------------------------------------------------------


def test_request_and_response_round_trip(ready: ConnectionPair) -> None:
    action = np.array([0.25, -0.5], dtype=np.float32)
    request = Request(
        id=7,
        config={"environment": {"repeat_action": 3}},
        reset={"seed": 42},
        action=action,
        observation={"agents": ["agent"]},
        repeat_action=5,
    )
    (got,) = ready.send(ready.client, request)
    assert isinstance(got, Request)
    assert got.id == 7
    assert got.config == {"environment": {"repeat_action": 3}}
    assert got.reset == {"seed": 42}
    _assert_bit_exact(got.action, action)
    assert got.observation == {"agents": ["agent"]}
    assert got.repeat_action == 5
    assert ready.client.outstanding == (7,)
    assert ready.server.outstanding == (7,)

    obs = np.arange(4, dtype=np.float64)
    response = Response(
        id=7,
        observation={"agent": obs},
        reward=1.5,
        terminated=False,
        truncated=True,
        info={"steps": 3},
        frames=5,
    )
    (back,) = ready.send(ready.server, response)
    assert isinstance(back, Response)
    assert back.id == 7
    _assert_bit_exact(back.observation["agent"], obs)
    assert back.reward == 1.5
    assert back.terminated is False and back.truncated is True
    assert back.info == {"steps": 3}
    assert back.frames == 5
    assert ready.client.outstanding == ()
    assert ready.server.outstanding == ()


def test_request_leaves_absent_parts_out() -> None:
    assert Request(id=3).to_wire() == {"id": 3}
    assert Request(id=3, reset={}).to_wire() == {"id": 3, "reset": {}}
    assert Request(id=3, action=0, repeat_action=2).to_wire() == {
        "id": 3,
        "action": 0,
        "repeat_action": 2,
    }


def test_empty_request_is_valid(ready: ConnectionPair) -> None:
    assert ready.send(ready.client, Request(id=0)) == [Request(id=0)]


def test_pipelined_requests_are_tracked_and_answered_in_order(ready: ConnectionPair) -> None:
    client, server = ready.client, ready.server
    data = b"".join(client.send(Request(id=i, action=i)) for i in (1, 2, 3))
    assert client.outstanding == (1, 2, 3)
    server.receive_data(data)
    received = drain(server)
    assert [r.id for r in received] == [1, 2, 3]
    assert [r.action for r in received] == [1, 2, 3]
    assert server.outstanding == (1, 2, 3)

    with pytest.raises(LocalProtocolError, match="out of order"):
        server.send(Response(id=2))
    with pytest.raises(LocalProtocolError, match="out of order"):
        server.send(ErrorReply(3, ErrorCode.INVALID_ACTION, "no"))
    with pytest.raises(LocalProtocolError, match="out of order"):
        server.send(Response(id=99))
    assert server.outstanding == (1, 2, 3)

    replies = server.send(Response(id=1, frames=1))
    assert server.outstanding == (2, 3)
    replies += server.send(ErrorReply(2, ErrorCode.INVALID_ACTION, "bad action"))
    assert server.outstanding == (3,)
    replies += server.send(Response(id=3, frames=3))
    assert server.outstanding == ()
    with pytest.raises(LocalProtocolError, match="out of order"):
        server.send(Response(id=4))

    client.receive_data(replies)
    got = drain(client)
    assert [type(m) for m in got] == [Response, ErrorReply, Response]
    assert [m.id for m in got] == [1, 2, 3]
    assert got[1].code == "invalid_action" and got[1].message == "bad action"
    assert got[1].fatal is False
    assert client.outstanding == ()
    assert client.state is State.READY


def test_client_outstanding_shrinks_as_replies_arrive(ready: ConnectionPair) -> None:
    client, server = ready.client, ready.server
    server.receive_data(client.send(Request(id=10)) + client.send(Request(id=11)))
    drain(server)
    client.receive_data(server.send(Response(id=10)))
    assert drain(client)[0].id == 10
    assert client.outstanding == (11,)
    client.receive_data(server.send(Response(id=11)))
    assert drain(client)[0].id == 11
    assert client.outstanding == ()


@pytest.mark.parametrize(
    "reply",
    [
        pytest.param(Response(id=99).to_wire(), id="response"),
        pytest.param(ErrorReply(99, "invalid_action", "x").to_wire(), id="error-reply"),
    ],
)
def test_client_refuses_a_reply_to_an_unexpected_id(ready: ConnectionPair, reply: dict) -> None:
    ready.client.send(Request(id=1))
    ready.client.receive_data(frame(reply))
    with pytest.raises(RemoteProtocolError, match="reply to request 99, expected 1") as info:
        ready.client.next_message()
    assert info.value.fatal is True
    assert ready.client.state is State.CLOSED
    assert ready.client.next_message() is CONNECTION_CLOSED
    with pytest.raises(LocalProtocolError, match="closed"):
        ready.client.send(Request(id=2))


def test_client_refuses_a_reply_when_nothing_is_outstanding(ready: ConnectionPair) -> None:
    ready.client.receive_data(frame(Response(id=1).to_wire()))
    with pytest.raises(RemoteProtocolError, match="expected none"):
        ready.client.next_message()
    assert ready.client.state is State.CLOSED


def test_client_refuses_replies_out_of_order(ready: ConnectionPair) -> None:
    ready.client.send(Request(id=1))
    ready.client.send(Request(id=2))
    ready.client.receive_data(frame(Response(id=2).to_wire()))
    with pytest.raises(RemoteProtocolError, match="reply to request 2, expected 1"):
        ready.client.next_message()
    assert ready.client.state is State.CLOSED


def test_error_reply_without_id_does_not_consume_a_request(ready: ConnectionPair) -> None:
    ready.send(ready.client, Request(id=1))
    (got,) = ready.send(ready.server, ErrorReply(None, ErrorCode.BAD_FRAME, "garbled"))
    assert got == ErrorReply(None, "bad_frame", "garbled", fatal=False)
    assert ready.client.outstanding == (1,)
    assert ready.server.outstanding == (1,)
    assert ready.client.state is State.READY and ready.server.state is State.READY


def test_fatal_error_reply_to_a_request_closes_both_ends(ready: ConnectionPair) -> None:
    ready.send(ready.client, Request(id=1, action=[1.0, 0.0]))
    got, closed = ready.send(
        ready.server, ErrorReply(1, ErrorCode.ENVIRONMENT_ERROR, "boom", fatal=True)
    )
    assert closed is CONNECTION_CLOSED
    assert got.fatal is True and got.id == 1
    assert ready.server.state is State.CLOSED
    assert ready.client.state is State.CLOSED
    assert ready.client.outstanding == ()


def test_send_that_fails_to_encode_changes_nothing(ready: ConnectionPair) -> None:
    ready.send(ready.client, Request(id=1))
    with pytest.raises(TypeError):
        ready.server.send(Response(id=1, info={"bad": object()}))
    assert ready.server.outstanding == (1,)
    with pytest.raises(TypeError):
        ready.client.send(Request(id=2, action=np.array([object()])))
    assert ready.client.outstanding == (1,)
    (got,) = ready.send(ready.server, Response(id=1))
    assert got.id == 1


def test_send_larger_than_the_frame_limit_is_refused() -> None:
    pair = ConnectionPair(max_frame_size=512)
    pair.handshake()
    pair.send(pair.client, Request(id=1))
    with pytest.raises(LocalProtocolError, match="exceeds the frame limit of 512"):
        pair.server.send(Response(id=1, info={"blob": b"x" * 600}))
    assert pair.server.outstanding == (1,)
    assert pair.server.state is State.READY


# --- request validation on the server --------------------------------------------------------


def _server_error(server: Connection, wire: Any) -> RemoteProtocolError:
    server.receive_data(frame(wire))
    with pytest.raises(RemoteProtocolError) as info:
        server.next_message()
    return info.value


@pytest.mark.parametrize(
    ("wire", "request_id", "message"),
    [
        pytest.param({"id": 4, "bogus": 1}, 4, "unknown request key 'bogus'", id="unknown-key"),
        pytest.param(
            {"id": 4, "step": 1, "act": 2}, 4, "unknown request key 'act'", id="unknown-keys"
        ),
        pytest.param({"reset": {}}, None, "request 'id' must be an integer", id="missing-id"),
        pytest.param({"id": "4"}, None, "request 'id' must be an integer", id="str-id"),
        pytest.param({"id": 4.0}, None, "request 'id' must be an integer", id="float-id"),
        pytest.param({"id": True}, None, "request 'id' must be an integer", id="bool-id"),
        pytest.param({"id": None}, None, "request 'id' must be an integer", id="nil-id"),
        pytest.param({"id": [4]}, None, "request 'id' must be an integer", id="list-id"),
        pytest.param({"id": 4, "config": [1]}, 4, "request 'config' must be a map", id="config"),
        pytest.param({"id": 4, "reset": True}, 4, "request 'reset' must be a map", id="reset"),
        pytest.param({"id": 4, "reset": None}, 4, "request 'reset' must be a map", id="reset-nil"),
        pytest.param(
            {"id": 4, "observation": "all"},
            4,
            "request 'observation' must be a map",
            id="observation",
        ),
        pytest.param(
            {"id": 4, "action": 1, "repeat_action": 0},
            4,
            "'repeat_action' must be an integer >= 1, got 0",
            id="repeat-0",
        ),
        pytest.param(
            {"id": 4, "action": 1, "repeat_action": -3},
            4,
            "'repeat_action' must be an integer >= 1, got -3",
            id="repeat-negative",
        ),
        pytest.param(
            {"id": 4, "action": 1, "repeat_action": 2.0},
            4,
            "'repeat_action' must be an integer >= 1, got 2.0",
            id="repeat-float",
        ),
        pytest.param(
            {"id": 4, "action": 1, "repeat_action": True},
            4,
            "'repeat_action' must be an integer >= 1, got True",
            id="repeat-bool",
        ),
        pytest.param(
            {"id": 4, "action": 1, "repeat_action": "4"},
            4,
            "'repeat_action' must be an integer >= 1",
            id="repeat-str",
        ),
        pytest.param(
            {"id": 4, "repeat_action": 2},
            4,
            "'repeat_action' given without an 'action'",
            id="repeat-without-action",
        ),
    ],
)
def test_invalid_request_is_a_bad_request(
    ready: ConnectionPair, wire: dict, request_id: int | None, message: str
) -> None:
    server = ready.server
    error = _server_error(server, wire)
    assert message in str(error)
    assert error.code == ErrorCode.BAD_REQUEST
    assert error.request_id == request_id
    assert error.fatal is False
    assert server.state is State.READY
    # The error reply answers the bad request; then the connection goes on.
    expected_outstanding = () if request_id is None else (request_id,)
    assert server.outstanding == expected_outstanding
    reply = server.send(ErrorReply(request_id, error.code, str(error)))
    assert server.outstanding == ()
    server.receive_data(frame({"id": 5, "reset": {"seed": 1}}))
    assert drain(server) == [Request(id=5, reset={"seed": 1})]
    assert server.outstanding == (5,)
    assert reply.startswith(struct.pack(">I", len(reply) - 4))


def test_unknown_key_message_lists_the_expected_keys(ready: ConnectionPair) -> None:
    error = _server_error(ready.server, {"id": 1, "step": {}})
    for key in ("config", "reset", "action", "observation", "repeat_action"):
        assert key in str(error)


def test_bad_request_error_reaches_the_client(ready: ConnectionPair) -> None:
    ready.client.send(Request(id=1))  # the client thinks it sent a valid request ...
    error = _server_error(ready.server, {"id": 1, "bogus": 0})  # ... the server got this
    (got,) = ready.send(ready.server, ErrorReply(error.request_id, error.code, str(error)))
    assert got.id == 1
    assert got.code == ErrorCode.BAD_REQUEST
    assert "bogus" in got.message
    assert ready.client.outstanding == ()
    assert ready.client.state is State.READY


def test_repeat_action_with_nil_action_is_a_bad_request(ready: ConnectionPair) -> None:
    error = _server_error(ready.server, {"id": 4, "action": None, "repeat_action": 2})
    assert error.code == ErrorCode.BAD_REQUEST


# --- framing ---------------------------------------------------------------------------------


def _requests() -> list[Request]:
    return [
        Request(id=1, reset={"seed": 0}),
        Request(id=2, action=np.array([0.5, -0.5], dtype=np.float32), repeat_action=2),
        Request(id=3, observation={}),
        Request(id=4, config={"a": {"b": [1, 2, 3]}}),
    ]


def _assert_requests_equal(got: list[Any], expected: list[Request]) -> None:
    assert len(got) == len(expected)
    for g, e in zip(got, expected, strict=True):
        assert isinstance(g, Request)
        assert pack(g.to_wire()) == pack(e.to_wire())


def test_data_fed_byte_by_byte(ready: ConnectionPair) -> None:
    requests = _requests()
    data = b"".join(ready.client.send(r) for r in requests)
    got: list[Any] = []
    for i in range(len(data)):
        ready.server.receive_data(data[i : i + 1])
        got += drain(ready.server)
    _assert_requests_equal(got, requests)
    assert ready.server.next_message() is NEED_DATA
    assert ready.server.outstanding == (1, 2, 3, 4)


def test_hello_and_replies_fed_byte_by_byte_to_the_client() -> None:
    pair = ConnectionPair()
    data = pair.server.send(make_hello())
    got: list[Any] = []
    for i in range(len(data)):
        pair.client.receive_data(data[i : i + 1])
        got += drain(pair.client)
    assert got == [make_hello()]
    pair.server.receive_data(pair.client.send(Request(id=1)) + pair.client.send(Request(id=2)))
    drain(pair.server)
    data = pair.server.send(Response(id=1, reward=2.0)) + pair.server.send(
        ErrorReply(2, ErrorCode.RESET_REQUIRED, "reset first")
    )
    got = []
    for i in range(len(data)):
        pair.client.receive_data(data[i : i + 1])
        got += drain(pair.client)
    assert got == [
        Response(id=1, reward=2.0),
        ErrorReply(2, "reset_required", "reset first"),
    ]
    assert pair.client.outstanding == ()


def test_several_frames_in_one_chunk(ready: ConnectionPair) -> None:
    requests = _requests()
    ready.server.receive_data(b"".join(ready.client.send(r) for r in requests))
    _assert_requests_equal(drain(ready.server), requests)
    assert ready.server.next_message() is NEED_DATA


def test_chunks_that_split_frames_anywhere(ready: ConnectionPair) -> None:
    requests = _requests()
    data = b"".join(ready.client.send(r) for r in requests)
    got: list[Any] = []
    for start in range(0, len(data), 7):
        ready.server.receive_data(data[start : start + 7])
        got += drain(ready.server)
    _assert_requests_equal(got, requests)


def test_need_data_until_the_frame_is_complete(ready: ConnectionPair) -> None:
    data = ready.client.send(Request(id=1, reset={"seed": 5}))
    server = ready.server
    assert server.next_message() is NEED_DATA
    server.receive_data(data[:2])  # half a length prefix
    assert server.next_message() is NEED_DATA
    server.receive_data(data[2:4])  # the whole prefix, no body
    assert server.next_message() is NEED_DATA
    server.receive_data(data[4:-1])  # all but the last byte
    assert server.next_message() is NEED_DATA
    assert server.outstanding == ()
    server.receive_data(data[-1:])
    assert server.next_message() == Request(id=1, reset={"seed": 5})
    assert server.next_message() is NEED_DATA


def test_oversized_length_prefix_is_fatal_before_the_body(ready: ConnectionPair) -> None:
    server, client = ready.server, ready.client
    server.receive_data(b"\xff\xff\xff\xff")
    with pytest.raises(RemoteProtocolError, match="exceeds the limit") as info:
        server.next_message()
    assert info.value.fatal is True
    assert info.value.code == ErrorCode.BAD_FRAME
    assert str(0xFFFFFFFF) in str(info.value)
    # The server may still say why, once, and then the connection is closed.
    data = server.send(ErrorReply(None, info.value.code, str(info.value), fatal=True))
    assert server.state is State.CLOSED
    assert server.next_message() is CONNECTION_CLOSED
    with pytest.raises(LocalProtocolError, match="closed"):
        server.send(ErrorReply(None, ErrorCode.BAD_FRAME, "again", fatal=True))
    client.receive_data(data)
    assert drain(client) == [
        ErrorReply(None, "bad_frame", str(info.value), fatal=True),
        CONNECTION_CLOSED,
    ]
    assert client.state is State.CLOSED


def test_oversized_frame_is_refused_even_with_more_data_buffered(ready: ConnectionPair) -> None:
    server = ready.server
    server.receive_data(struct.pack(">I", DEFAULT_MAX_FRAME_SIZE + 1) + b"x" * 100)
    with pytest.raises(RemoteProtocolError) as info:
        server.next_message()
    assert info.value.fatal is True
    assert server.next_message() is CONNECTION_CLOSED
    server.receive_data(frame({"id": 1}))
    assert server.next_message() is CONNECTION_CLOSED


def test_frame_of_exactly_the_limit_is_accepted() -> None:
    hello = make_hello()
    data = frame(hello.to_wire())
    limit = len(data) - 4
    client = Connection(Role.CLIENT, max_frame_size=limit)
    client.receive_data(data)
    assert client.next_message() == hello

    small = Connection(Role.CLIENT, max_frame_size=limit - 1)
    small.receive_data(data[:4])
    with pytest.raises(RemoteProtocolError, match=f"limit of {limit - 1} bytes") as info:
        small.next_message()
    assert info.value.fatal is True


def test_client_also_refuses_oversized_frames(pair: ConnectionPair) -> None:
    pair.client.receive_data(b"\xff\xff\xff\xff")
    with pytest.raises(RemoteProtocolError, match="exceeds the limit") as info:
        pair.client.next_message()
    assert info.value.fatal is True
    assert pair.client.next_message() is CONNECTION_CLOSED


@pytest.mark.parametrize("cut", [1, 3, 4, 10])
def test_eof_in_the_middle_of_a_frame_is_fatal(ready: ConnectionPair, cut: int) -> None:
    data = ready.client.send(Request(id=1, reset={"seed": 123456}))
    assert len(data) > cut
    ready.server.receive_data(data[:cut])
    assert ready.server.next_message() is NEED_DATA
    ready.server.receive_data(b"")
    with pytest.raises(RemoteProtocolError, match="closed in the middle of a frame") as info:
        ready.server.next_message()
    assert f"{cut} bytes buffered" in str(info.value)
    assert info.value.fatal is True
    assert ready.server.state is State.CLOSED
    assert ready.server.next_message() is CONNECTION_CLOSED


def test_clean_eof_is_connection_closed(ready: ConnectionPair) -> None:
    ready.server.receive_data(b"")
    assert ready.server.next_message() is CONNECTION_CLOSED
    assert ready.server.state is State.CLOSED
    assert ready.server.next_message() is CONNECTION_CLOSED
    ready.client.receive_data(b"")
    assert ready.client.next_message() is CONNECTION_CLOSED
    assert ready.client.state is State.CLOSED


def test_buffered_frames_are_delivered_before_eof(ready: ConnectionPair) -> None:
    requests = _requests()
    ready.server.receive_data(b"".join(ready.client.send(r) for r in requests))
    ready.server.receive_data(b"")
    got = drain(ready.server)
    assert got[-1] is CONNECTION_CLOSED
    _assert_requests_equal(got[:-1], requests)


def test_eof_before_hello_is_connection_closed(pair: ConnectionPair) -> None:
    pair.client.receive_data(b"")
    assert pair.client.next_message() is CONNECTION_CLOSED
    assert pair.client.state is State.CLOSED


@pytest.mark.parametrize(
    ("body", "message"),
    [
        pytest.param(pack([1, 2, 3]), "a frame must hold a map, got list", id="list"),
        pytest.param(pack(7), "a frame must hold a map, got int", id="int"),
        pytest.param(pack("id"), "a frame must hold a map, got str", id="str"),
        pytest.param(pack(None), "a frame must hold a map, got NoneType", id="nil"),
        pytest.param(pack(np.zeros(2)), "a frame must hold a map, got ndarray", id="array"),
        pytest.param(b"\xc1", "not valid msgpack", id="invalid-msgpack"),
        pytest.param(pack({"id": 1}) + b"\x00", "trailing bytes", id="trailing-bytes"),
    ],
)
def test_bad_frame_body_is_an_error_and_the_server_goes_on(
    ready: ConnectionPair, body: bytes, message: str
) -> None:
    server = ready.server
    server.receive_data(raw_frame(body) + frame({"id": 2}))
    with pytest.raises(RemoteProtocolError, match=re.escape(message)) as info:
        server.next_message()
    assert info.value.code == ErrorCode.BAD_FRAME
    assert info.value.fatal is False
    assert info.value.request_id is None
    assert server.outstanding == ()
    server.send(ErrorReply(None, info.value.code, str(info.value)))
    assert server.next_message() == Request(id=2)
    assert server.state is State.READY


def test_non_map_frame_on_the_client_is_an_error(ready: ConnectionPair) -> None:
    ready.client.receive_data(frame([1, 2]))
    with pytest.raises(RemoteProtocolError, match="a frame must hold a map, got list"):
        ready.client.next_message()


def test_length_prefix_is_big_endian(ready: ConnectionPair) -> None:
    data = ready.client.send(Request(id=1))
    body = pack({"id": 1})
    assert data == len(body).to_bytes(4, "big") + body


# --- Response / ErrorReply parsing -----------------------------------------------------------

_RESPONSE = Response(
    id=1, observation={"a": 1}, reward=0.5, terminated=True, truncated=False, info={}, frames=4
).to_wire()


@pytest.mark.parametrize("missing", sorted(_RESPONSE))
def test_response_from_wire_rejects_missing_fields(missing: str) -> None:
    wire = {k: v for k, v in _RESPONSE.items() if k != missing}
    with pytest.raises(RemoteProtocolError, match=f"invalid response: KeyError\\('{missing}'\\)"):
        Response.from_wire(wire)


@pytest.mark.parametrize(
    "change",
    [{"reward": "lots"}, {"reward": None}, {"frames": "four"}, {"frames": None}],
    ids=["reward-str", "reward-nil", "frames-str", "frames-nil"],
)
def test_response_from_wire_rejects_wrong_types(change: dict) -> None:
    with pytest.raises(RemoteProtocolError, match="invalid response"):
        Response.from_wire({**_RESPONSE, **change})


def test_response_from_wire_reads_all_fields() -> None:
    got = Response.from_wire(_RESPONSE)
    assert got == Response(
        id=1, observation={"a": 1}, reward=0.5, terminated=True, truncated=False, info={}, frames=4
    )
    assert type(got.reward) is float and type(got.frames) is int


@pytest.mark.parametrize(
    "wire",
    [
        pytest.param({"id": 1}, id="no-error"),
        pytest.param({"id": 1, "error": {"message": "m"}}, id="no-code"),
        pytest.param({"id": 1, "error": {"code": "c"}}, id="no-message"),
        pytest.param({"id": 1, "error": "boom"}, id="error-str"),
        pytest.param({"id": 1, "error": ["c", "m"]}, id="error-list"),
        pytest.param({"id": 1, "error": None}, id="error-nil"),
    ],
)
def test_error_reply_from_wire_rejects_missing_fields(wire: dict) -> None:
    with pytest.raises(RemoteProtocolError, match="invalid error reply"):
        ErrorReply.from_wire(wire)


def test_error_reply_from_wire_defaults() -> None:
    got = ErrorReply.from_wire({"error": {"code": "busy", "message": "m"}})
    assert got == ErrorReply(id=None, code="busy", message="m", fatal=False)


def test_malformed_reply_on_the_client_is_a_remote_protocol_error(ready: ConnectionPair) -> None:
    ready.client.send(Request(id=1))
    ready.client.receive_data(frame({"id": 1, "error": {"code": "x"}}))
    with pytest.raises(RemoteProtocolError, match="invalid error reply"):
        ready.client.next_message()
    ready.client.receive_data(frame({"id": 1, "reward": 1.0}))
    with pytest.raises(RemoteProtocolError, match="invalid response"):
        ready.client.next_message()
    assert ready.client.outstanding == (1,)


def test_a_request_shows_its_parts_but_never_its_token() -> None:
    text = repr(Request(id=3, inspect={"tree": {}}, token="s3cret"))
    assert "inspect={'tree': {}}" in text and "token=..." in text
    assert "s3cret" not in text


# --- steps: a vector step in columns ----------------------------------------------------------


def test_steps_and_their_columns_round_trip(ready: ConnectionPair) -> None:
    actions = np.array([[0.5], [-1.0], [0.0]], dtype=np.float32)
    reset = np.array([False, True, False])
    (got,) = ready.send(ready.client, Request(id=9, steps=Steps(actions, reset, 2)))
    assert isinstance(got, Request) and got.steps is not None
    _assert_bit_exact(got.steps.action, actions)
    assert got.steps.reset.tolist() == [False, True, False] and got.steps.repeat_action == 2
    answer = StepsResponse(
        id=9, observation=np.arange(15, dtype=np.float32).reshape(3, 5),
        reward=np.array([1.0, 0.0, 2.0]), terminated=np.array([False, False, True]),
        truncated=np.zeros(3, np.bool_), frames=np.array([2, 0, 1]),
        info=({}, {"seed": 1}, {}),
        errors=(None, ErrorReply(9, "environment_error", "boom"), None),
    )
    (back,) = ready.send(ready.server, answer)
    assert isinstance(back, StepsResponse) and back.id == 9
    _assert_bit_exact(back.observation, answer.observation)
    assert back.reward.tolist() == [1.0, 0.0, 2.0] and back.frames.tolist() == [2, 0, 1]
    assert back.terminated.tolist() == [False, False, True] and not back.truncated.any()
    assert back.info == ({}, {"seed": 1}, {})
    assert back.errors == (None, ErrorReply(9, "environment_error", "boom"), None)
    assert ready.client.outstanding == ()


def test_a_reset_mask_may_be_a_list_of_booleans(ready: ConnectionPair) -> None:
    ready.server.receive_data(frame({"id": 1, "steps": {"action": [0, 1], "reset": [True, False]}}))
    (got,) = drain(ready.server)
    assert got.steps.reset.dtype == np.bool_ and got.steps.reset.tolist() == [True, False]


@pytest.mark.parametrize(
    ("steps", "message"),
    [
        pytest.param([1, 2], "'steps' must be a map", id="not-a-map"),
        pytest.param({"reset": [True]}, "'steps' needs an 'action'", id="no-action"),
        pytest.param({"action": [1], "jump": 1}, "unknown key 'jump' in steps", id="unknown"),
        pytest.param({"action": [1], "reset": [1]}, "steps.reset must be a list of booleans",
                     id="reset-ints"),
        pytest.param({"action": [1], "reset": "yes"}, "steps.reset must be a list of booleans",
                     id="reset-str"),
        pytest.param({"action": [1], "repeat_action": 0}, "steps.repeat_action must be an "
                     "integer >= 1", id="repeat-zero"),
    ],
)
def test_invalid_steps_are_bad_requests(ready: ConnectionPair, steps: Any, message: str) -> None:
    error = _server_error(ready.server, {"id": 3, "steps": steps})
    assert message in str(error) and error.code == ErrorCode.BAD_REQUEST
    assert error.request_id == 3 and not error.fatal


def test_steps_go_alone(ready: ConnectionPair) -> None:
    error = _server_error(ready.server, {"id": 3, "steps": {"action": [1]}, "reset": {}})
    assert "a 'steps' request carries nothing else but its id" in str(error)


_COLUMNS = {"observation": [[0.0], [1.0]], "reward": [1.0, 2.0], "terminated": [False, True],
            "truncated": [False, False], "frames": [4, 2], "info": [{}, {}]}


@pytest.mark.parametrize(
    "change",
    [{"reward": None}, {"frames": [4]}, {"info": [{}]}, {"info": [{}, 3]},
     {"errors": [None]}, {"errors": [None, {"code": "x"}]}, {"terminated": "no"}],
    ids=["reward-nil", "frames-short", "info-short", "info-not-map", "errors-short",
         "error-no-message", "flags-str"],
)
def test_malformed_steps_responses_are_remote_protocol_errors(change: dict) -> None:
    with pytest.raises(RemoteProtocolError, match="invalid steps response"):
        StepsResponse.from_wire({"id": 1, "steps": {**_COLUMNS, **change}})
