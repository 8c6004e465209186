"""Remote step rate against the floor: a bare msgpack ping-pong over loopback, same run.

    .venv/bin/python benchmarks/step_rate.py [--steps N]

The baseline is a Python echo server in a subprocess answering 4-byte-length-prefixed msgpack
frames as large as CartPole's request and response; the figure under test is
``Client.step`` against ``rlenv serve examples.cartpole:CartPoleEnvironment`` (termination
limits lifted so that no reset interrupts the measurement). Each figure is the median of five
rounds.
"""

from __future__ import annotations

import argparse
import socket
import statistics
import struct
import subprocess
import sys
import time

import msgpack
import numpy as np

from examples.cartpole import TARGET
from rlenv.protocol import pack
from rlenv_client import Client, ServerProcess

ECHO_SERVER = """
import socket, struct, sys
listener = socket.create_server(("127.0.0.1", 0))
print(listener.getsockname()[1], flush=True)
conn, _ = listener.accept()
conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
reply = bytes.fromhex(sys.argv[1])
def recv_exactly(n):
    data = b""
    while len(data) < n:
        chunk = conn.recv(n - len(data))
        if not chunk:
            raise SystemExit
        data += chunk
    return data
while True:
    size = struct.unpack(">I", recv_exactly(4))[0]
    recv_exactly(size)
    conn.sendall(reply)
"""

ROUNDS = 5


def frame(message: object) -> bytes:
    body = pack(message)
    return struct.pack(">I", len(body)) + body


def ping_pong_rate(steps: int) -> float:
    """Round trips per second of a bare msgpack request/response over loopback."""
    request = frame({"id": 1, "action": np.zeros(1, np.float32), "observation": {"agent": {}}})
    response = frame({"id": 1, "observation": {"agent": np.zeros(5, np.float32)}, "reward": 1.0,
                      "terminated": False, "truncated": False, "info": {}, "frames": 4})
    echo = subprocess.Popen([sys.executable, "-c", ECHO_SERVER, response.hex()],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert echo.stdout is not None
        port = int(echo.stdout.readline())
        with socket.create_connection(("127.0.0.1", port)) as sock:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            rates = []
            for _ in range(ROUNDS):
                start = time.perf_counter()
                for _ in range(steps):
                    sock.sendall(request)
                    size = struct.unpack(">I", sock.recv(4))[0]
                    body = sock.recv(size)
                    msgpack.unpackb(body)
                rates.append(steps / (time.perf_counter() - start))
        return statistics.median(rates)
    finally:
        echo.kill()
        echo.wait()


def step_rate(client: Client, steps: int, repeat: int) -> float:
    """Client.step calls per second at ``repeat`` physics ticks per action."""
    action = np.zeros(1, np.float32)
    client.reset(seed=0)
    rates = []
    for _ in range(ROUNDS):
        start = time.perf_counter()
        for _ in range(steps):
            client.step(action, repeat)
        rates.append(steps / (time.perf_counter() - start))
    return statistics.median(rates)


def progress(message: str) -> None:
    """Say on stderr what is being measured (the table goes to stdout)."""
    print(f"... {message} ({ROUNDS} rounds)", file=sys.stderr, flush=True)


def main() -> None:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=4000, help="steps per round")
    args = parser.parse_args()
    progress("measuring the msgpack ping-pong baseline")
    baseline = ping_pong_rate(args.steps)
    rows = [("msgpack ping-pong over loopback (baseline)", baseline)]
    with ServerProcess(TARGET) as server, Client(server.host, server.port) as client:
        client.configure(world={"track_limit": 1e9}, agent={"angle_limit": 1e9})
        for repeat in (1, 4):
            progress(f"measuring Client.step at repeat_action={repeat}")
            rows.append((f"Client.step, CartPole, repeat_action={repeat}",
                         step_rate(client, args.steps, repeat)))
    print(f"{'measurement':<48}{'steps/s':>10}{'us/step':>10}{'x baseline':>12}")
    for name, rate in rows:
        print(f"{name:<48}{rate:>10.0f}{1e6 / rate:>10.1f}{rate / baseline:>12.2f}")


if __name__ == "__main__":
    main()
