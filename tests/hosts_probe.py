"""The client side of ``test_hosts.py``: run on the other host (``ip netns exec B python ...``).

``python tests/hosts_probe.py MODE HOST PORT TOKEN [ARG...]`` prints one JSON line saying what
the server at ``HOST:PORT`` did. ``TOKEN`` is the server's right token: after every probe but
``connect``, a well-behaved client presents it, resets and steps CartPole (``"afterwards"``), so
each refusal is followed by proof that the server still serves.

Modes:

- ``client [SENT]``: :class:`rlenv_client.Client` with token ``SENT`` (``-``: none), then reset
  and step; a refusal is reported as the :class:`~rlenv.protocol.errors.RemoteError`'s fields.
- ``request SENT``: raw TCP: read the hello, send a reset request carrying token ``SENT``
  (``-``: none), read the reply and whether the server then closed the connection.
- ``non-request-token``: raw TCP: send a map carrying the right token but no ``id`` (not a
  request, so it must not authenticate), then a reset request without a token.
- ``prefix SIZE``: raw TCP: send only a length prefix of ``SIZE`` bytes before any token.
- ``after-auth SIZE``: raw TCP: authenticate, then send a request frame of more than ``SIZE``
  bytes (its padding is a second token, which the server ignores once authenticated).
- ``connect ADDRESS...``: try a TCP connection to each ``HOST:PORT``; report each outcome.

The raw modes frame messages by hand (a 4-byte big-endian length, then msgpack), sharing no
code with the client library.
"""

from __future__ import annotations

import json
import socket
import struct
import sys
from typing import Any

import msgpack
import numpy as np

from rlenv.protocol.errors import RemoteError
from rlenv_client import Client

TIMEOUT = 5.0
"""Seconds to wait for connecting and for each answer."""
_HEADER = struct.Struct(">I")


def serve_cartpole(host: str, port: int, token: str | None) -> dict[str, Any]:
    """Connect with ``token``, reset and step CartPole; what happened, as JSON-ready data."""
    try:
        with Client(host, port, timeout=TIMEOUT, token=token) as client:
            observation, _ = client.reset(seed=0)
            after, reward, terminated, truncated, info = client.step(np.array([0.5], np.float32))
    except RemoteError as error:
        return {
            "refused": {"code": str(error.code), "message": error.message, "fatal": error.fatal}
        }
    return {
        "observation": np.asarray(observation).tolist(),
        "stepped": np.asarray(after).tolist(),
        "reward": float(reward),
        "terminated": bool(terminated),
        "truncated": bool(truncated),
        "frames": int(info["frames"]),
    }


def _receive_exactly(sock: socket.socket, size: int) -> bytes | None:
    data = bytearray()
    while len(data) < size:
        chunk = sock.recv(size - len(data))
        if not chunk:
            return None
        data += chunk
    return bytes(data)


def receive(sock: socket.socket) -> dict[str, Any] | None:
    """The next frame's map, or ``None`` if the server closed the connection first."""
    header = _receive_exactly(sock, _HEADER.size)
    if header is None:
        return None
    body = _receive_exactly(sock, _HEADER.unpack(header)[0])
    if body is None:
        return None
    message = msgpack.unpackb(body, raw=False, strict_map_key=False)
    assert isinstance(message, dict), message
    return message


def send(sock: socket.socket, message: dict[str, Any]) -> int:
    """Frame and send ``message``; returns the frame body's size."""
    body = msgpack.packb(message, use_bin_type=True)
    sock.sendall(_HEADER.pack(len(body)) + body)
    return len(body)


def summary(reply: dict[str, Any] | None) -> dict[str, Any] | None:
    """The JSON-ready gist of a reply: its id and its error (``None`` for a response)."""
    if reply is None:
        return None
    if "error" in reply:
        error = reply["error"]
        return {
            "id": reply.get("id"),
            "error": {key: error.get(key) for key in ("code", "message", "fatal")},
        }
    return {"id": reply.get("id"), "error": None}


def closed_by_server(sock: socket.socket) -> bool:
    """Whether the server closes the connection (within :data:`TIMEOUT`) with nothing more."""
    try:
        return sock.recv(1) == b""
    except TimeoutError:
        return False
    except ConnectionResetError:
        return True


def raw(host: str, port: int, mode: str, args: list[str], token: str) -> dict[str, Any]:
    """Run one raw-TCP probe ``mode`` (see the module docstring)."""
    with socket.create_connection((host, port), TIMEOUT) as sock:
        sock.settimeout(TIMEOUT)
        hello = receive(sock)
        assert hello is not None and "hello" in hello, hello
        result: dict[str, Any] = {
            "hello": {
                "token_required": hello["hello"].get("token_required"),
                "max_first_frame_size": hello["hello"]["limits"]["max_first_frame_size"],
                "max_frame_size": hello["hello"]["limits"]["max_frame_size"],
            }
        }
        if mode == "request":
            request: dict[str, Any] = {"id": 1, "reset": {"seed": 0}}
            if args[0] != "-":
                request["token"] = args[0]
            send(sock, request)
            result["reply"] = summary(receive(sock))
        elif mode == "non-request-token":
            send(sock, {"token": token, "reset": {"seed": 0}})
            result["first"] = summary(receive(sock))
            send(sock, {"id": 2, "reset": {"seed": 0}})
            result["reply"] = summary(receive(sock))
        elif mode == "prefix":
            sock.sendall(_HEADER.pack(int(args[0])))
            result["reply"] = summary(receive(sock))
        elif mode == "after-auth":
            send(sock, {"id": 1, "token": token})
            result["first"] = summary(receive(sock))
            result["size"] = send(sock, {"id": 2, "token": "x" * (int(args[0]) + 1)})
            result["reply"] = summary(receive(sock))
            return result  # the connection stays open
        else:
            raise SystemExit(f"unknown mode {mode!r}")
        result["closed"] = closed_by_server(sock)
    return result


def connect(address: str) -> str:
    """``connected``, ``refused``, or the name of the error connecting to ``HOST:PORT``."""
    host, _, port = address.rpartition(":")
    try:
        with socket.create_connection((host, int(port)), TIMEOUT):
            return "connected"
    except ConnectionRefusedError:
        return "refused"
    except OSError as error:
        return f"{type(error).__name__}: {error}"


def main(argv: list[str]) -> dict[str, Any]:
    """Run the probe ``argv`` asks for; see the module docstring."""
    mode = argv[0]
    if mode == "connect":
        return {"connect": {address: connect(address) for address in argv[1:]}}
    host, port, token, args = argv[1], int(argv[2]), argv[3], argv[4:]
    if mode == "client":
        result = {"client": serve_cartpole(host, port, None if args[0] == "-" else args[0])}
    else:
        result = raw(host, port, mode, args, token)
    result["afterwards"] = serve_cartpole(host, port, token)
    return result


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1:])), flush=True)
