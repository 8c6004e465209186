"""Test support for the HTTP gateway: ``rlenv http`` in a subprocess, and plain HTTP requests.

Requests go through the standard library's ``http.client`` (any method, body and headers,
``Host`` included), so the tests see exactly what a client in another language would.
"""

from __future__ import annotations

import http.client
import json
import os
import signal
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from typing import Any

import numpy as np

from rlenv_client.launcher import end_process

SHUTDOWN_SECONDS = 10.0
"""SIGTERM must end the gateway within this."""


class Reply:
    """A status, the headers (names in lower case) and the body."""

    def __init__(self, status: int, headers: dict[str, str], body: bytes) -> None:
        self.status, self.headers, self.body = status, headers, body

    def json(self) -> Any:
        return json.loads(self.body)

    @property
    def content_type(self) -> str:
        return self.headers.get("content-type", "")

    def __repr__(self) -> str:
        return f"Reply({self.status}, {self.content_type}, {self.body[:300]!r})"


class Gateway:
    """``rlenv http ARGS --port 0``, reading the address it prints; :meth:`close` ends it.

    ``$RLENV_TOKEN`` is left out of its environment unless ``env`` sets it.
    """

    def __init__(self, *args: str, env: dict[str, str] | None = None) -> None:
        self.opened: list[str] = []  # sessions made by session(), for close_sessions
        self._stderr = tempfile.TemporaryFile()
        self.process = subprocess.Popen(
            [sys.executable, "-m", "rlenv", "http", *args, "--port", "0"],
            stdout=subprocess.PIPE,
            stderr=self._stderr,
            text=True,
            env={**{k: v for k, v in os.environ.items() if k != "RLENV_TOKEN"}, **(env or {})},
        )
        line = self.process.stdout.readline()  # type: ignore[union-attr]
        if not line.startswith("listening on http://"):
            end_process(self.process, 0.0, first=None)
            raise RuntimeError(f"the gateway did not start ({line!r}): {self.stderr()}")
        self.url = line.strip().removeprefix("listening on ")
        host, port = self.url.removeprefix("http://").rsplit(":", 1)
        self.host, self.port = host, int(port)

    def stderr(self) -> str:
        self._stderr.seek(0)
        return self._stderr.read().decode(errors="replace")

    def request(
        self,
        method: str,
        path: str,
        body: Any = None,
        *,
        headers: dict[str, str] | None = None,
        raw: bytes | None = None,
        timeout: float = 30.0,
    ) -> Reply:
        """``method path`` with ``body`` as JSON (or ``raw`` bytes as they are)."""
        connection = http.client.HTTPConnection(self.host, self.port, timeout=timeout)
        try:
            data = raw if raw is not None else None if body is None else json.dumps(body)
            connection.request(method, path, data, headers=headers or {})
            answer = connection.getresponse()
            return Reply(
                answer.status, {k.lower(): v for k, v in answer.getheaders()}, answer.read()
            )
        finally:
            connection.close()

    def session(self, env_id: str | None = None, **kwargs: Any) -> str:
        """A new session's id."""
        body: dict[str, Any] = {} if env_id is None else {"env_id": env_id}
        if kwargs:
            body["kwargs"] = kwargs
        reply = self.request("POST", "/v1/envs", body)
        assert reply.status == 201, reply
        self.opened.append(reply.json()["id"])
        return self.opened[-1]

    def close_sessions(self) -> None:
        """Delete the sessions :meth:`session` opened that are still there."""
        while self.opened:
            status = self.request("DELETE", f"/v1/envs/{self.opened.pop()}").status
            assert status in (204, 404), status

    def post(self, path: str, body: Any = None, expect: int = 200) -> Any:
        """POST, check the status, return the JSON answer."""
        reply = self.request("POST", path, body)
        assert reply.status == expect, reply
        return reply.json() if reply.body else None

    def get(self, path: str, expect: int = 200) -> Any:
        """GET, check the status, return the JSON answer."""
        reply = self.request("GET", path)
        assert reply.status == expect, reply
        return reply.json()

    def close(self) -> float:
        """SIGTERM; returns how long it took to exit (killed, and failing, past the limit)."""
        if self.process.poll() is not None:
            return 0.0
        started = time.monotonic()
        try:
            if end_process(self.process, SHUTDOWN_SECONDS) == -signal.SIGKILL:
                raise AssertionError(
                    f"SIGTERM did not end the gateway in {SHUTDOWN_SECONDS} s: {self.stderr()}"
                )
        finally:
            self.process.stdout.close()  # type: ignore[union-attr]
            self._stderr.close()
        return time.monotonic() - started


def assert_problem(reply: Reply, status: int, code: str) -> dict[str, Any]:
    """``reply`` is an RFC 9457 problem of this status and code; returns its body."""
    assert reply.status == status, reply
    assert reply.content_type == "application/problem+json", reply
    problem = reply.json()
    assert {"type", "title", "status", "detail", "code"} <= problem.keys(), problem
    assert problem["status"] == status and problem["code"] == code, problem
    assert problem["type"] == f"urn:rlenv:problem:{code}" and problem["detail"], problem
    return problem


def assert_same_observation(wire: Any, expected: Any) -> None:
    """A JSON observation is gymnasium's float32 one, bit for bit (keyed by agent or not).

    float32 -> JSON -> float32 is exact: the gateway writes each value's shortest repr.
    """
    if isinstance(expected, dict):
        assert isinstance(wire, dict) and wire.keys() == expected.keys(), (wire, expected)
        for name in expected:
            assert_same_observation(wire[name], expected[name])
        return
    assert expected.dtype == np.float32, expected
    assert np.array_equal(np.asarray(wire, dtype=np.float32), expected), (wire, expected)


def decode_png(data: bytes) -> np.ndarray:
    """The pixels of a PNG written with filter type 0 (as the gateway writes them)."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    position, chunks, idat = 8, {}, b""
    while position < len(data):
        length, kind = struct.unpack(">I4s", data[position : position + 8])
        body = data[position + 8 : position + 8 + length]
        (crc,) = struct.unpack(">I", data[position + 8 + length : position + 12 + length])
        assert crc == zlib.crc32(kind + body), kind
        chunks[kind] = body
        if kind == b"IDAT":
            idat += body
        position += 12 + length
    width, height, depth, color = struct.unpack(">IIBB", chunks[b"IHDR"][:10])
    assert depth == 8 and b"IEND" in chunks
    channels = {0: 1, 4: 2, 2: 3, 6: 4}[color]
    rows = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(height, 1 + width * channels)
    assert (rows[:, 0] == 0).all()
    return rows[:, 1:].reshape(height, width, channels)
