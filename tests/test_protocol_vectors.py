"""The shared protocol test vectors (``docs/protocol/vectors/``) are true and up to date.

(a) every committed frame is self-consistent: its length prefix matches, and its bytes decode
(with the codec the server and the client use) to the value the file gives; (b) regenerating
them against real servers gives the committed files (frames from the server byte for byte,
but for the paths a vector declares in ``varies``); (c) the canonical encoding of each value, as
the Python client encodes, gives the recorded bytes, exactly where the file says so.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest
from protocol_vectors import (
    SCENARIOS,
    VECTORS_DIR,
    decode_value,
    dumps,
    encode_value,
    from_tagged,
    generate,
    mask,
    to_tagged,
)

from rlenv.protocol.codec import HEADER, unpack
from rlenv.protocol.errors import ErrorCode, RemoteProtocolError

FILES = sorted(path.name for path in VECTORS_DIR.glob("*.json"))
Exchange = dict[str, Any]


def _load(name: str) -> dict[str, Any]:
    return json.loads((VECTORS_DIR / name).read_text(encoding="utf-8"))


def _exchanges() -> Iterator[tuple[str, int, Exchange]]:
    for name in FILES:
        for index, exchange in enumerate(_load(name)["exchanges"]):
            yield name, index, exchange


def _same(a: Any, b: Any) -> bool:
    """Equal as JSON text: 4 and 4.0 differ, and so does the order of a map's keys."""
    return json.dumps(a) == json.dumps(b)


def _body(exchange: Exchange) -> tuple[bytes, bool]:
    """The bytes after the length prefix, and whether the prefix gives their length."""
    data = bytes.fromhex(exchange["hex"])
    body = data[HEADER.size :]
    return body, len(data) >= HEADER.size and HEADER.unpack_from(data)[0] == len(body)


EXCHANGES = list(_exchanges())
IDS = [f"{name}:{index}" for name, index, _ in EXCHANGES]


def test_every_scenario_has_its_file() -> None:
    assert FILES == sorted(item.file for item in SCENARIOS)


@pytest.mark.parametrize("name", FILES)
def test_files_are_written_as_the_generator_writes_them(name: str) -> None:
    text = (VECTORS_DIR / name).read_text(encoding="utf-8")
    document = json.loads(text)
    assert text == dumps(document)
    assert set(document) == {"title", "server", "exchanges"}
    for exchange in document["exchanges"]:
        assert exchange["from"] in ("client", "server")
        assert set(exchange) <= {
            "from",
            "connection",
            "note",
            "hex",
            "value",
            "canonical",
            "varies",
            "closes",
        }
        if exchange["from"] == "client":
            assert "varies" not in exchange and "closes" not in exchange
    numbered = {"connection" in exchange for exchange in document["exchanges"]}
    assert len(numbered) == 1, "connection on every exchange, or on none"


@pytest.mark.parametrize(("name", "index", "exchange"), EXCHANGES, ids=IDS)
def test_a_frame_decodes_to_its_value(name: str, index: int, exchange: Exchange) -> None:
    """(a) The prefix gives the body's length, and the body decodes to ``value``."""
    body, prefix_matches = _body(exchange)
    if "value" not in exchange:  # a frame a client sent on purpose, broken or with no JSON form
        assert exchange["from"] == "client"
        if prefix_matches:
            try:
                decoded = decode_value(body)
            except ValueError:  # not msgpack: the server's codec refuses it too
                with pytest.raises(RemoteProtocolError):
                    unpack(body)
            else:  # msgpack with a bin map key or a NaN, which the notation has no form for
                with pytest.raises(TypeError):
                    to_tagged(decoded)
        return
    assert prefix_matches
    value = exchange["value"]
    assert _same(to_tagged(decode_value(body)), value)
    try:
        decoded = unpack(body)
    except RemoteProtocolError:  # an ext type the protocol refuses, sent on purpose
        assert exchange["from"] == "client"
    else:
        assert _same(to_tagged(decoded), value)


@pytest.mark.parametrize(("name", "index", "exchange"), EXCHANGES, ids=IDS)
def test_canonical_encoding_gives_the_bytes(name: str, index: int, exchange: Exchange) -> None:
    """(c) Encoding ``value`` as the Python client does gives the bytes, unless marked."""
    if "value" not in exchange:
        return
    body, _ = _body(exchange)
    canonical = exchange.get("canonical", True)
    assert (encode_value(exchange["value"]) == body) is canonical
    if exchange["from"] == "server":
        assert canonical, "the server's frames are canonical"


def test_the_tagged_notation_round_trips_odd_keys() -> None:
    value = {"$bin": b"\x01", "$$x": [1.0, 2, None], "plain": {"$ext": "not a tag"}}
    tagged = to_tagged(value)
    assert tagged == {
        "$$bin": {"$bin": "01"},
        "$$$x": [1.0, 2, None],
        "plain": {"$$ext": "not a tag"},
    }
    assert from_tagged(tagged) == value


def test_every_error_code_has_a_vector() -> None:
    codes = set()
    for _, _, exchange in EXCHANGES:
        value = exchange.get("value")
        if exchange["from"] == "server" and isinstance(value, dict):
            if "error" in value:
                codes.add(value["error"]["code"])
            for slot in value.get("batch") or ():
                if isinstance(slot, dict) and "error" in slot:
                    codes.add(slot["error"]["code"])
    assert codes == {str(code) for code in ErrorCode}


@pytest.fixture(scope="module")
def regenerated() -> dict[str, dict[str, Any]]:
    """Every vector file, generated again from fresh servers."""
    return generate()


@pytest.mark.parametrize("name", FILES)
def test_regenerating_gives_the_committed_file(
    regenerated: dict[str, dict[str, Any]],
    name: str,
) -> None:
    """(b) The same frames, byte for byte, but for the paths a vector says vary."""
    assert _comparable(regenerated[name]) == _comparable(_load(name))


def _comparable(document: dict[str, Any]) -> dict[str, Any]:
    """The document, each varying path masked (and so the bytes of its frame left out)."""
    document = json.loads(json.dumps(document))
    for exchange in document["exchanges"]:
        if exchange.get("varies"):
            exchange["value"] = mask(exchange["value"], exchange["varies"])
            del exchange["hex"]
    return document
