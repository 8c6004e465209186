"""Tests of the sans-IO wire protocol (the ``rlenv.protocol`` package), without sockets.

Two :class:`Connection` objects talk by handing each other bytes, like h11's ConnectionPair.
What a request's parts mean is the server's business: see ``test_parts.py``.
"""

from __future__ import annotations

import itertools
import re
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.vector.utils import batch_space
from spaces_catalog import TESTING_SPACES

import rlenv.protocol
from rlenv.protocol import (
    CONNECTION_CLOSED,
    DEFAULT_MAX_FRAME_SIZE,
    NDARRAY_EXT,
    NEED_DATA,
    PROTOCOL_VERSION,
    BatchResponse,
    Connection,
    ErrorReply,
    Hello,
    Request,
    Response,
    Role,
    State,
    StepsResponse,
    frame,
    pack,
    unpack,
)
from rlenv.protocol.codec import MAX_FRAME_OBJECTS
from rlenv.protocol.connection import TRANSITIONS, Event
from rlenv.protocol.errors import (
    ErrorCode,
    LocalProtocolError,
    ProtocolVersionError,
    RemoteProtocolError,
)
from rlenv.protocol.spaces import codec_for
from rlenv.testing import connection_pair
from rlenv.testing import frame as raw_frame

# --- helpers ---------------------------------------------------------------------------------


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


@dataclass
class Pair:
    """A client and a server Connection wired back to back."""

    client: Connection
    server: Connection

    def other(self, conn: Connection) -> Connection:
        return self.server if conn is self.client else self.client

    def send(self, sender: Connection, message: Any) -> list[Any]:
        """Send ``message`` from ``sender``; return what the peer receives."""
        receiver = self.other(sender)
        receiver.receive_data(sender.send(message))
        return drain(receiver)

    def handshake(self, hello: Hello | None = None) -> Hello:
        (received,) = self.send(self.server, hello or make_hello())
        return received


def new_pair(max_frame_size: int = DEFAULT_MAX_FRAME_SIZE) -> Pair:
    """A pair before the handshake."""
    return Pair(Connection(Role.CLIENT, max_frame_size), Connection(Role.SERVER, max_frame_size))


@pytest.fixture
def pair() -> Pair:
    return new_pair()


@pytest.fixture
def ready() -> Pair:
    """A pair after the handshake (``rlenv.testing.connection_pair``)."""
    return Pair(*connection_pair(make_hello()))


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


# --- the package -----------------------------------------------------------------------------


def test_the_package_exports_its_public_names() -> None:
    for name in rlenv.protocol.__all__:
        assert getattr(rlenv.protocol, name) is not None
    assert PROTOCOL_VERSION[0] == 2  # this package is the 2.x protocol
    assert NDARRAY_EXT == 1
    assert rlenv.protocol.Connection is Connection


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
def test_non_contiguous_arrays_round_trip(make: Callable[[np.ndarray], np.ndarray]) -> None:
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


def test_ndarray_ext_layout() -> None:
    """Ext type 1: dtype length and ndim (``<BB``), dtype.str, shape (``<Q`` each), C data."""
    original = np.arange(6, dtype=">i2").reshape(2, 3).T  # big-endian, not C-contiguous
    encoded = msgpack.unpackb(pack(original))
    assert encoded.code == 1
    expected = (
        struct.pack("<BB", 3, 2)
        + b">i2"
        + struct.pack("<2Q", 3, 2)
        + np.ascontiguousarray(original).tobytes()
    )
    assert encoded.data == expected
    scalar = msgpack.unpackb(pack(np.array(7, np.uint8)))
    assert scalar.data == struct.pack("<BB", 3, 0) + b"|u1" + b"\x07"


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


@pytest.mark.skipif(
    np.lib.NumpyVersion(np.__version__) < "2.0.0",
    reason="numpy 1 makes no array of more than 32 dimensions",
)
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


def test_frame_is_a_big_endian_length_then_the_msgpack_body() -> None:
    value = {"id": 1, "action": np.arange(3, dtype=np.float32)}
    body = pack(value)
    assert frame(value) == len(body).to_bytes(4, "big") + body
    assert frame(value) == raw_frame(body)
    with pytest.raises(TypeError, match="cannot travel on the wire"):
        frame({"x": object()})


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
        pytest.param(
            b"\xc1",
            "frame is not valid msgpack: a byte that begins no msgpack "
            "value (such as 0xc1, never used)",
            id="reserved-byte",
        ),
        pytest.param(
            b"\x91" * 5000 + b"\x00",
            "frame is not valid msgpack: containers nested deeper than the decoder allows",
            id="too-deep",
        ),
        pytest.param(b"", "frame is not valid msgpack", id="empty"),
        pytest.param(b"\x92\x01", "frame is not valid msgpack", id="truncated-array"),
        pytest.param(b"\xa5abc", "frame is not valid msgpack", id="truncated-str"),
        pytest.param(msgpack.packb({"a": 1}) + b"\x00", "trailing bytes", id="trailing-byte"),
        pytest.param(
            msgpack.packb({"a": 1}) + msgpack.packb({"b": 2}), "trailing bytes", id="two-maps"
        ),
        pytest.param(
            msgpack.packb(msgpack.ExtType(5, b"abc")),
            "ext type 5 is not allowed: the only ext type is 1",
            id="ext-5",
        ),
        pytest.param(
            msgpack.packb({"reset": {"options": {"at": msgpack.Timestamp(1)}}}),
            "ext type -1 (msgpack's timestamp) is not allowed",
            id="timestamp-32",
        ),
        pytest.param(
            b"\x91\xd7\xff" + bytes(8),
            "ext type -1 (msgpack's timestamp) is not allowed",
            id="timestamp-64",
        ),
        pytest.param(
            b"\x91\xc7\x0c\xff" + bytes(12),
            "ext type -1 (msgpack's timestamp) is not allowed",
            id="timestamp-96",
        ),
        pytest.param(
            b"\x91\xd4\xff\x00",  # msgpack says what is wrong from 1.2.2 on
            "invalid timestamp data"
            if msgpack.version >= (1, 2, 2)
            else "frame is not valid msgpack",
            id="timestamp-invalid",
        ),
        pytest.param(
            msgpack.packb({"x": msgpack.ExtType(42, b"")}),
            "ext type 42 is not allowed: the only ext type is 1",
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
            _ndarray_ext(b"float32", (2,), b"\x00" * 8),
            "ndarray dtype 'float32' is not written as numpy's dtype.str ('<f4')",
            id="dtype-name",
        ),
        pytest.param(
            _ndarray_ext(b"<f16", (1,), b"\x00" * 16),
            "ndarray dtype float128 is not allowed on the wire",
            id="long-double",
        ),
        pytest.param(
            _ndarray_ext(b"<u1", (2,), b"\x00" * 2),
            "ndarray dtype '<u1' is not written as numpy's dtype.str ('|u1')",
            id="dtype-byte-order-of-a-byte",
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
            _ndarray_ext(b"(2,)<f4", (1,), b"\x00" * 8),
            "is not allowed on the wire",
            id="subarray-dtype",
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
            _ndarray_ext(b"|u1", (2**32, 2**32), b"\x00"),
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


@pytest.mark.parametrize(
    "body",
    [
        pytest.param(b"\xdd\xff\xff\xff\xff", id="array32"),
        pytest.param(b"\xdf\xff\xff\xff\xff", id="map32"),
        pytest.param(b"\xdb\xff\xff\xff\xff", id="str32"),
        pytest.param(b"\xc6\xff\xff\xff\xff", id="bin32"),
        pytest.param(b"\xc9\xff\xff\xff\xff\x01", id="ext32"),
        pytest.param(b"\x81\xa1a\xdd\x00\x01\x00\x00" + b"\xc0" * 100, id="nested-array"),
    ],
)
def test_containers_may_not_claim_more_than_the_body_holds(body: bytes) -> None:
    """A few bytes cannot make the decoder allocate gigabytes."""
    with pytest.raises(RemoteProtocolError, match="not valid msgpack") as info:
        unpack(body)
    assert info.value.code == ErrorCode.BAD_FRAME and info.value.fatal is False


def test_unpack_accepts_a_memoryview() -> None:
    body = pack({"a": np.arange(3, dtype=np.int8)})
    decoded = unpack(memoryview(body))
    assert decoded["a"].tolist() == [0, 1, 2]


# --- handshake -------------------------------------------------------------------------------


def test_connections_start_awaiting_hello(pair: Pair) -> None:
    assert pair.client.state is State.AWAIT_HELLO
    assert pair.server.state is State.AWAIT_HELLO
    assert pair.client.outstanding == () and pair.server.outstanding == ()
    assert pair.client.next_message() is NEED_DATA
    assert pair.server.next_message() is NEED_DATA
    assert pair.client.buffered == 0 and not pair.client.peer_closed


def test_connection_pair_is_ready_after_the_handshake() -> None:
    client, server = connection_pair(make_hello())
    assert client.state is State.READY and server.state is State.READY
    assert client.role is Role.CLIENT and server.role is Role.SERVER
    assert client.outstanding == () and server.outstanding == ()


def test_hello_reaches_the_client_intact(pair: Pair) -> None:
    hello = make_hello(
        agents=("left", "right"),
        physics_ticks_per_second=240,
        repeat_action=8,
        render_modes=("rgb_array", "human"),
        token_required=True,
        instances=3,
        target="examples.pair:PairEnvironment",
        driven=("right",),
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
    assert got.token_required is True
    assert got.instances == 3
    assert got.target == "examples.pair:PairEnvironment"
    assert got.driven == ("right",)
    assert got.protocol == PROTOCOL_VERSION
    assert pair.server.state is State.READY
    assert pair.client.state is State.READY


def test_hello_without_token_required_or_instances_takes_the_defaults(pair: Pair) -> None:
    wire = make_hello().to_wire()
    del wire["hello"]["token_required"], wire["hello"]["instances"], wire["hello"]["target"]
    del wire["hello"]["driven"]
    pair.client.receive_data(frame(wire))
    (got,) = drain(pair.client)
    assert got.token_required is False and got.instances == 1 and got.target is None
    assert got.driven == ()


@pytest.mark.parametrize(
    "space", [pytest.param(s, id=re.sub(r"\s+", " ", repr(s))[:50]) for s in TESTING_SPACES]
)
def test_hello_carries_every_catalog_space(space: spaces.Space) -> None:
    pair = new_pair()
    hello = make_hello(action_space=space, observation_space=spaces.Dict({"agent": space}))
    (got,) = pair.send(pair.server, hello)
    assert got.action_space == space
    assert got.observation_space["agent"] == space


def test_client_may_not_send_a_request_before_the_hello(pair: Pair) -> None:
    with pytest.raises(LocalProtocolError):
        pair.client.send(Request(1, {"reset": {}}))
    assert pair.client.outstanding == ()
    assert pair.client.state is State.AWAIT_HELLO
    pair.handshake()
    assert pair.send(pair.client, Request(1, {"reset": {}})) == [Request(1, {"reset": {}})]


def test_server_may_not_send_a_response_before_the_hello(pair: Pair) -> None:
    with pytest.raises(LocalProtocolError):
        pair.server.send(Response(id=1))
    assert pair.server.state is State.AWAIT_HELLO


def test_hello_is_sent_only_once(ready: Pair) -> None:
    with pytest.raises(LocalProtocolError):
        ready.server.send(make_hello())
    assert ready.server.state is State.READY


@pytest.mark.parametrize(
    "message",
    [
        pytest.param(make_hello(), id="hello"),
        pytest.param(Response(id=1), id="response"),
        pytest.param(ErrorReply(1, "x", "y"), id="error"),
        pytest.param(ErrorReply(None, "x", "y", fatal=True), id="fatal-error"),
        pytest.param(BatchResponse(1, (None,)), id="batch"),
    ],
)
def test_client_only_sends_requests(ready: Pair, message: Any) -> None:
    ready.client.send(Request(1))
    with pytest.raises(LocalProtocolError):
        ready.client.send(message)
    assert ready.client.state is State.READY and ready.client.outstanding == (1,)


def test_server_does_not_send_requests(ready: Pair) -> None:
    with pytest.raises(LocalProtocolError):
        ready.server.send(Request(id=1))
    assert ready.server.outstanding == ()


def test_something_that_is_not_a_message_is_refused(ready: Pair) -> None:
    for conn in (ready.client, ready.server):
        with pytest.raises(LocalProtocolError, match="not a message"):
            conn.send({"id": 1})  # type: ignore[arg-type]
        assert conn.state is State.READY


def test_client_refuses_a_first_message_that_is_not_a_hello(pair: Pair) -> None:
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
        pytest.param(lambda h: h.update(protocol=[2, "x"]), "invalid hello", id="str-minor"),
        pytest.param(lambda h: h.pop("environment"), "invalid hello", id="no-environment"),
        pytest.param(lambda h: h.pop("agents"), "invalid hello", id="no-agents"),
        pytest.param(
            lambda h: h.update(action_space={"type": "Nope"}), "invalid hello", id="bad-space"
        ),
        pytest.param(lambda h: h.update(repeat_action="many"), "invalid hello", id="bad-repeat"),
        pytest.param(lambda h: h.update(agents=3), "invalid hello", id="agents-int"),
        pytest.param(lambda h: h.update(instances="two"), "invalid hello", id="instances-str"),
        pytest.param(lambda h: h.update(target=3), "invalid hello", id="target-int"),
        pytest.param(lambda h: h.update(driven="agent"), "invalid hello", id="driven-str"),
        pytest.param(
            lambda h: h.update(driven=["other"]),
            "driven must list some of the agents",
            id="driven-unknown",
        ),
    ],
)
def test_invalid_hello_is_a_remote_protocol_error(
    pair: Pair, mutate: Callable[[dict[str, Any]], Any], message: str
) -> None:
    wire = make_hello().to_wire()
    mutate(wire["hello"])
    pair.client.receive_data(frame(wire))
    with pytest.raises(RemoteProtocolError, match=message):
        pair.client.next_message()
    assert pair.client.state is not State.READY


def test_hello_that_is_not_a_map_is_a_remote_protocol_error(pair: Pair) -> None:
    pair.client.receive_data(frame({"hello": [1, 0]}))
    with pytest.raises(RemoteProtocolError, match="hello must be a map"):
        pair.client.next_message()


def test_hello_with_malformed_dict_space_is_a_remote_protocol_error(pair: Pair) -> None:
    wire = make_hello().to_wire()
    wire["hello"]["observation_space"] = {"type": "Dict", "spaces": ["agent"]}
    pair.client.receive_data(frame(wire))
    with pytest.raises(RemoteProtocolError):
        pair.client.next_message()


# --- version ---------------------------------------------------------------------------------


def test_other_major_version_is_refused(pair: Pair) -> None:
    major, minor = PROTOCOL_VERSION
    pair.client.receive_data(pair.server.send(make_hello(protocol=(major + 1, 3))))
    with pytest.raises(ProtocolVersionError) as info:
        pair.client.next_message()
    text = str(info.value)
    assert f"{major + 1}.3" in text
    assert f"{major}.{minor}" in text
    assert pair.client.state is not State.READY
    with pytest.raises(LocalProtocolError):
        pair.client.send(Request(id=1))


def test_older_major_version_is_refused(pair: Pair) -> None:
    """A 1.x server (the single-module protocol) is refused, naming both versions."""
    major, minor = PROTOCOL_VERSION
    pair.client.receive_data(frame(make_hello(protocol=(major - 1, 9)).to_wire()))
    with pytest.raises(ProtocolVersionError, match=re.escape(f"{major - 1}.9")) as info:
        pair.client.next_message()
    assert f"{major}.{minor}" in str(info.value)


def test_other_minor_version_is_accepted(pair: Pair) -> None:
    major, minor = PROTOCOL_VERSION
    (got,) = pair.send(pair.server, make_hello(protocol=(major, minor + 7)))
    assert isinstance(got, Hello)
    assert got.protocol == (major, minor + 7)
    assert pair.client.state is State.READY


# --- error reply instead of a hello ----------------------------------------------------------


def test_error_reply_instead_of_hello_closes_both_ends(pair: Pair) -> None:
    refusal = ErrorReply(None, ErrorCode.BUSY, "another client controls Test-v0", fatal=True)
    received = pair.send(pair.server, refusal)
    assert pair.server.state is State.CLOSED
    assert len(received) == 2 and received[1] is CONNECTION_CLOSED
    assert received[0] == ErrorReply(None, "busy", "another client controls Test-v0", fatal=True)
    assert received[0].code == ErrorCode.BUSY
    assert pair.client.state is State.CLOSED
    assert pair.client.next_message() is CONNECTION_CLOSED
    with pytest.raises(LocalProtocolError):
        pair.client.send(Request(id=1))
    with pytest.raises(LocalProtocolError):
        pair.server.send(make_hello())


def test_server_may_refuse_a_connection_only_with_a_fatal_error(pair: Pair) -> None:
    with pytest.raises(LocalProtocolError):
        pair.server.send(ErrorReply(None, ErrorCode.BUSY, "no"))
    assert pair.server.state is State.AWAIT_HELLO


def test_client_closes_on_a_non_fatal_error_instead_of_the_hello(pair: Pair) -> None:
    """Tolerated on receipt (another server implementation), though a Connection never sends it."""
    pair.client.receive_data(frame(ErrorReply(None, ErrorCode.BUSY, "no").to_wire()))
    got, closed = drain(pair.client)
    assert isinstance(got, ErrorReply) and got.fatal is False
    assert closed is CONNECTION_CLOSED
    assert pair.client.state is State.CLOSED


# --- the transition table --------------------------------------------------------------------

_SEND_EVENTS = (Event.SEND_HELLO, Event.SEND_REQUEST, Event.SEND_REPLY, Event.SEND_FATAL_ERROR)
_RECEIVE_EVENTS = (
    Event.RECEIVE_HELLO,
    Event.RECEIVE_REQUEST,
    Event.RECEIVE_REPLY,
    Event.RECEIVE_FATAL_ERROR,
)
_RECEIVED: dict[Event, Event] = {
    Event.SEND_HELLO: Event.RECEIVE_HELLO,
    Event.SEND_REQUEST: Event.RECEIVE_REQUEST,
    Event.SEND_REPLY: Event.RECEIVE_REPLY,
    Event.SEND_FATAL_ERROR: Event.RECEIVE_FATAL_ERROR,
}


def _connection_in(role: Role, state: State) -> Connection:
    """A connection of ``role`` in ``state``; when READY, request 1 is outstanding."""
    if state is State.AWAIT_HELLO:
        return Connection(role)
    client, server = connection_pair(make_hello())
    server.receive_data(client.send(Request(1)))
    assert server.next_message() == Request(1)
    conn = client if role is Role.CLIENT else server
    if state is State.CLOSED:
        conn.receive_data(b"")
        assert conn.next_message() is CONNECTION_CLOSED
    elif state is State.BROKEN:
        conn.receive_data(b"\xff\xff\xff\xff")
        with pytest.raises(RemoteProtocolError, match="exceeds the limit"):
            conn.next_message()
    assert conn.state is state
    return conn


def _message_for(event: Event) -> Any:
    """A message whose sending is ``event`` (valid in any state where the table allows it)."""
    return {
        Event.SEND_HELLO: make_hello(),
        Event.SEND_REQUEST: Request(2, {"reset": {}}),
        Event.SEND_REPLY: Response(1, frames=4),
        Event.SEND_FATAL_ERROR: ErrorReply(None, ErrorCode.TIMEOUT, "too slow", fatal=True),
    }[event]


def _wire_for(event: Event, state: State) -> dict[str, Any]:
    """A frame's map whose receipt is ``event`` in ``state``."""
    if event is Event.RECEIVE_REPLY and state is State.AWAIT_HELLO:
        return ErrorReply(None, ErrorCode.BUSY, "no").to_wire()  # the only reply before a hello
    sent = next(send for send, received in _RECEIVED.items() if received is event)
    return _message_for(sent).to_wire()


# A client whose framing breaks closes at once: only a server is ever BROKEN.
_ALL = [
    (role, state, event)
    for role, state, event in itertools.product(Role, State, Event)
    if not (role is Role.CLIENT and state is State.BROKEN)
]


@pytest.mark.parametrize(
    ("role", "state", "event"),
    [key for key in _ALL if key[2] in _SEND_EVENTS],
    ids=lambda v: v.name,
)
def test_sending_follows_the_table(role: Role, state: State, event: Event) -> None:
    conn = _connection_in(role, state)
    outstanding = conn.outstanding
    after = TRANSITIONS.get((role, state, event))
    if after is None:
        with pytest.raises(LocalProtocolError):
            conn.send(_message_for(event))
        assert conn.state is state and conn.outstanding == outstanding
    else:
        assert conn.send(_message_for(event))
        assert conn.state is after


# The server reads every frame as a request: a reply-shaped frame is a request with odd parts
# (see test_server_reads_a_reply_shaped_frame_as_a_request).
_UNCLASSIFIED = {
    (Role.SERVER, State.READY, Event.RECEIVE_REPLY),
    (Role.SERVER, State.READY, Event.RECEIVE_FATAL_ERROR),
}


@pytest.mark.parametrize(
    ("role", "state", "event"),
    [key for key in _ALL if key[2] in _RECEIVE_EVENTS and key not in _UNCLASSIFIED],
    ids=lambda v: v.name,
)
def test_receiving_follows_the_table(role: Role, state: State, event: Event) -> None:
    conn = _connection_in(role, state)
    after = TRANSITIONS.get((role, state, event))
    conn.receive_data(frame(_wire_for(event, state)))
    if state in (State.CLOSED, State.BROKEN):
        assert after is None
        assert conn.next_message() is CONNECTION_CLOSED  # nothing more is read
    elif after is None:
        with pytest.raises(RemoteProtocolError):
            conn.next_message()
        assert conn.state in (state, State.CLOSED)  # unchanged, or closed when fatal
    else:
        got = conn.next_message()
        assert got is not NEED_DATA and got is not CONNECTION_CLOSED
        assert conn.state is after


@pytest.mark.parametrize(("role", "state"), sorted({key[:2] for key in _ALL}), ids=lambda v: v.name)
def test_end_of_stream_closes_in_any_state(role: Role, state: State) -> None:
    assert TRANSITIONS[(role, state, Event.END)] is State.CLOSED
    conn = _connection_in(role, state)
    conn.receive_data(b"")
    assert conn.peer_closed
    assert conn.next_message() is CONNECTION_CLOSED
    assert conn.state is State.CLOSED


def test_server_reads_a_reply_shaped_frame_as_a_request(ready: Pair) -> None:
    """The protocol leaves parts to the server, so it cannot tell such a frame from a request."""
    ready.server.receive_data(frame(Response(1).to_wire()))
    ready.server.receive_data(frame(ErrorReply(2, "x", "y", fatal=True).to_wire()))
    first, second = drain(ready.server)
    assert isinstance(first, Request) and "reward" in first.parts
    assert isinstance(second, Request) and "error" in second.parts
    assert ready.server.outstanding == (1, 2) and ready.server.state is State.READY


def test_what_one_side_may_send_the_other_may_receive() -> None:
    """Every send in the table has its receipt on the other side, leading to the same state."""
    for (role, state, event), after in TRANSITIONS.items():
        if event in _SEND_EVENTS:
            peer = Role.SERVER if role is Role.CLIENT else Role.CLIENT
            seen = State.READY if state is State.BROKEN else state  # the peer saw no break
            assert TRANSITIONS.get((peer, seen, _RECEIVED[event])) is after, (role, state, event)


class _Recorder:
    """Moves messages between a pair, checking every transition against the table."""

    def __init__(self) -> None:
        self.seen: set[tuple[Role, State, Event]] = set()

    def saw(self, conn: Connection, before: State, event: Event) -> None:
        assert TRANSITIONS[(conn.role, before, event)] is conn.state, (conn.role, before, event)
        self.seen.add((conn.role, before, event))

    def send(self, sender: Connection, receiver: Connection, message: Any) -> Any:
        sent = (
            Event.SEND_FATAL_ERROR
            if isinstance(message, ErrorReply) and message.fatal
            else {Hello: Event.SEND_HELLO, Request: Event.SEND_REQUEST}.get(
                type(message), Event.SEND_REPLY
            )
        )
        before, receiver_before = sender.state, receiver.state
        data = sender.send(message)
        self.saw(sender, before, sent)
        receiver.receive_data(data)
        got = receiver.next_message()
        assert type(got) is type(message)
        self.saw(receiver, receiver_before, _RECEIVED[sent])
        return got

    def saw_sent(self, conn: Connection, message: Any) -> None:
        before = conn.state
        conn.send(message)
        self.saw(conn, before, Event.SEND_FATAL_ERROR)

    def broken(self, conn: Connection) -> None:
        before = conn.state
        conn.receive_data(b"\xff\xff\xff\xff")
        with pytest.raises(RemoteProtocolError, match="exceeds the limit"):
            conn.next_message()
        self.saw(conn, before, Event.BREAK)

    def end(self, *conns: Connection) -> None:
        for conn in conns:
            before = conn.state
            conn.receive_data(b"")
            assert conn.next_message() is CONNECTION_CLOSED
            self.saw(conn, before, Event.END)


def test_the_table_is_exhaustive_over_what_a_well_behaved_pair_does() -> None:
    """Every transition of well-behaved conversations is in the table, and every entry is used.

    Except one: a client tolerates a non-fatal error instead of the hello, which a
    :class:`Connection` never sends (tested on its own above).
    """
    record = _Recorder()
    # A conversation: hello, pipelined requests, every kind of reply, a fatal error, the end.
    client, server = Connection(Role.CLIENT), Connection(Role.SERVER)
    record.send(server, client, make_hello())
    for request_id in range(1, 6):
        record.send(client, server, Request(request_id, {"observation": {}}))
    record.send(server, client, Response(1))
    record.send(server, client, ErrorReply(2, ErrorCode.INVALID_ACTION, "no"))
    record.send(server, client, BatchResponse(3, (Response(3), None)))
    steps = StepsResponse(
        4,
        b"",
        np.zeros(1),
        np.zeros(1, np.bool_),
        np.zeros(1, np.bool_),
        np.zeros(1, np.int64),
        ({},),
    )
    record.send(server, client, steps)
    record.send(server, client, ErrorReply(5, ErrorCode.ENVIRONMENT_ERROR, "boom", fatal=True))
    record.end(client, server)
    # A server that refuses the connection.
    client, server = Connection(Role.CLIENT), Connection(Role.SERVER)
    record.send(server, client, ErrorReply(None, ErrorCode.BUSY, "taken", fatal=True))
    # Peers that hang up before the hello, or in the middle of the conversation.
    record.end(Connection(Role.CLIENT), Connection(Role.SERVER))
    record.end(*connection_pair(make_hello()))
    # Broken framing: the server says why, once; a client closes.
    for ready in (False, True):
        client, server = (
            connection_pair(make_hello())
            if ready
            else (Connection(Role.CLIENT), Connection(Role.SERVER))
        )
        record.broken(server)
        if ready:
            record.send(server, client, ErrorReply(None, ErrorCode.BAD_FRAME, "no", fatal=True))
        else:
            record.saw_sent(server, ErrorReply(None, ErrorCode.BAD_FRAME, "no", fatal=True))
        record.broken(ready and connection_pair(make_hello())[0] or Connection(Role.CLIENT))
    server = Connection(Role.SERVER)  # broken, and the client hangs up before the last word
    record.broken(server)
    record.end(server)

    assert set(TRANSITIONS) - record.seen == {(Role.CLIENT, State.AWAIT_HELLO, Event.RECEIVE_REPLY)}


# --- request envelope ------------------------------------------------------------------------


def test_request_to_wire_is_the_id_and_the_parts() -> None:
    assert Request(3).to_wire() == {"id": 3}
    assert Request(3, {"reset": {}}).to_wire() == {"id": 3, "reset": {}}
    assert Request(3, {"action": 0, "repeat_action": 2}).to_wire() == {
        "id": 3,
        "action": 0,
        "repeat_action": 2,
    }
    assert Request(3, {}, token="t").to_wire() == {"id": 3, "token": "t"}


def test_request_from_wire_takes_the_map_apart() -> None:
    request = Request.from_wire({"id": 4, "token": "s3cret", "reset": {"seed": 1}, "x": [1]})
    assert request.id == 4 and request.token == "s3cret"
    assert request.parts == {"reset": {"seed": 1}, "x": [1]}


@pytest.mark.parametrize(
    "parts",
    [
        pytest.param({"bogus": 1}, id="unknown-key"),
        pytest.param({"config": [1]}, id="config-not-a-map"),
        pytest.param({"reset": None}, id="reset-nil"),
        pytest.param({"action": 1, "repeat_action": 0}, id="repeat-0"),
        pytest.param({"repeat_action": 2}, id="repeat-without-action"),
        pytest.param({"steps": [1], "reset": {}}, id="steps-in-company"),
        pytest.param({"batch": []}, id="empty-batch"),
    ],
)
def test_the_protocol_does_not_validate_parts(ready: Pair, parts: dict[str, Any]) -> None:
    """Parts are the server's business (test_parts.py): any map with an id is a request."""
    ready.server.receive_data(frame({"id": 4, **parts}))
    (got,) = drain(ready.server)
    assert got == Request(4, parts)
    assert ready.server.outstanding == (4,)


def _server_error(server: Connection, wire: Any) -> RemoteProtocolError:
    server.receive_data(frame(wire))
    with pytest.raises(RemoteProtocolError) as info:
        server.next_message()
    return info.value


@pytest.mark.parametrize(
    "wire",
    [
        pytest.param({"reset": {}}, id="missing-id"),
        pytest.param({"id": "4"}, id="str-id"),
        pytest.param({"id": 4.0}, id="float-id"),
        pytest.param({"id": True}, id="bool-id"),
        pytest.param({"id": None}, id="nil-id"),
        pytest.param({"id": [4]}, id="list-id"),
        pytest.param(make_hello().to_wire(), id="hello"),
    ],
)
def test_request_without_an_integer_id_is_a_bad_request(ready: Pair, wire: dict) -> None:
    server = ready.server
    error = _server_error(server, wire)
    assert "request 'id' must be an integer" in str(error)
    assert error.code == ErrorCode.BAD_REQUEST
    assert error.request_id is None and error.fatal is False
    assert server.state is State.READY and server.outstanding == ()
    # The error reply (id nil) answers nothing outstanding; then the connection goes on.
    server.send(ErrorReply(None, error.code, str(error)))
    server.receive_data(frame({"id": 5, "reset": {"seed": 1}}))
    assert drain(server) == [Request(5, {"reset": {"seed": 1}})]
    assert server.outstanding == (5,)


@pytest.mark.parametrize("token", [12345, 1.5, b"bytes", ["t"]], ids=repr)
def test_token_that_is_not_a_string_is_a_bad_request_answered_by_id(
    ready: Pair, token: Any
) -> None:
    error = _server_error(ready.server, {"id": 4, "token": token, "reset": {}})
    assert "'token' must be a string" in str(error) and "12345" not in str(error)
    assert error.code == ErrorCode.BAD_REQUEST and error.request_id == 4 and not error.fatal
    assert ready.server.outstanding == (4,)  # the error reply answers it
    ready.server.send(ErrorReply(4, error.code, str(error)))
    assert ready.server.outstanding == ()


def test_a_nil_token_is_no_token(ready: Pair) -> None:
    ready.server.receive_data(frame({"id": 4, "token": None, "reset": {}}))
    assert drain(ready.server) == [Request(4, {"reset": {}})]


def test_bad_request_error_reaches_the_client(ready: Pair) -> None:
    ready.client.send(Request(1))  # the client thinks it sent a valid request ...
    error = _server_error(ready.server, {"id": 1, "token": 7})  # ... the server got this
    (got,) = ready.send(ready.server, ErrorReply(error.request_id, error.code, str(error)))
    assert got.id == 1
    assert got.code == ErrorCode.BAD_REQUEST
    assert "token" in got.message
    assert ready.client.outstanding == ()
    assert ready.client.state is State.READY


def test_a_request_shows_its_parts_but_never_its_token() -> None:
    request = Request(3, {"inspect": {"tree": {}}}, token="s3cret")
    for text in (repr(request), str(request), repr([request]), f"{request}"):
        assert "inspect={'tree': {}}" in text and "token=..." in text
        assert "s3cret" not in text
    assert "token" not in repr(Request(3, {"reset": {}}))
    assert "s3cret" not in repr(Request.from_wire({"id": 1, "token": "s3cret"}))


def test_request_repr_cuts_long_parts() -> None:
    text = repr(Request(1, {"action": list(range(1000))}))
    assert len(text) < 200


# --- request / reply pairing -----------------------------------------------------------------


def test_request_and_response_round_trip(ready: Pair) -> None:
    action = np.array([0.25, -0.5], dtype=np.float32)
    request = Request(
        7,
        {
            "config": {"environment": {"repeat_action": 3}},
            "reset": {"seed": 42},
            "action": action,
            "observation": {"agent": {}},
            "repeat_action": 5,
        },
    )
    (got,) = ready.send(ready.client, request)
    assert isinstance(got, Request)
    assert got.id == 7 and got.token is None
    assert got.parts["config"] == {"environment": {"repeat_action": 3}}
    assert got.parts["reset"] == {"seed": 42}
    _assert_bit_exact(got.parts["action"], action)
    assert got.parts["observation"] == {"agent": {}}
    assert got.parts["repeat_action"] == 5
    assert ready.client.outstanding == (7,)
    assert ready.server.outstanding == (7,)

    obs = np.arange(4, dtype=np.float64)
    response = Response(
        id=7,
        observation={"agent": obs.tobytes(), "render": np.zeros((2, 2, 3), np.uint8)},
        reward=1.5,
        terminated=False,
        truncated=True,
        info={"steps": 3},
        frames=5,
    )
    (back,) = ready.send(ready.server, response)
    assert isinstance(back, Response)
    assert back.id == 7
    assert back.observation["agent"] == obs.tobytes()
    _assert_bit_exact(back.observation["render"], np.zeros((2, 2, 3), np.uint8))
    assert back.reward == 1.5
    assert back.terminated is False and back.truncated is True
    assert back.info == {"steps": 3}
    assert back.frames == 5
    assert back.agents is None
    assert ready.client.outstanding == ()
    assert ready.server.outstanding == ()


def test_request_with_a_token_round_trips(ready: Pair) -> None:
    (got,) = ready.send(ready.client, Request(1, {"reset": {}}, token="s3cret"))
    assert got == Request(1, {"reset": {}}, token="s3cret")


def test_empty_request_is_valid(ready: Pair) -> None:
    assert ready.send(ready.client, Request(0)) == [Request(0)]


def test_response_with_agents_round_trips(ready: Pair) -> None:
    ready.send(ready.client, Request(1))
    agents = {"left": {"reward": 1.0, "terminated": True, "truncated": False}}
    (got,) = ready.send(ready.server, Response(1, reward=1.0, agents=agents))
    assert got == Response(1, reward=1.0, agents=agents)


def test_arrays_received_on_a_connection_are_read_only(ready: Pair) -> None:
    """Small and large frames alike (whether the body is copied out of the buffer or not)."""
    for request_id, size in enumerate((4, 200_000)):
        action = np.arange(size, dtype=np.float32)
        (got,) = ready.send(ready.client, Request(request_id, {"action": action}))
        _assert_bit_exact(got.parts["action"], action)
        assert got.parts["action"].flags.writeable is False


def test_pipelined_requests_are_tracked_and_answered_in_order(ready: Pair) -> None:
    client, server = ready.client, ready.server
    data = b"".join(client.send(Request(i, {"action": i})) for i in (1, 2, 3))
    assert client.outstanding == (1, 2, 3)
    server.receive_data(data)
    received = drain(server)
    assert [r.id for r in received] == [1, 2, 3]
    assert [r.parts["action"] for r in received] == [1, 2, 3]
    assert server.outstanding == (1, 2, 3)

    with pytest.raises(LocalProtocolError, match="out of order"):
        server.send(Response(id=2))
    with pytest.raises(LocalProtocolError, match="out of order"):
        server.send(ErrorReply(3, ErrorCode.INVALID_ACTION, "no"))
    with pytest.raises(LocalProtocolError, match="out of order"):
        server.send(Response(id=99))
    with pytest.raises(LocalProtocolError, match="out of order"):
        server.send(ErrorReply(3, ErrorCode.ENVIRONMENT_ERROR, "boom", fatal=True))
    assert server.outstanding == (1, 2, 3)
    assert server.state is State.READY

    replies = server.send(Response(id=1, frames=1))
    assert server.outstanding == (2, 3)
    replies += server.send(ErrorReply(2, ErrorCode.INVALID_ACTION, "bad action"))
    assert server.outstanding == (3,)
    replies += server.send(BatchResponse(3, (Response(3, frames=3), None)))
    assert server.outstanding == ()
    with pytest.raises(LocalProtocolError, match="out of order"):
        server.send(Response(id=4))

    client.receive_data(replies)
    got = drain(client)
    assert [type(m) for m in got] == [Response, ErrorReply, BatchResponse]
    assert [m.id for m in got] == [1, 2, 3]
    assert got[1].code == "invalid_action" and got[1].message == "bad action"
    assert got[1].fatal is False
    assert got[2].replies == (Response(3, frames=3), None)
    assert client.outstanding == ()
    assert client.state is State.READY


def test_client_outstanding_shrinks_as_replies_arrive(ready: Pair) -> None:
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
        pytest.param(ErrorReply(99, "timeout", "x", fatal=True).to_wire(), id="fatal-error"),
        pytest.param(BatchResponse(99, ()).to_wire(), id="batch"),
    ],
)
def test_client_refuses_a_reply_to_an_unexpected_id(ready: Pair, reply: dict) -> None:
    ready.client.send(Request(id=1))
    ready.client.receive_data(frame(reply))
    with pytest.raises(RemoteProtocolError, match="reply to request 99, expected 1") as info:
        ready.client.next_message()
    assert info.value.fatal is True
    assert ready.client.state is State.CLOSED
    assert ready.client.next_message() is CONNECTION_CLOSED
    with pytest.raises(LocalProtocolError):
        ready.client.send(Request(id=2))


def test_client_refuses_a_reply_when_nothing_is_outstanding(ready: Pair) -> None:
    ready.client.receive_data(frame(Response(id=1).to_wire()))
    with pytest.raises(RemoteProtocolError, match="expected none"):
        ready.client.next_message()
    assert ready.client.state is State.CLOSED


def test_client_refuses_replies_out_of_order(ready: Pair) -> None:
    ready.client.send(Request(id=1))
    ready.client.send(Request(id=2))
    ready.client.receive_data(frame(Response(id=2).to_wire()))
    with pytest.raises(RemoteProtocolError, match="reply to request 2, expected 1"):
        ready.client.next_message()
    assert ready.client.state is State.CLOSED


def test_error_reply_without_id_does_not_consume_a_request(ready: Pair) -> None:
    ready.send(ready.client, Request(id=1))
    (got,) = ready.send(ready.server, ErrorReply(None, ErrorCode.BAD_FRAME, "garbled"))
    assert got == ErrorReply(None, "bad_frame", "garbled", fatal=False)
    assert ready.client.outstanding == (1,)
    assert ready.server.outstanding == (1,)
    assert ready.client.state is State.READY and ready.server.state is State.READY


def test_fatal_error_reply_to_a_request_closes_both_ends(ready: Pair) -> None:
    ready.send(ready.client, Request(1, {"action": [1.0, 0.0]}))
    got, closed = ready.send(
        ready.server, ErrorReply(1, ErrorCode.ENVIRONMENT_ERROR, "boom", fatal=True)
    )
    assert closed is CONNECTION_CLOSED
    assert got.fatal is True and got.id == 1
    assert ready.server.state is State.CLOSED
    assert ready.client.state is State.CLOSED
    assert ready.client.outstanding == () and ready.server.outstanding == ()
    with pytest.raises(LocalProtocolError):
        ready.server.send(ErrorReply(None, ErrorCode.TIMEOUT, "again", fatal=True))


def test_fatal_error_without_id_closes_with_requests_outstanding(ready: Pair) -> None:
    ready.send(ready.client, Request(1))
    got, closed = ready.send(ready.server, ErrorReply(None, ErrorCode.TIMEOUT, "idle", fatal=True))
    assert got == ErrorReply(None, "timeout", "idle", fatal=True) and closed is CONNECTION_CLOSED
    assert ready.client.state is State.CLOSED and ready.server.state is State.CLOSED


def test_send_that_fails_to_encode_changes_nothing(ready: Pair) -> None:
    ready.send(ready.client, Request(id=1))
    with pytest.raises(TypeError):
        ready.server.send(Response(id=1, info={"bad": object()}))
    assert ready.server.outstanding == (1,)
    with pytest.raises(TypeError):
        ready.client.send(Request(2, {"action": np.array([object()])}))
    assert ready.client.outstanding == (1,)
    (got,) = ready.send(ready.server, Response(id=1))
    assert got.id == 1


def test_a_client_learns_the_servers_frame_limit_from_the_hello(pair: Pair) -> None:
    hello = pair.handshake(make_hello(limits={"max_frame_size": 1000, "idle_timeout": None}))
    assert hello.protocol == (2, 7)
    assert hello.limits == {"max_frame_size": 1000, "idle_timeout": None}
    assert pair.client.max_send_size == 1000
    with pytest.raises(LocalProtocolError, match="exceeds the peer's frame limit of 1000"):
        pair.client.send(Request(1, {"reset": {"options": {"blob": b"x" * 1000}}}))
    assert pair.client.outstanding == ()
    (request,) = pair.send(pair.client, Request(1, {"reset": {"options": {"blob": b"x" * 900}}}))
    assert request.id == 1


def test_a_hello_without_limits_leaves_the_protocols(pair: Pair) -> None:
    """A 2.0 server announces no limits: the client keeps the protocol's."""
    wire = make_hello().to_wire()
    del wire["hello"]["limits"]
    wire["hello"]["protocol"] = [2, 0]
    pair.client.receive_data(frame(wire))
    (hello,) = drain(pair.client)
    assert hello.limits == {} and hello.protocol == (2, 0) and hello.render_size is None
    assert pair.client.max_send_size == DEFAULT_MAX_FRAME_SIZE


def test_send_larger_than_the_protocol_frame_limit_is_refused(ready: Pair) -> None:
    ready.send(ready.client, Request(id=1))
    with pytest.raises(
        LocalProtocolError, match=f"exceeds the peer's frame limit of {DEFAULT_MAX_FRAME_SIZE}"
    ):
        ready.server.send(Response(id=1, info={"blob": b"x" * DEFAULT_MAX_FRAME_SIZE}))
    assert ready.server.outstanding == (1,)
    assert ready.server.state is State.READY


def test_a_connection_limit_bounds_what_it_receives_not_what_it_sends() -> None:
    """``max_frame_size`` is this side's receive limit; the peer refuses larger frames itself."""
    pair = new_pair(max_frame_size=512)
    pair.handshake()
    pair.send(pair.client, Request(id=1))
    data = pair.server.send(Response(id=1, info={"blob": b"x" * 600}))
    assert len(data) > 512 + 4 and pair.server.outstanding == ()
    pair.client.receive_data(data)
    with pytest.raises(RemoteProtocolError, match="limit of 512 bytes") as info:
        pair.client.next_message()
    assert info.value.fatal is True


# --- framing ---------------------------------------------------------------------------------


def _requests() -> list[Request]:
    return [
        Request(1, {"reset": {"seed": 0}}),
        Request(2, {"action": np.array([0.5, -0.5], dtype=np.float32), "repeat_action": 2}),
        Request(3, {"observation": {}}, token="t"),
        Request(4, {"config": {"a": {"b": [1, 2, 3]}}}),
    ]


def _assert_requests_equal(got: list[Any], expected: list[Request]) -> None:
    assert len(got) == len(expected)
    for g, e in zip(got, expected, strict=True):
        assert isinstance(g, Request)
        assert pack(g.to_wire()) == pack(e.to_wire())


def test_data_fed_byte_by_byte(ready: Pair) -> None:
    requests = _requests()
    data = b"".join(ready.client.send(r) for r in requests)
    got: list[Any] = []
    for i in range(len(data)):
        ready.server.receive_data(data[i : i + 1])
        got += drain(ready.server)
    _assert_requests_equal(got, requests)
    assert ready.server.next_message() is NEED_DATA
    assert ready.server.outstanding == (1, 2, 3, 4)
    assert ready.server.buffered == 0


def test_hello_and_replies_fed_byte_by_byte_to_the_client(pair: Pair) -> None:
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


def test_several_frames_in_one_chunk(ready: Pair) -> None:
    requests = _requests()
    ready.server.receive_data(b"".join(ready.client.send(r) for r in requests))
    _assert_requests_equal(drain(ready.server), requests)
    assert ready.server.next_message() is NEED_DATA


def test_chunks_that_split_frames_anywhere(ready: Pair) -> None:
    requests = _requests()
    data = b"".join(ready.client.send(r) for r in requests)
    got: list[Any] = []
    for start in range(0, len(data), 7):
        ready.server.receive_data(data[start : start + 7])
        got += drain(ready.server)
    _assert_requests_equal(got, requests)


def test_need_data_until_the_frame_is_complete(ready: Pair) -> None:
    data = ready.client.send(Request(1, {"reset": {"seed": 5}}))
    server = ready.server
    assert server.next_message() is NEED_DATA
    server.receive_data(data[:2])  # half a length prefix
    assert server.next_message() is NEED_DATA
    server.receive_data(data[2:4])  # the whole prefix, no body
    assert server.next_message() is NEED_DATA
    server.receive_data(data[4:-1])  # all but the last byte
    assert server.next_message() is NEED_DATA
    assert server.buffered == len(data) - 1
    assert server.outstanding == ()
    server.receive_data(data[-1:])
    assert server.next_message() == Request(1, {"reset": {"seed": 5}})
    assert server.next_message() is NEED_DATA


def test_oversized_length_prefix_is_fatal_before_the_body(ready: Pair) -> None:
    server, client = ready.server, ready.client
    server.receive_data(b"\xff\xff\xff\xff")
    with pytest.raises(RemoteProtocolError, match="exceeds the limit") as info:
        server.next_message()
    assert info.value.fatal is True
    assert info.value.code == ErrorCode.BAD_FRAME
    assert str(0xFFFFFFFF) in str(info.value)
    assert server.next_message() is CONNECTION_CLOSED  # nothing more is read ...
    # ... but the server may still say why, once, and then the connection is closed.
    data = server.send(ErrorReply(None, info.value.code, str(info.value), fatal=True))
    assert server.state is State.CLOSED
    assert server.next_message() is CONNECTION_CLOSED
    with pytest.raises(LocalProtocolError):
        server.send(ErrorReply(None, ErrorCode.BAD_FRAME, "again", fatal=True))
    client.receive_data(data)
    assert drain(client) == [
        ErrorReply(None, "bad_frame", str(info.value), fatal=True),
        CONNECTION_CLOSED,
    ]
    assert client.state is State.CLOSED


def test_oversized_frame_is_refused_even_with_more_data_buffered(ready: Pair) -> None:
    server = ready.server
    server.receive_data(struct.pack(">I", DEFAULT_MAX_FRAME_SIZE + 1) + b"x" * 100)
    with pytest.raises(RemoteProtocolError) as info:
        server.next_message()
    assert info.value.fatal is True
    assert server.next_message() is CONNECTION_CLOSED
    server.receive_data(frame({"id": 1}))
    assert server.next_message() is CONNECTION_CLOSED
    assert server.outstanding == ()


def test_oversized_frame_before_the_hello_allows_one_fatal_error(pair: Pair) -> None:
    pair.server.receive_data(b"\xff\xff\xff\xff")
    with pytest.raises(RemoteProtocolError, match="exceeds the limit"):
        pair.server.next_message()
    pair.server.send(ErrorReply(None, ErrorCode.BAD_FRAME, "not rlenv", fatal=True))
    assert pair.server.state is State.CLOSED


def test_frame_of_exactly_the_limit_is_accepted() -> None:
    hello = make_hello()
    data = frame(hello.to_wire())
    limit = len(data) - 4
    client = Connection(Role.CLIENT, max_frame_size=limit)
    client.receive_data(data)
    assert client.next_message() == hello

    small = Connection(Role.CLIENT, max_frame_size=limit - 1)
    small.receive_data(data[:4])  # the length prefix alone is enough to refuse
    with pytest.raises(RemoteProtocolError, match=f"limit of {limit - 1} bytes") as info:
        small.next_message()
    assert info.value.fatal is True


def test_client_also_refuses_oversized_frames(pair: Pair) -> None:
    pair.client.receive_data(b"\xff\xff\xff\xff")
    with pytest.raises(RemoteProtocolError, match="exceeds the limit") as info:
        pair.client.next_message()
    assert info.value.fatal is True
    assert pair.client.next_message() is CONNECTION_CLOSED


@pytest.mark.parametrize("cut", [1, 3, 4, 10])
def test_eof_in_the_middle_of_a_frame_is_fatal(ready: Pair, cut: int) -> None:
    data = ready.client.send(Request(1, {"reset": {"seed": 123456}}))
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


def test_clean_eof_is_connection_closed(ready: Pair) -> None:
    ready.server.receive_data(b"")
    assert ready.server.peer_closed
    assert ready.server.next_message() is CONNECTION_CLOSED
    assert ready.server.state is State.CLOSED
    assert ready.server.next_message() is CONNECTION_CLOSED
    ready.client.receive_data(b"")
    assert ready.client.next_message() is CONNECTION_CLOSED
    assert ready.client.state is State.CLOSED


def test_buffered_frames_are_delivered_before_eof(ready: Pair) -> None:
    requests = _requests()
    ready.server.receive_data(b"".join(ready.client.send(r) for r in requests))
    ready.server.receive_data(b"")
    got = drain(ready.server)
    assert got[-1] is CONNECTION_CLOSED
    _assert_requests_equal(got[:-1], requests)


def test_eof_before_hello_is_connection_closed(pair: Pair) -> None:
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
        pytest.param(
            pack({"id": msgpack.ExtType(9, b"")}),
            "ext type 9 is not allowed: the only ext type is 1",
            id="foreign-ext",
        ),
        pytest.param(
            pack({"id": 1, "reset": {"options": {"at": [msgpack.Timestamp(0, 5)]}}}),
            "ext type -1 (msgpack's timestamp) is not allowed",
            id="timestamp",
        ),
        pytest.param(
            pack(
                {
                    "id": 1,
                    "reset": {"options": {"at": msgpack.Timestamp(0, 5), "big": bytes(1 << 20)}},
                }
            ),
            "ext type -1 (msgpack's timestamp) is not allowed",
            id="timestamp-big",
        ),
    ],
)
def test_bad_frame_body_is_an_error_and_the_server_goes_on(
    ready: Pair, body: bytes, message: str
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


def _nested_unfinished_arrays(levels: int, items: bytes, count: int) -> bytes:
    """A request whose option nests ``levels`` arrays, each ``count`` ``items`` and then the
    next array: none completes before the last (what a decoder's hooks would never see)."""
    level = b"\xdd" + struct.pack(">I", count + 1) + items * count
    return b"\x82\xa2id\x01\xa5reset\x81\xa7options\x81\xa1a" + level * levels + b"\x90" * levels


@pytest.mark.parametrize(
    "body",
    [
        pytest.param(
            b"\x81\xa1a\xdd" + struct.pack(">I", MAX_FRAME_OBJECTS) + b"\x90" * MAX_FRAME_OBJECTS,
            id="empty-arrays",
        ),
        pytest.param(
            _nested_unfinished_arrays(8, b"\xa2ab", MAX_FRAME_OBJECTS // 6),
            id="unfinished-arrays-of-strings",
        ),
        pytest.param(_nested_unfinished_arrays(1000, b"\xc0", 2000), id="deep-nils"),
    ],
)
def test_a_frame_of_too_many_objects_is_refused_before_it_is_decoded(
    ready: Pair, body: bytes
) -> None:
    """64 MiB of empty arrays decoded into 5.2 GB of Python objects: a frame now holds at most
    MAX_FRAME_OBJECTS objects, counted before anything is decoded."""
    server = ready.server
    server.receive_data(raw_frame(body) + frame({"id": 2}))
    with pytest.raises(RemoteProtocolError) as info:
        server.next_message()
    assert (
        str(info.value) == f"frame holds more than {MAX_FRAME_OBJECTS} msgpack objects, "
        "the limit of a frame"
    )
    assert (info.value.code, info.value.fatal, info.value.request_id) == (
        ErrorCode.BAD_FRAME,
        False,
        None,
    )
    assert server.next_message() == Request(id=2)  # the frame was consumed; the rest goes on


def test_objects_are_counted_exactly_whatever_their_type() -> None:
    """Every kind of msgpack object, then padding: exactly the limit decodes, one more does not
    (on both sides, for the client decodes with the same codec)."""
    array = np.arange(3, dtype=np.uint8)
    kinds = [
        b"\x05",
        b"\xe0",
        b"\xc0",
        b"\xc2",
        b"\xc3",
        b"\xcc\xff",
        b"\xcd\x01\x00",
        b"\xce" + bytes(4),
        b"\xcf" + bytes(8),
        b"\xd0\x80",
        b"\xd1" + bytes(2),
        b"\xd2" + bytes(4),
        b"\xd3" + bytes(8),
        b"\xca" + bytes(4),
        b"\xcb" + bytes(8),
        b"\xa3abc",
        b"\xd9\x05hello",
        b"\xda\x01\x00" + b"s" * 256,
        b"\xdb" + struct.pack(">I", 70_000) + b"t" * 70_000,
        b"\xc4\x00",
        b"\xc5\x01\x00" + bytes(256),
        b"\xc6" + struct.pack(">I", 70_000) + bytes(70_000),
        pack(array),
        pack(np.zeros((), np.float64)),
        pack(np.zeros(300, np.uint8)),
        pack(np.zeros(70_000, np.uint8)),
        b"\x80",
        b"\x90",
        b"\x81\xa1k\x01",
        b"\xdc\x00\x01\x01",
        b"\xde\x00\x00",
        b"\xdf" + bytes(4),
        b"\xdd" + bytes(4),
    ]
    assert {kind[0] for kind in kinds} >= {0xD8, 0xC7, 0xC8, 0xC9}  # the arrays' ext sizes
    objects_in_kinds = len(kinds) + 3  # the map {"k": 1} holds two more, the array16 one
    for extra, refused in ((0, False), (1, True)):
        padding = MAX_FRAME_OBJECTS - 3 - objects_in_kinds + extra
        body = (
            b"\x81\xa1a\xdd"
            + struct.pack(">I", len(kinds) + padding)
            + b"".join(kinds)
            + b"\x00" * padding
        )
        for strict in (True, False):
            if refused:
                with pytest.raises(RemoteProtocolError, match="more than 1048576 msgpack"):
                    unpack(body, strict=strict)
            else:
                items = unpack(body, strict=strict)["a"]
                assert len(items) == len(kinds) + padding and items[-1] == 0
                assert items[22].tolist() == [0, 1, 2] and items[28] == {"k": 1}


def test_non_map_frame_on_the_client_is_an_error(ready: Pair) -> None:
    ready.client.receive_data(frame([1, 2]))
    with pytest.raises(RemoteProtocolError, match="a frame must hold a map, got list"):
        ready.client.next_message()


def test_length_prefix_is_big_endian(ready: Pair) -> None:
    data = ready.client.send(Request(id=1))
    body = pack({"id": 1})
    assert data == len(body).to_bytes(4, "big") + body


# --- Response / ErrorReply / BatchResponse parsing ------------------------------------------

_RESPONSE = Response(
    id=1, observation={"a": 1}, reward=0.5, terminated=True, truncated=False, info={}, frames=4
).to_wire()


@pytest.mark.parametrize(
    "missing",
    [
        *sorted(_RESPONSE),
    ],
)
def test_response_from_wire_rejects_missing_fields(missing: str) -> None:
    wire = {k: v for k, v in _RESPONSE.items() if k != missing}
    with pytest.raises(RemoteProtocolError, match="invalid response") as info:
        Response.from_wire(wire)
    assert missing in str(info.value)


@pytest.mark.parametrize(
    "change",
    [
        {"reward": "lots"},
        {"reward": None},
        {"reward": True},
        {"frames": "four"},
        {"frames": None},
        {"frames": 4.0},
        {"frames": True},
        {"terminated": 1},
        {"truncated": None},
        {"info": []},
        {"info": None},
        {"observation": [1]},
        {"observation": b"raw"},
        {"agents": [1]},
    ],
    ids=lambda change: "-".join(f"{k}={v!r}" for k, v in change.items()),
)
def test_response_from_wire_rejects_wrong_types(change: dict[str, Any]) -> None:
    with pytest.raises(RemoteProtocolError, match="invalid response"):
        Response.from_wire({**_RESPONSE, **change})


def test_response_from_wire_reads_all_fields() -> None:
    got = Response.from_wire(_RESPONSE)
    assert got == Response(
        id=1, observation={"a": 1}, reward=0.5, terminated=True, truncated=False, info={}, frames=4
    )
    assert type(got.reward) is float and type(got.frames) is int


def test_response_from_wire_takes_an_integer_reward_as_a_float() -> None:
    got = Response.from_wire({**_RESPONSE, "reward": 3, "observation": None})
    assert got.reward == 3.0 and type(got.reward) is float and got.observation is None


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


def test_error_reply_round_trips_its_code_as_a_string() -> None:
    wire = ErrorReply(3, ErrorCode.INVALID_CONFIG, "no", fatal=True).to_wire()
    assert wire == {"id": 3, "error": {"code": "invalid_config", "message": "no", "fatal": True}}
    assert type(wire["error"]["code"]) is str
    assert ErrorReply.from_wire(unpack(pack(wire))) == ErrorReply(3, "invalid_config", "no", True)


def test_malformed_reply_on_the_client_is_a_remote_protocol_error(ready: Pair) -> None:
    ready.client.send(Request(id=1))
    ready.client.receive_data(frame({"id": 1, "error": {"code": "x"}}))
    with pytest.raises(RemoteProtocolError, match="invalid error reply"):
        ready.client.next_message()
    ready.client.receive_data(frame({"id": 1, "reward": 1.0}))
    with pytest.raises(RemoteProtocolError, match="invalid response"):
        ready.client.next_message()
    ready.client.receive_data(frame({"id": 1, "batch": "no"}))
    with pytest.raises(RemoteProtocolError, match="invalid batch response"):
        ready.client.next_message()
    ready.client.receive_data(frame({"id": 1, "steps": {}}))
    with pytest.raises(RemoteProtocolError, match="invalid steps response"):
        ready.client.next_message()
    assert ready.client.outstanding == (1,) and ready.client.state is State.READY


@pytest.mark.parametrize(
    "wire",
    [
        pytest.param({k: v for k, v in _RESPONSE.items() if k != "id"}, id="response"),
        pytest.param({"batch": []}, id="batch"),
    ],
)
def test_reply_without_an_id_on_the_client_is_a_remote_protocol_error(
    ready: Pair, wire: dict
) -> None:
    ready.client.send(Request(1))
    ready.client.receive_data(frame(wire))
    with pytest.raises(RemoteProtocolError):
        ready.client.next_message()


def test_batch_response_round_trips(ready: Pair) -> None:
    ready.send(ready.client, Request(8, {"batch": [{"reset": {}}, None, {"action": 9}]}))
    answer = BatchResponse(
        8, (Response(8, frames=0), None, ErrorReply(8, ErrorCode.INVALID_ACTION, "no"))
    )
    (got,) = ready.send(ready.server, answer)
    assert got == BatchResponse(8, (Response(8), None, ErrorReply(8, "invalid_action", "no")))
    assert ready.client.outstanding == ()


@pytest.mark.parametrize(
    ("batch", "message"),
    [
        pytest.param("no", "'batch' is not a list", id="not-a-list"),
        pytest.param(None, "'batch' is not a list", id="nil"),
        pytest.param([3], "a reply is not a map", id="reply-int"),
        pytest.param([None, [1]], "a reply is not a map", id="reply-list"),
        pytest.param([{"id": 1, "error": {"code": "x"}}], "invalid error reply", id="bad-error"),
        pytest.param([{"id": 1, "reward": 0.0}], "invalid response", id="bad-response"),
        pytest.param([{**_RESPONSE, "frames": "x"}], "invalid response", id="bad-frames"),
    ],
)
def test_batch_response_from_wire_rejects_malformed_replies(batch: Any, message: str) -> None:
    with pytest.raises(RemoteProtocolError, match=message):
        BatchResponse.from_wire({"id": 1, "batch": batch})


@pytest.mark.parametrize(
    "wire",
    [
        pytest.param({"batch": []}, id="no-id"),
        pytest.param(
            {"id": 1, "batch": [{k: v for k, v in _RESPONSE.items() if k != "id"}]},
            id="reply-without-id",
        ),
    ],
)
def test_batch_response_without_an_id_is_a_remote_protocol_error(wire: dict) -> None:
    with pytest.raises(RemoteProtocolError):
        BatchResponse.from_wire(wire)


# --- steps: a vector step in columns ----------------------------------------------------------


def _steps_answer(**overrides: Any) -> StepsResponse:
    codec = codec_for(spaces.Box(-10.0, 10.0, (5,), np.float32))
    rows = np.arange(15, dtype=np.float32).reshape(3, 5)
    fields: dict[str, Any] = {
        "id": 9,
        "observation": codec.join([codec.pack(row) for row in rows]),
        "reward": np.array([1.0, 0.0, 2.5]),
        "terminated": np.array([False, False, True]),
        "truncated": np.zeros(3, np.bool_),
        "frames": np.array([2, 0, 1]),
        "info": ({}, {"seed": 1}, {}),
        "errors": (None, ErrorReply(9, "environment_error", "boom"), None),
    }
    fields.update(overrides)
    return StepsResponse(**fields)


def test_steps_request_and_answer_round_trip(ready: Pair) -> None:
    actions = np.array([[0.5], [-1.0], [0.0]], dtype=np.float32)
    reset = np.array([False, True, False])
    (got,) = ready.send(
        ready.client, Request(9, {"steps": {"action": actions, "reset": reset, "repeat_action": 2}})
    )
    steps = got.parts["steps"]
    _assert_bit_exact(steps["action"], actions)
    assert steps["reset"].tolist() == [False, True, False] and steps["repeat_action"] == 2

    answer = _steps_answer()
    (back,) = ready.send(ready.server, answer)
    assert isinstance(back, StepsResponse) and back.id == 9
    batched = codec_for(batch_space(spaces.Box(-10.0, 10.0, (5,), np.float32), 3))
    np.testing.assert_array_equal(
        batched.unpack(back.observation), np.arange(15, dtype=np.float32).reshape(3, 5)
    )
    assert back.reward.dtype == np.float64 and back.reward.tolist() == [1.0, 0.0, 2.5]
    assert back.frames.dtype == np.int64 and back.frames.tolist() == [2, 0, 1]
    assert back.terminated.dtype == np.bool_ and back.terminated.tolist() == [False, False, True]
    assert back.truncated.dtype == np.bool_ and not back.truncated.any()
    assert back.info == ({}, {"seed": 1}, {})
    assert back.errors == (None, ErrorReply(9, "environment_error", "boom"), None)
    assert ready.client.outstanding == ()


def test_steps_columns_travel_as_raw_little_endian_bytes() -> None:
    wire = unpack(pack(_steps_answer(errors=None).to_wire()))
    columns = wire["steps"]
    assert columns["reward"] == struct.pack("<3d", 1.0, 0.0, 2.5)
    assert columns["terminated"] == b"\x00\x00\x01"
    assert columns["truncated"] == b"\x00\x00\x00"
    assert columns["frames"] == struct.pack("<3q", 2, 0, 1)
    assert columns["observation"] == np.arange(15, dtype="<f4").tobytes()
    assert columns["info"] == [{}, {"seed": 1}, {}]
    assert "errors" not in columns


def test_steps_response_with_no_errors_reads_none() -> None:
    got = StepsResponse.from_wire(unpack(pack(_steps_answer(errors=None).to_wire())))
    assert got.errors is None


_COLUMNS = _steps_answer().to_wire()["steps"]  # K = 3


@pytest.mark.parametrize(
    "change",
    [
        pytest.param({"reward": _COLUMNS["reward"][:-1]}, id="reward-a-byte-short"),
        pytest.param({"reward": _COLUMNS["reward"][:16]}, id="reward-a-value-short"),
        pytest.param({"reward": _COLUMNS["reward"] + b"\x00" * 8}, id="reward-a-value-long"),
        pytest.param({"reward": [1.0, 0.0, 2.5]}, id="reward-list"),
        pytest.param({"reward": None}, id="reward-nil"),
        pytest.param({"reward": "abcdefgh" * 3}, id="reward-str"),
        pytest.param({"frames": _COLUMNS["frames"][:-8]}, id="frames-short"),
        pytest.param({"frames": _COLUMNS["frames"] + b"\x00"}, id="frames-a-byte-long"),
        pytest.param({"frames": [2, 0, 1]}, id="frames-list"),
        pytest.param({"terminated": b"\x00\x00"}, id="terminated-short"),
        pytest.param({"terminated": b"\x00" * 4}, id="terminated-long"),
        pytest.param({"terminated": [False, False, True]}, id="terminated-list"),
        pytest.param({"truncated": b""}, id="truncated-empty"),
        pytest.param({"truncated": "no"}, id="truncated-str"),
        pytest.param({"info": [{}, {}]}, id="info-short"),
        pytest.param({"info": [{}, {}, {}, {}]}, id="info-long"),
        pytest.param({"info": [{}, 3, {}]}, id="info-not-map"),
        pytest.param({"info": None}, id="info-nil"),
        pytest.param({"errors": [None]}, id="errors-short"),
        pytest.param({"errors": [None, {"code": "x"}, None]}, id="error-no-message"),
        pytest.param({"errors": [None, "boom", None]}, id="error-str"),
        pytest.param({"errors": 3}, id="errors-int"),
    ],
)
def test_malformed_steps_responses_are_remote_protocol_errors(change: dict[str, Any]) -> None:
    with pytest.raises(RemoteProtocolError, match="invalid steps response"):
        StepsResponse.from_wire({"id": 1, "steps": {**_COLUMNS, **change}})


@pytest.mark.parametrize("missing", sorted(set(_COLUMNS) - {"errors"}))
def test_steps_response_without_a_column_is_refused(missing: str) -> None:
    columns = {k: v for k, v in _COLUMNS.items() if k != missing}
    with pytest.raises(RemoteProtocolError, match="invalid steps response"):
        StepsResponse.from_wire({"id": 1, "steps": columns})


@pytest.mark.parametrize("steps", [[1, 2], "columns", None], ids=repr)
def test_steps_response_that_is_not_a_map_is_refused(steps: Any) -> None:
    with pytest.raises(RemoteProtocolError, match="invalid steps response"):
        StepsResponse.from_wire({"id": 1, "steps": steps})


def test_steps_response_of_zero_instances_round_trips() -> None:
    empty = StepsResponse(
        1, b"", np.zeros(0), np.zeros(0, np.bool_), np.zeros(0, np.bool_), np.zeros(0, np.int64), ()
    )
    got = StepsResponse.from_wire(unpack(pack(empty.to_wire())))
    assert got.reward.shape == (0,) and got.info == () and got.errors is None


def test_a_message_of_more_objects_than_a_frame_may_hold_is_not_sent(ready: Pair) -> None:
    ready.send(ready.client, Request(id=1))
    many = list(range(MAX_FRAME_OBJECTS))  # and the map, its keys...: over the limit
    with pytest.raises(LocalProtocolError, match=f"more than {MAX_FRAME_OBJECTS} msgpack "):
        ready.server.send(Response(id=1, info={"many": many}))
    assert ready.server.outstanding == (1,) and ready.server.state is State.READY
    fewer = ready.server.send(Response(id=1, info={"many": many[: MAX_FRAME_OBJECTS - 100]}))
    ready.client.receive_data(fewer)
    (response,) = drain(ready.client)
    assert len(response.info["many"]) == MAX_FRAME_OBJECTS - 100


def test_pipelined_frames_in_any_pieces_come_out_whole_and_in_order(ready: Pair) -> None:
    # Frames of a few bytes and past the 64 KiB a view is taken from, cut anywhere: the reader
    # keeps an offset into what it holds (and compacts it now and then), never losing a byte.
    sizes = [1, 200, 70_000, 3, 0, 100_000, 10, 65_536, 5]
    requests = [Request(i + 1, {"blob": bytes([i]) * size}) for i, size in enumerate(sizes)]
    stream = b"".join(ready.client.send(request) for request in requests)
    rng = np.random.default_rng(0)
    cuts = sorted(set(rng.integers(1, len(stream), 40).tolist()))
    got: list[Any] = []
    for start, end in itertools.pairwise([0, *cuts, len(stream)]):
        ready.server.receive_data(stream[start:end])
        if rng.random() < 0.5:  # sometimes several pieces arrive before anything is read
            got += drain(ready.server)
    got += drain(ready.server)
    assert [(r.id, bytes(r.parts["blob"])) for r in got] == [
        (r.id, r.parts["blob"]) for r in requests
    ]
    assert ready.server.buffered == 0
    assert ready.server.outstanding == tuple(range(1, len(sizes) + 1))


def test_a_backlog_of_frames_in_one_piece_is_read_frame_by_frame(ready: Pair) -> None:
    frames = [ready.client.send(Request(i)) for i in range(1, 1001)]
    ready.server.receive_data(b"".join(frames))
    left = sum(map(len, frames))
    for i, sent in enumerate(frames, 1):
        assert ready.server.next_message().id == i
        left -= len(sent)
        assert ready.server.buffered == left
    assert ready.server.next_message() is NEED_DATA
