"""Bytes: frames, msgpack, and numpy arrays inside msgpack.

A **frame** is a 4-byte big-endian length followed by that many bytes holding exactly one msgpack
object. numpy arrays whose dtype and shape are not known in advance (rendered frames, world
data, info) travel as msgpack ext type :data:`NDARRAY_EXT` (dtype, shape, raw bytes) and decode
with ``np.frombuffer``: no copy, read-only. Values of the spaces a hello declares travel more
cheaply still, as raw bytes in their space's dtype (see :mod:`rlenv.protocol.spaces`).
Nothing is ever pickled.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any, Final

import msgpack
import numpy as np

from rlenv.protocol.errors import RemoteProtocolError

__all__ = [
    "DEFAULT_MAX_FRAME_SIZE",
    "HEADER",
    "MAX_FRAME_OBJECTS",
    "NDARRAY_EXT",
    "count_objects",
    "find_non_text_key",
    "frame",
    "pack",
    "unpack",
]

DEFAULT_MAX_FRAME_SIZE: Final = 64 * 1024 * 1024
"""Largest frame body accepted by default, checked against the length prefix before reading."""

MAX_FRAME_OBJECTS: Final = 1 << 20
"""Most msgpack objects a frame may hold (every value counts, keys, arrays and maps included).
A byte may hold an empty array, which costs Python some 64 bytes: this bounds what a frame
decodes into. Frames of this many bytes or fewer cannot exceed it; longer ones are counted
before they are decoded."""

NDARRAY_EXT: Final = 1
"""msgpack ext type code of a numpy array."""

HEADER: Final = struct.Struct(">I")
"""The length prefix of a frame."""

_ARRAY_HEADER = struct.Struct("<BB")  # dtype string length, number of dimensions
_MAX_NDIM = 32
_ITEM_SIZES = {"b": (1,), "i": (1, 2, 4, 8), "u": (1, 2, 4, 8), "f": (2, 4, 8), "c": (8, 16)}
_CACHE_SIZE = 1024  # distinct (dtype, shape) pairs remembered; bounded against hostile peers
_ENCODED_HEADERS: dict[tuple[np.dtype, tuple[int, ...]], bytes] = {}
_DECODED_HEADERS: dict[bytes, tuple[np.dtype, tuple[int, ...], int, int]] = {}


def encode_ndarray(array: np.ndarray) -> msgpack.ExtType:
    """``array`` as the ndarray ext type: dtype string, shape, then the elements in C order.

    Raises:
        TypeError: the dtype (object, structured, datetime...) or the rank cannot travel.
    """
    key = (array.dtype, array.shape)
    header = _ENCODED_HEADERS.get(key)
    if header is None:
        if (
            array.dtype.itemsize not in _ITEM_SIZES.get(array.dtype.kind, ())
            or array.dtype.fields is not None
        ):
            raise TypeError(f"arrays of dtype {array.dtype} cannot travel on the wire")
        if array.ndim > _MAX_NDIM:
            raise TypeError(f"arrays of more than {_MAX_NDIM} dimensions cannot travel on the wire")
        dtype = array.dtype.str.encode()
        header = _ARRAY_HEADER.pack(len(dtype), array.ndim) + dtype
        header += struct.pack(f"<{array.ndim}Q", *array.shape)
        if len(_ENCODED_HEADERS) < _CACHE_SIZE:
            _ENCODED_HEADERS[key] = header
    return msgpack.ExtType(NDARRAY_EXT, header + array.tobytes())


def decode_ndarray(data: bytes) -> np.ndarray:
    """The read-only array an ndarray ext payload holds (a view of ``data``).

    Raises:
        ValueError: a malformed header, a dtype that may not travel, or a size mismatch.
    """
    dtype, shape, count, offset = _parse_header(data)
    if count * dtype.itemsize != len(data) - offset:
        raise ValueError(
            f"ndarray of shape {shape} and dtype {dtype} needs {count * dtype.itemsize} bytes, "
            f"the frame holds {len(data) - offset}"
        )
    return np.frombuffer(data, dtype=dtype, count=count, offset=offset).reshape(shape)


def _parse_header(data: bytes) -> tuple[np.dtype, tuple[int, ...], int, int]:
    """(dtype, shape, element count, header length) of an encoded array; cached by header."""
    try:
        dtype_len, ndim = _ARRAY_HEADER.unpack_from(data)
        header_len = _ARRAY_HEADER.size + dtype_len + 8 * ndim
    except struct.error:
        raise ValueError("malformed ndarray header: too short") from None
    header = data[:header_len]
    parsed = _DECODED_HEADERS.get(header)
    if parsed is not None:
        return parsed
    if ndim > _MAX_NDIM:
        raise ValueError(f"ndarray of {ndim} dimensions; at most {_MAX_NDIM} are allowed")
    try:
        text = data[_ARRAY_HEADER.size : _ARRAY_HEADER.size + dtype_len].decode("ascii")
        dtype = np.dtype(text)
        shape = struct.unpack_from(f"<{ndim}Q", data, _ARRAY_HEADER.size + dtype_len)
    except (struct.error, UnicodeDecodeError, TypeError, ValueError) as exc:
        raise ValueError(f"malformed ndarray header: {exc}") from None
    if (
        dtype.itemsize not in _ITEM_SIZES.get(dtype.kind, ())
        or dtype.fields is not None
        or dtype.subdtype is not None
    ):
        raise ValueError(f"ndarray dtype {dtype} is not allowed on the wire")
    if dtype.str != text:
        raise ValueError(
            f"ndarray dtype {text!r:.40} is not written as numpy's dtype.str ({dtype.str!r})"
        )
    count = 1
    for n in shape:
        count *= n
    parsed = (dtype, shape, count, header_len)
    if len(_DECODED_HEADERS) < _CACHE_SIZE:
        _DECODED_HEADERS[header] = parsed
    return parsed


def _default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return encode_ndarray(obj)
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"objects of type {type(obj).__name__} cannot travel on the wire")


def _ext_hook(code: int, data: bytes) -> Any:
    if code != NDARRAY_EXT:
        raise ValueError(_foreign_ext(code))
    return decode_ndarray(data)


pack: Callable[[Any], bytes] = msgpack.Packer(
    default=_default, use_bin_type=True, autoreset=True
).pack
"""Encode an object as msgpack, numpy arrays and scalars included (no framing).

Raises ``TypeError`` when it holds something that cannot travel on the wire. (The packer's own
method: no Python call around it on every message.)
"""


def frame(obj: Any) -> bytes:
    """``obj`` encoded as one whole frame: length prefix, then the msgpack body.

    Raises:
        TypeError: ``obj`` holds something that cannot travel on the wire.
    """
    body = pack(obj)
    return HEADER.pack(len(body)) + body


def unpack(body: bytes | bytearray | memoryview, *, strict: bool = True) -> Any:
    """Decode one msgpack object that fills ``body`` exactly.

    Strings are UTF-8, and every map key at every depth must be a str: msgpack refuses
    integer, float, nil and ext keys itself, and when ``strict`` (the default) a bin key is
    refused too. No container may declare more elements or bytes than ``body`` holds (msgpack
    bounds each by the body's length), and a frame holds at most :data:`MAX_FRAME_OBJECTS`
    objects (counted before decoding, in frames longer than that). The only ext type is
    :data:`NDARRAY_EXT`; any other is refused, and when ``strict`` so is msgpack's timestamp
    type (-1), which msgpack decodes without asking the hook: a decoded frame that may hold one
    (its type byte, 0xff, is in it) is searched for it. A client reading a server may skip the
    strict checks (rlenv servers never send either), which keeps the search off a path where
    packed floats make 0xff bytes common.

    Raises:
        RemoteProtocolError: invalid msgpack, a map key that is not a str, trailing bytes, a
            foreign ext type (timestamps included), a malformed array, or more objects than
            :data:`MAX_FRAME_OBJECTS`.
    """
    if len(body) > MAX_FRAME_OBJECTS and count_objects(body) > MAX_FRAME_OBJECTS:
        raise RemoteProtocolError(
            f"frame holds more than {MAX_FRAME_OBJECTS} msgpack objects, the limit of a frame"
        )
    try:
        value = msgpack.unpackb(
            body, ext_hook=_ext_hook, object_hook=_text_keys if strict else None
        )
    except msgpack.ExtraData:
        raise RemoteProtocolError("trailing bytes after the message in the frame") from None
    except (ValueError, TypeError, msgpack.UnpackException, RecursionError) as exc:
        detail = str(exc) or _UNNAMED_ERRORS.get(type(exc), type(exc).__name__)
        raise RemoteProtocolError(f"frame is not valid msgpack: {detail}") from None
    if strict and (body.__class__ is memoryview or 0xFF in body) and _holds_timestamp(value):
        raise RemoteProtocolError(f"frame is not valid msgpack: {_foreign_ext(-1)}")
    return value


def _object_sizes() -> tuple[list[int], dict[int, tuple[struct.Struct, int]]]:
    """The bytes each msgpack type byte's object takes (0: read its length).

    For the types with a length: the length's format and the bytes before the payload.
    """
    sizes = [1] * 0x100  # positive and negative fixint, nil, false, true; 0xc1 (never used)
    for byte in range(0xA0, 0xC0):
        sizes[byte] = 1 + (byte & 0x1F)  # fixstr; fixmap and fixarray are 1 byte, as headers
    sizes[0xCA:0xE0] = [5, 9, 2, 3, 5, 9, 2, 3, 5, 9, 3, 4, 6, 10, 18, 0, 0, 0, 3, 5, 3, 5]
    lengths = {}
    for first, skip in ((0xC4, 1), (0xC7, 2), (0xD9, 1)):  # bin; ext (a type byte); str
        for index, form in enumerate((">B", ">H", ">I")):
            sizes[first + index] = 0
            lengths[first + index] = (struct.Struct(form), skip + 2**index)
    return sizes, lengths


_SIZES, _LENGTHS = _object_sizes()


def count_objects(body: bytes | bytearray | memoryview) -> int:
    """How many msgpack objects ``body`` holds, up to one more than :data:`MAX_FRAME_OBJECTS`.

    Objects follow each other whatever their nesting (an array's header, then its elements), so
    counting them is a walk over the headers that skips payloads; malformed bytes end the walk
    (msgpack then says what is wrong).
    """
    end = len(body)
    position = count = 0
    sizes, lengths = _SIZES, _LENGTHS
    while position < end and count <= MAX_FRAME_OBJECTS:
        byte = body[position]
        size = sizes[byte]
        if not size:
            form, skip = lengths[byte]
            if position + skip > end:
                break
            size = skip + form.unpack_from(body, position + 1)[0]
        position += size
        count += 1
    return count


def _text_keys(mapping: dict[Any, Any]) -> dict[Any, Any]:
    """``mapping``, once every key is known to be a str (msgpack's ``object_hook``)."""
    for key in mapping:
        if key.__class__ is not str:
            raise ValueError(_not_text(key))
    return mapping


def find_non_text_key(value: Any) -> str | None:
    """Why ``value`` cannot travel as rlenv data: a map key that is not a str, at any depth.

    Returns:
        ``None`` when every map key (in maps, lists and tuples, nested) is a str; else a
        message naming the first other key.
    """
    pending = [value]
    while pending:
        item = pending.pop()
        if isinstance(item, dict):
            for key, entry in item.items():
                if key.__class__ is not str:
                    return _not_text(key)
                if isinstance(entry, _CONTAINERS):
                    pending.append(entry)
        elif isinstance(item, _CONTAINERS):
            pending.extend(entry for entry in item if isinstance(entry, _CONTAINERS))
    return None


_CONTAINERS = (dict, list, tuple)  # a tuple of types: isinstance's fastest form


def _not_text(key: Any) -> str:
    kind = "bin" if isinstance(key, bytes | bytearray) else type(key).__name__
    return f"map key {key!r:.40} is {kind}, not a str: every map key must be a str"


_UNNAMED_ERRORS = {  # msgpack's errors that come without a message
    msgpack.FormatError: "a byte that begins no msgpack value (such as 0xc1, never used)",
    msgpack.StackError: "containers nested deeper than the decoder allows",
}


def _holds_timestamp(value: Any) -> bool:
    """Whether ``value`` holds a ``msgpack.Timestamp`` at any depth."""
    pending = [value]
    while pending:
        item = pending.pop()
        if item.__class__ is dict:
            pending.extend(item.values())
        elif item.__class__ is list:
            pending.extend(item)
        elif item.__class__ is msgpack.Timestamp:
            return True
    return False


def _foreign_ext(code: int) -> str:
    name = " (msgpack's timestamp)" if code == -1 else ""
    return f"ext type {code}{name} is not allowed: the only ext type is {NDARRAY_EXT} (arrays)"
