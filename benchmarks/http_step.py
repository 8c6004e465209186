"""What a step costs through the HTTP gateway, against a TCP client step, in one run.

``python benchmarks/http_step.py [--rounds R] [--steps N] [--implementations]`` (needs the
http extra). On the same environment (CartPole, repeat_action 4, the bench's endless
configuration, one zero action over and over), in turns, each round in a rotated order:

- **tcp**: ``rlenv_client.Client.step`` against an ``rlenv serve`` subprocess, on the socket
  (``shared_memory=False``: the baseline, and what the gateway does to reach a session's
  server); **tcp+lane**: the same client through a shared-memory lane (its default on one
  machine);
- **http**: ``POST /v1/envs/{id}/step`` against ``rlenv http TARGET`` (each session's
  environment in an ``rlenv serve`` subprocess of its own), from a minimal raw-socket
  HTTP/1.1 keep-alive client, as a Go or Rust client would send it (``http.client`` alone
  adds 50-80 us per request);
- **ws**: the same gateway's ``WS /v1/envs/{id}/ws``, from a minimal raw-socket WebSocket client;
- **relay**: ``POST .../step`` against ``rlenv http HOST:PORT``, a gateway relaying to a
  running ``rlenv serve`` over TCP;
- with ``--implementations``, the in-process gateway on the other uvicorn implementations
  (the asyncio event loop instead of uvloop, h11 instead of httptools), to see what the
  optional ``httptools`` and ``uvloop`` buy.

It prints microseconds per step (min and median over the rounds) and each variant's ratio to
tcp: the ratio of the two minima, and the min and the median of the per-round ratios.
"""

from __future__ import annotations

import argparse
import base64
import http.client
import json
import os
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Callable

import numpy as np

from rlenv_client import Client, ServerProcess
from rlenv_client.launcher import end_process
from rlenv_tools._bench import ENDLESS

CARTPOLE = "examples.cartpole:CartPoleEnvironment"
STEP_BODY = json.dumps({"action": [0.0], "repeat_action": 4}).encode()


class Gateway:
    """``rlenv http TARGET --port 0`` (or this script's ``--serve``) in a subprocess."""

    def __init__(self, target: str, loop: str = "auto", http_impl: str = "auto") -> None:
        if loop == "auto" and http_impl == "auto":
            command = [sys.executable, "-m", "rlenv", "http", target, "--port", "0"]
        else:
            command = [sys.executable, __file__, "--serve", target, loop, http_impl]
        self.process = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
        line = self.process.stdout.readline()  # type: ignore[union-attr]
        if not line.startswith("listening on http://"):
            self.close()
            raise RuntimeError(f"the gateway did not start: {line!r}")
        host, port = line.strip().removeprefix("listening on http://").rsplit(":", 1)
        self.host, self.port = host, int(port)

    def session(self, env_id: str | None = None) -> str:
        """A new session, configured like the bench's CartPole and reset."""
        connection = http.client.HTTPConnection(self.host, self.port, timeout=30)
        body = {"kwargs": ENDLESS} if env_id is None else {"env_id": env_id, "kwargs": ENDLESS}
        connection.request("POST", "/v1/envs", json.dumps(body))
        answer = connection.getresponse()
        created = json.loads(answer.read())
        if answer.status != 201:
            raise RuntimeError(f"creating a session: {created}")
        connection.request("POST", f"/v1/envs/{created['id']}/reset", b'{"seed": 0}')
        connection.getresponse().read()
        connection.close()
        return created["id"]

    def close(self) -> None:
        end_process(self.process, 10.0)


class RawHTTP:
    """A minimal HTTP/1.1 keep-alive client: one ``sendall`` per request, no parsing beyond
    the status line and Content-Length."""

    def __init__(self, host: str, port: int, path: str, body: bytes) -> None:
        self.sock = socket.create_connection((host, port))
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.request = (
            f"POST {path} HTTP/1.1\r\nHost: {host}:{port}\r\nContent-Type: "
            f"application/json\r\nContent-Length: {len(body)}\r\n\r\n"
        ).encode() + body

    def step(self) -> bytes:
        self.sock.sendall(self.request)
        data = b""
        while True:
            data += self.sock.recv(65536)
            end = data.find(b"\r\n\r\n")
            if end >= 0:
                break
        if not data.startswith(b"HTTP/1.1 200"):
            raise RuntimeError(f"the gateway answered {data[:200]!r}")
        start = data.lower().find(b"content-length:") + len(b"content-length:")
        length = int(data[start : data.find(b"\r\n", start)])
        body = data[end + 4 :]
        while len(body) < length:
            body += self.sock.recv(65536)
        return body

    def close(self) -> None:
        self.sock.close()


class RawWebSocket:
    """A minimal WebSocket client: the handshake, then one masked text frame per step (the
    same message each time, so masked once) and the unmasked answer."""

    def __init__(self, host: str, port: int, path: str, message: bytes) -> None:
        self.sock = socket.create_connection((host, port))
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                "Sec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        answer = b""
        while b"\r\n\r\n" not in answer:
            answer += self.sock.recv(4096)
        if not answer.startswith(b"HTTP/1.1 101"):
            raise RuntimeError(f"the WebSocket was refused: {answer[:200]!r}")
        self.pending = answer[answer.find(b"\r\n\r\n") + 4 :]
        mask = os.urandom(4)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(message))
        length = len(message)
        header = (
            bytes([0x81, 0x80 | length])
            if length < 126
            else bytes([0x81, 0x80 | 126]) + length.to_bytes(2, "big")
        )
        self.frame = header + mask + masked

    def step(self) -> bytes:
        self.sock.sendall(self.frame)
        data = self.pending
        while len(data) < 2:
            data += self.sock.recv(65536)
        length, start = data[1] & 0x7F, 2
        if length == 126:
            while len(data) < 4:
                data += self.sock.recv(65536)
            length, start = int.from_bytes(data[2:4], "big"), 4
        while len(data) < start + length:
            data += self.sock.recv(65536)
        self.pending = data[start + length :]
        return data[start : start + length]

    def close(self) -> None:
        self.sock.close()


def timed(step: Callable[[], object], steps: int) -> float:
    """Microseconds per call of ``step``, over ``steps`` calls."""
    started = time.perf_counter()
    for _ in range(steps):
        step()
    return (time.perf_counter() - started) / steps * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--steps", type=int, default=2000, help="steps per round and variant")
    parser.add_argument(
        "--implementations",
        action="store_true",
        help="also time the gateway on asyncio's loop and on h11",
    )
    args = parser.parse_args()

    closing: list[Callable[[], None]] = []
    try:
        action = np.zeros(1, np.float32)
        variants: dict[str, Callable[[], object]] = {}
        for name, lane in (("tcp", False), ("tcp+lane", None)):
            server = ServerProcess(CARTPOLE)
            closing.append(server.close)
            client = Client(server.host, server.port, timeout=30, shared_memory=lane)
            closing.append(client.close)
            client.configure(**ENDLESS)
            client.reset(seed=0)
            variants[name] = lambda client=client: client.step(action, 4)  # type: ignore[misc]

        def http_variant(name: str, gateway: Gateway) -> str:
            closing.append(gateway.close)
            session = gateway.session()
            client = RawHTTP(gateway.host, gateway.port, f"/v1/envs/{session}/step", STEP_BODY)
            closing.append(client.close)
            variants[name] = client.step
            return session

        gateway = Gateway(CARTPOLE)
        http_variant("http", gateway)
        socket_session = gateway.session()
        websocket = RawWebSocket(
            gateway.host,
            gateway.port,
            f"/v1/envs/{socket_session}/ws",
            json.dumps({"type": "step", **json.loads(STEP_BODY)}).encode(),
        )
        closing.append(websocket.close)
        variants["ws"] = websocket.step
        relayed = ServerProcess(CARTPOLE)
        closing.append(relayed.close)
        http_variant("relay", Gateway(relayed.address))
        if args.implementations:
            http_variant("http asyncio+httptools", Gateway(CARTPOLE, "asyncio", "httptools"))
            http_variant("http uvloop+h11", Gateway(CARTPOLE, "uvloop", "h11"))
            http_variant("http asyncio+h11", Gateway(CARTPOLE, "asyncio", "h11"))

        for step in variants.values():  # warm up: caches, branch predictors, the JIT-less rest
            timed(step, 200)
        times: dict[str, list[float]] = {name: [] for name in variants}
        names = list(variants)
        for round_index in range(args.rounds):
            shift = round_index % len(names)
            for name in names[shift:] + names[:shift]:
                times[name].append(timed(variants[name], args.steps))
            print(
                f"round {round_index + 1}: "
                + ", ".join(f"{name} {times[name][-1]:.0f}" for name in names),
                file=sys.stderr,
                flush=True,
            )
    finally:
        for close in reversed(closing):
            close()

    print(
        f"{'variant':<26}{'min us':>9}{'median us':>11}{'min/min':>9}{'ratio min':>11}"
        f"{'ratio median':>14}"
    )
    for name in names:
        ratios = [mine / base for mine, base in zip(times[name], times["tcp"], strict=True)]
        print(
            f"{name:<26}{min(times[name]):>9.1f}{statistics.median(times[name]):>11.1f}"
            f"{min(times[name]) / min(times['tcp']):>9.2f}{min(ratios):>11.2f}"
            f"{statistics.median(ratios):>14.2f}"
        )


def serve_variant(target: str, loop: str, http_impl: str) -> None:
    """``rlenv http TARGET --port 0`` on the given uvicorn loop and HTTP implementation."""
    from rlenv_tools.http.app import Settings, serve

    serve(
        Settings(target=target, port=0),
        loop=loop,
        http=http_impl,
        ready=lambda url: print(f"listening on {url}", flush=True),
    )


if __name__ == "__main__":
    if sys.argv[1:2] == ["--serve"]:
        serve_variant(*sys.argv[2:5])
    else:
        main()
