"""``rlenv bench``: rlenv's figures, each beside a baseline measured in the same run.

Every figure is the median of several rounds and is printed with its baseline and the ratio.
A figure's rounds take turns with its baseline's (after a warm-up round each), so that both are
measured under the same conditions however the machine's speed drifts during the run:

- (r) the hand-written CartPole server (``examples.handwritten``: the same pymunk CartPole, a
  blocking socket loop, ``msgpack``) driven by a raw client at repeat_action 4, against (a):
  the floor of a remote step, doing the same work as rlenv's CartPole and nothing more;
- (a) a bare msgpack request/response over loopback (a Python echo server; arrays as raw
  bytes);
- (b) in-process CartPole steps (no socket) against (a);
- (c) remote ``Client.step`` on CartPole at repeat_action 4 against (r), and at 1 against (a):
  through a shared-memory lane (the default on one machine), and on the socket alone
  (``shared_memory=False``) against (r) and against the lane;
- (d) an 84x84x3 uint8 observation (``examples.pixels``) against a ping-pong carrying the same
  bytes;
- (e) ``RemoteVectorEnv`` throughput by number of environments and servers (the instances of
  a server stepped by one ``steps`` request, in columns), against (f);
- (f) gymnasium's ``AsyncVectorEnv`` with 8 ``CartPole-v1`` on the same machine (and 64
  CartPoles in this process, ``in_process=True``, against it too);
- (i) ``gymnasium.make_vec("rlenv/CartPole-v0", num_envs=64)`` with its default options (the
  default layout and repeat_action 4, episodes ending and autoresetting) on random actions,
  against (f), and against (j): the hand-written servers (``python -m examples.handwritten 32``,
  one per core, a raw client sending every server its column of actions and reset flags) doing
  the same work: the floor of a vector step; and the same ``make_vec`` on sockets alone
  (``shared_memory=False``), against the lanes;
- (g) p50 / p99 latency of a remote step against the ping-pong's;
- (h) memory of one server process, and per extra environment instance in one process.

Progress goes to stderr, the table to stdout, and everything to JSON with ``--json PATH``.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import json
import logging
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import msgpack
import numpy as np

from rlenv.protocol.codec import HEADER
from rlenv.targets import module_name
from rlenv.transport import _procfs as procfs
from rlenv_client.launcher import end_process

__all__ = [
    "Figure",
    "HandWrittenServer",
    "HandWrittenVector",
    "Rate",
    "format_table",
    "interleaved",
    "random_steps",
    "random_steps_of",
    "run_benchmarks",
    "to_json",
]

logger = logging.getLogger(__name__)

CARTPOLE = "rlenv.examples.cartpole:CartPoleEnvironment"
PIXELS = "rlenv.examples.pixels:PixelsEnvironment"
HAND_WRITTEN = "rlenv.examples.handwritten"
"""The module of the hand-written CartPole server (run with ``python -m`` under its name here:
``examples.handwritten`` in a checkout, :func:`rlenv.targets.module_name`)."""
ENDLESS = {"world": {"track_limit": 1e9}, "agent": {"angle_limit": 1e9}}
"""CartPole's configuration for the bench: one episode for the whole run, no resets."""
_ASYNC_CARTPOLES = "AsyncVectorEnv(8) CartPole-v1"
"""The vector figures' baseline (f), as the table names it."""

_ECHO_SERVER = """
# The floor: a server of a few lines of Python, run by "python -c", that imports nothing of
# rlenv (its frames are the codec's: a 4-byte big-endian length, then the body).
import socket, struct, sys
listener = socket.create_server(("127.0.0.1", 0))
sys.stdout.write(str(listener.getsockname()[1]) + chr(10))
sys.stdout.flush()
conn, _ = listener.accept()
conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
reply = sys.stdin.buffer.read()
def recv_exactly(n):
    data = b""
    while len(data) < n:
        chunk = conn.recv(min(n - len(data), 65536))
        if not chunk:
            raise SystemExit
        data += chunk
    return data
while True:
    size = struct.unpack(">I", recv_exactly(4))[0]
    recv_exactly(size)
    conn.sendall(reply)
"""


@dataclass(frozen=True)
class Figure:
    """One measurement with its baseline: ``value`` and ``baseline`` in the same ``unit``."""

    name: str
    value: float
    unit: str
    baseline_name: str = ""
    baseline: float | None = None

    @property
    def ratio(self) -> float | None:
        """``value / baseline`` (higher is better for rates)."""
        return None if not self.baseline else self.value / self.baseline


class Rate:
    """One thing to measure: ``run(steps)`` does ``steps`` units of work (calls, env-steps...).

    Args:
        run: does the work.
        steps: units per round.
        scale: units counted per step (e.g. sub-environments per vector step).
        name: what progress reports call it.
        warmup: units of its warm-up round (default: ``steps``).

    Attributes:
        rates: units per second, one per timed round.
    """

    def __init__(
        self,
        run: Callable[[int], None],
        steps: int,
        scale: int = 1,
        name: str = "",
        warmup: int | None = None,
    ) -> None:
        self.run, self.steps, self.scale, self.name = run, steps, scale, name
        self.warmup = steps if warmup is None else warmup
        self.rates: list[float] = []

    def round(self) -> None:
        """Time one round; its rate goes into :attr:`rates`."""
        start = time.perf_counter()
        self.run(self.steps)
        self.rates.append(self.steps * self.scale / (time.perf_counter() - start))

    @property
    def median(self) -> float:
        """The median of :attr:`rates`."""
        return statistics.median(self.rates)


def interleaved(
    rounds: int, *measures: Rate, progress: Callable[[str], None] | None = None
) -> list[float]:
    """The median rate of each measure, their rounds taken in turn after one warm-up round.

    Taking turns puts a figure and its baseline under the same conditions, however the
    machine's speed drifts during the run (shared virtual machines drift a lot). ``progress``
    is told each round's rates.
    """
    for measure in measures:
        measure.run(measure.warmup)
    for number in range(rounds):
        for measure in measures:
            measure.round()
        if progress is not None:
            progress(
                f"round {number + 1}/{rounds}: "
                + ", ".join(f"{measure.name} {measure.rates[-1]:,.0f}" for measure in measures)
            )
    return [measure.median for measure in measures]


def _calls(
    call: Callable[[], object],
    latencies: list[float] | None = None,
) -> Callable[[int], None]:
    """``run(n)`` calling ``call`` n times; each call's duration into ``latencies`` if given."""

    def run(n: int) -> None:
        for _ in range(n):
            started = time.perf_counter()
            call()
            if latencies is not None:
                latencies.append(time.perf_counter() - started)

    return run


def _frame(message: object) -> bytes:
    """``message`` packed by msgpack, behind the codec's 4-byte length (:data:`HEADER`)."""
    body = msgpack.packb(message)
    return HEADER.pack(len(body)) + body


def _receive_frame(sock: socket.socket) -> bytes:
    """The body of the next frame on ``sock``: recv until the whole frame is in.

    The hand-written client's reader, not :func:`rlenv.transport.frames.receive_frame`: it does
    what any client must and no more, one ``recv`` for a whole answer (that one reads the
    length first, a second ``recv`` per answer on the floor the figures are measured against).
    It reads nothing beyond the answer because the hand-written server sends nothing unasked.
    """
    data = sock.recv(65536)
    while len(data) < HEADER.size or len(data) < HEADER.size + HEADER.unpack_from(data)[0]:
        chunk = sock.recv(65536)
        if not chunk:
            raise ConnectionError("the server closed the connection")
        data += chunk
    return data[HEADER.size :]


class _PingPong:
    """A Python echo server answering every frame with a fixed reply (the floor)."""

    def __init__(self, reply: bytes) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-c", _ECHO_SERVER], stdin=subprocess.PIPE, stdout=subprocess.PIPE
        )
        assert self.process.stdin is not None and self.process.stdout is not None
        port = int(self.process.stdout.readline())
        self.process.stdin.write(reply)
        self.process.stdin.close()
        self.sock = socket.create_connection(("127.0.0.1", port))
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.reply_size = len(reply) - HEADER.size

    def round_trip(self, request: bytes) -> None:
        self.sock.sendall(request)
        data = self.sock.recv(65536)
        while len(data) < self.reply_size + HEADER.size:
            data += self.sock.recv(65536)
        msgpack.unpackb(data[HEADER.size :])

    def close(self) -> None:
        self.sock.close()
        end_process(self.process, 0.0, first=None)

    def __enter__(self) -> _PingPong:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class HandWrittenServer:
    """The hand-written CartPole server in a subprocess, and a raw client to it.

    The client does what any client must and no more: pack the request, one ``sendall``,
    receive the whole answer, unpack it, copy the observation out of its bytes.
    """

    def __init__(self, instances: int = 1) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-m", module_name(HAND_WRITTEN), str(instances)],
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            assert self.process.stdout is not None
            line = self.process.stdout.readline()
            if not line.startswith("listening on "):
                raise RuntimeError(f"{HAND_WRITTEN} did not start: {line!r}")
            host, _, port = line.removeprefix("listening on ").strip().rpartition(":")
            self.sock = socket.create_connection((host, int(port)))
        except BaseException:
            end_process(self.process, 0.0, first=None)
            raise
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.ids = itertools.count(1)

    def call(self, request: dict[str, Any]) -> dict[str, Any]:
        """Send ``request`` (its ``id`` added) and return the answer."""
        self.sock.sendall(_frame({"id": next(self.ids), **request}))
        return msgpack.unpackb(_receive_frame(self.sock))

    def step(self, action: np.ndarray, repeat_action: int = 4) -> tuple[Any, ...]:
        """One step: ``(observation, reward, terminated, truncated, info)``."""
        reply = self.call({"action": action.tobytes(), "repeat_action": repeat_action})
        observation = np.frombuffer(reply["observation"], np.float32).copy()
        return observation, reply["reward"], reply["terminated"], reply["truncated"], reply["info"]

    def close(self) -> None:
        """Close the connection and stop the server."""
        self.sock.close()
        end_process(self.process, 0.0, first=None)

    def __enter__(self) -> HandWrittenServer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class HandWrittenVector:
    """``servers`` hand-written servers of ``instances`` CartPoles each, stepped in columns.

    What a vector of hand-written servers does and no more: send every server its actions and
    reset flags, then gather the observations into one batch; a CartPole whose pole fell is
    reset on its next step (gymnasium's ``NEXT_STEP`` autoreset). The floor of ``rlenv bench``
    and ``benchmarks/vector_speed.py``.
    """

    def __init__(self, servers: int, instances: int) -> None:
        self.instances = instances
        self.servers: list[HandWrittenServer] = []
        try:
            for _ in range(servers):
                self.servers.append(HandWrittenServer(instances))
        except BaseException:
            self.close()
            raise
        self.resets = [[False] * instances for _ in self.servers]
        self.observations = np.zeros((servers * instances, 5), np.float32)

    def step(self, actions: np.ndarray) -> None:
        """One vector step of ``actions`` (one float32 per CartPole)."""
        count = self.instances
        for index, server in enumerate(self.servers):
            server.sock.sendall(
                _frame(
                    {
                        "id": 1,
                        "action": actions[index * count : (index + 1) * count].tobytes(),
                        "reset": self.resets[index],
                        "repeat_action": 4,
                    }
                )
            )
        for index, server in enumerate(self.servers):
            reply = msgpack.unpackb(_receive_frame(server.sock))
            self.observations[index * count : (index + 1) * count] = np.frombuffer(
                reply["observation"], np.float32
            ).reshape(count, 5)
            self.resets[index] = [bool(fell) for fell in reply["terminated"]]

    def close(self) -> None:
        """Stop every server."""
        for server in self.servers:
            server.close()


def _step_request(action: np.ndarray | int) -> bytes:
    """A step request as rlenv's client sends one; arrays as raw bytes."""
    wire = action.tobytes() if isinstance(action, np.ndarray) else action
    return _frame({"id": 1, "action": wire, "observation": {"agent": {}}})


def _step_reply(observation: np.ndarray) -> bytes:
    """A step answer as rlenv's server sends one, the observation as raw bytes."""
    return _frame(
        {
            "id": 1,
            "observation": {"agent": observation.tobytes()},
            "reward": 1.0,
            "terminated": False,
            "truncated": False,
            "info": {},
            "frames": 4,
        }
    )


def _rss_kib(pid: int) -> int:
    rss = procfs.status_kib(pid, "VmRSS")
    if rss is None:
        raise RuntimeError("no VmRSS")
    return rss


def run_benchmarks(
    rounds: int = 5,
    steps: int = 2000,
    quick: bool = False,
    progress: Callable[[str], None] = logger.info,
) -> list[Figure]:
    """Measure every figure (see the module docstring).

    Args:
        rounds: rounds per figure; the median is kept.
        steps: steps per round.
        quick: fewer vector layouts.
        progress: told what is being measured, before each figure.
    """
    progress(
        "(a, b, c, g) ping-pong, (r) hand-written server, in-process and remote CartPole "
        "steps, in turns"
    )
    figures, cartpole_rss = _single_steps(rounds, steps)
    progress("(d) 84x84x3 uint8 observations and a ping-pong of the same bytes, in turns")
    figures.append(_image_steps(rounds, steps // 2))
    progress("(e, f, i) RemoteVectorEnv layouts, make_vec and gymnasium's AsyncVectorEnv, in turns")
    figures += _vectors(rounds, steps, quick)
    progress("(h) memory")
    figures.append(Figure("one CartPole server process, resident", cartpole_rss / 1024, "MiB"))
    figures.append(Figure("one more CartPole instance in a process", _instance_kib(), "KiB"))
    return figures


def _single_steps(rounds: int, steps: int) -> tuple[list[Figure], int]:
    """Figures (r, a, b, c, g), and the CartPole server's resident KiB."""
    from rlenv_client import Client, LocalClient, ServerProcess

    action = np.zeros(1, np.float32)
    pong_latencies: list[float] = []
    step_latencies: list[float] = []
    with (
        _PingPong(_step_reply(np.zeros(5, np.float32))) as echo,
        HandWrittenServer() as raw,
        LocalClient(CARTPOLE) as local,
        ServerProcess(CARTPOLE) as server,
        Client(server.host, server.port) as client,
        ServerProcess(CARTPOLE) as other,
        Client(other.host, other.port, shared_memory=False) as socket_client,
    ):
        request = _step_request(action)
        raw.call({"config": ENDLESS, "reset": {"seed": 0}})
        for each in (local, client, socket_client):
            each.configure(**ENDLESS)
            each.reset(seed=0)
        floor, hand_written, local_rate, remote_1, remote_4, socket_4 = interleaved(
            rounds,
            Rate(_calls(lambda: echo.round_trip(request), pong_latencies), steps),
            Rate(_calls(lambda: raw.step(action, 4)), steps),
            Rate(_calls(lambda: local.step(action, 4)), steps),
            Rate(_calls(lambda: client.step(action, 1)), steps),
            Rate(_calls(lambda: client.step(action, 4), step_latencies), steps),
            Rate(_calls(lambda: socket_client.step(action, 4)), steps),
        )
        cartpole_rss = _rss_kib(server.pid)
    pong = "msgpack ping-pong"
    figures = [
        Figure(
            "hand-written CartPole server, raw client (repeat 4)",
            hand_written,
            "steps/s",
            pong,
            floor,
        ),
        Figure("msgpack ping-pong over loopback", floor, "round trips/s"),
        Figure("in-process CartPole step (repeat 4)", local_rate, "steps/s", pong, floor),
        Figure("remote CartPole Client.step (repeat 1)", remote_1, "steps/s", pong, floor),
        Figure(
            "remote CartPole Client.step (repeat 4)",
            remote_4,
            "steps/s",
            "hand-written server (repeat 4)",
            hand_written,
        ),
        Figure(
            "remote CartPole Client.step on the socket alone (repeat 4)",
            socket_4,
            "steps/s",
            "hand-written server (repeat 4)",
            hand_written,
        ),
        Figure(
            "Client.step through shared memory against the socket",
            remote_4,
            "steps/s",
            "the socket alone",
            socket_4,
        ),
    ]
    for quantile in (50, 99):
        mine = float(np.percentile(step_latencies, quantile)) * 1e6
        theirs = float(np.percentile(pong_latencies, quantile)) * 1e6
        figures.append(
            Figure(
                f"p{quantile} remote step latency (repeat 4)",
                mine,
                "us",
                f"p{quantile} ping-pong",
                theirs,
            )
        )
    return figures, cartpole_rss


def _image_steps(rounds: int, steps: int) -> Figure:
    """Figure (d)."""
    from rlenv_client import Client, ServerProcess

    image = np.zeros((84, 84, 3), np.uint8)
    with (
        _PingPong(_step_reply(image)) as echo,
        ServerProcess(PIXELS) as server,
        Client(server.host, server.port) as client,
    ):
        client.reset(seed=0)
        request = _step_request(0)
        image_floor, rate = interleaved(
            rounds,
            Rate(_calls(lambda: echo.round_trip(request)), steps),
            Rate(_calls(lambda: client.step(0, 1)), steps),
        )
    return Figure(
        "remote 84x84x3 observation step",
        rate,
        "steps/s",
        "ping-pong carrying the same bytes",
        image_floor,
    )


def _vectors(rounds: int, steps: int, quick: bool) -> list[Figure]:
    """Figures (e, f, i, j): make_vec and its floor first, alone with AsyncVectorEnv."""
    return _made_vectors(rounds, steps) + _vector_layouts(rounds, steps, quick)


def _async_cartpoles(stack: contextlib.ExitStack) -> Any:
    """The baseline (f): gymnasium's AsyncVectorEnv of 8 CartPole-v1, closed by ``stack``."""
    import gymnasium

    envs = gymnasium.vector.AsyncVectorEnv([lambda: gymnasium.make("CartPole-v1")] * 8)
    stack.callback(envs.close)
    return envs


def _made_vectors(rounds: int, steps: int) -> list[Figure]:
    """Figures (f, i, j): AsyncVectorEnv; make_vec on lanes, on sockets, and its floor."""
    import gymnasium

    from rlenv_client.vector_servers import default_layout

    layout = default_layout(64)
    floor_name = f"hand-written {len(layout)} servers x {layout[0]} CartPoles"
    batches = max(steps // 16, 50)  # vector steps per round: enough for episodes to end
    with contextlib.ExitStack() as stack:
        async_envs = _async_cartpoles(stack)
        made = gymnasium.make_vec("rlenv/CartPole-v0", num_envs=64)
        stack.callback(made.close)
        on_sockets = gymnasium.make_vec("rlenv/CartPole-v0", num_envs=64, shared_memory=False)
        stack.callback(on_sockets.close)
        floor = HandWrittenVector(len(layout), layout[0])  # as make_vec lays them out
        stack.callback(floor.close)
        async_rate, made_rate, floor_rate, sockets_rate = interleaved(
            rounds,
            Rate(random_steps(async_envs), batches * 8, scale=8),
            Rate(random_steps(made), batches, scale=64),
            Rate(random_steps_of(floor.step, made), batches, scale=64),
            Rate(random_steps(on_sockets), batches, scale=64),
        )
    return [
        Figure(f"gymnasium {_ASYNC_CARTPOLES}", async_rate, "env-steps/s"),
        Figure(
            f"{floor_name}, raw client", floor_rate, "env-steps/s", _ASYNC_CARTPOLES, async_rate
        ),
        Figure(
            "gymnasium.make_vec('rlenv/CartPole-v0', num_envs=64)",
            made_rate,
            "env-steps/s",
            _ASYNC_CARTPOLES,
            async_rate,
        ),
        Figure(
            "make_vec('rlenv/CartPole-v0', 64) against the floor",
            made_rate,
            "env-steps/s",
            floor_name,
            floor_rate,
        ),
        Figure(
            "make_vec('rlenv/CartPole-v0', 64) on sockets alone",
            sockets_rate,
            "env-steps/s",
            _ASYNC_CARTPOLES,
            async_rate,
        ),
        Figure(
            "make_vec(64) through shared memory against sockets",
            made_rate,
            "env-steps/s",
            "sockets alone",
            sockets_rate,
        ),
    ]


def _vector_layouts(rounds: int, steps: int, quick: bool) -> list[Figure]:
    """Figures (e): RemoteVectorEnv by environments and servers, and in-process, against (f)."""
    from rlenv_client import RemoteVectorEnv

    served = (
        [(4, 1), (8, 4), (64, 32)]
        if quick
        else [(1, 1), (2, 1), (4, 1), (8, 1), (8, 4), (64, 32), (64, 64)]
    )
    layouts: list[tuple[str, int, dict[str, Any]]] = [
        (
            f"{count} envs, {-(-count // per_server)} servers x {per_server}",
            count,
            {"instances_per_server": per_server},
        )
        for count, per_server in served
    ] + [
        (
            "8 envs, 2 servers x 4, sockets alone",
            8,
            {"instances_per_server": 4, "shared_memory": False},
        ),
        ("64 envs in this process", 64, {"in_process": True}),
    ]
    with contextlib.ExitStack() as stack:
        async_envs = _async_cartpoles(stack)
        measures = [Rate(random_steps(async_envs), steps // 4, scale=8)]
        for _, count, place in layouts:
            envs = stack.enter_context(RemoteVectorEnv(count, CARTPOLE, repeat_action=1, **place))
            envs.reset(seed=0)
            batch = np.zeros((count, 1), np.float32)
            measures.append(
                Rate(
                    _calls(functools.partial(envs.step, batch)),
                    max(steps // count, 20),
                    scale=count,
                )
            )
        async_rate, *vector_rates = interleaved(rounds, *measures)
    return [
        Figure(
            f"RemoteVectorEnv {name} (repeat 1, zero actions)",
            rate,
            "env-steps/s",
            _ASYNC_CARTPOLES,
            async_rate,
        )
        for (name, _, _), rate in zip(layouts, vector_rates, strict=True)
    ]


def random_steps(envs: Any, batches: int = 64) -> Callable[[int], None]:
    """``run(n)``: ``n`` steps of the vector ``envs`` (reset with seed 0) on random actions."""
    envs.reset(seed=0)
    return random_steps_of(envs.step, envs, batches)


def random_steps_of(
    step: Callable[[Any], object], envs: Any, batches: int = 64
) -> Callable[[int], None]:
    """``run(n)``: ``n`` calls of ``step`` with random actions of the vector ``envs``."""
    envs.action_space.seed(0)
    actions = [envs.action_space.sample() for _ in range(batches)]

    def run(n: int) -> None:
        for i in range(n):
            step(actions[i % batches])

    return run


_INSTANCE_MEMORY = """
import os, sys
from rlenv_client import LocalClient
from rlenv_tools._bench import _rss_kib
first = LocalClient(sys.argv[1])
first.reset(seed=0)
before = _rss_kib(os.getpid())
extra = [LocalClient(sys.argv[1]) for _ in range(int(sys.argv[2]))]
for instance in extra:
    instance.reset(seed=0)
print((_rss_kib(os.getpid()) - before) / len(extra))
"""


def _instance_kib(count: int = 50) -> float:
    """Resident memory per extra CartPole instance, each in its own tree.

    Measured in a fresh process: in this one, memory freed by the other figures would hold them.
    """
    output = subprocess.run(
        [sys.executable, "-c", _INSTANCE_MEMORY, CARTPOLE, str(count)],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    ).stdout
    return float(output)


def format_table(figures: list[Figure]) -> str:
    """The figures as a fixed-width table."""
    width = max([len("measurement"), *(len(figure.name) for figure in figures)]) + 2
    lines = [f"{'measurement':<{width}}{'value':>14}  {'unit':<14}{'x baseline':>11}  baseline"]
    for figure in figures:
        ratio = "" if figure.ratio is None else f"{figure.ratio:.2f}"
        baseline = (
            ""
            if figure.baseline is None
            else f"{figure.baseline_name} ({figure.baseline:,.0f} {figure.unit})"
        )
        lines.append(
            f"{figure.name:<{width}}{figure.value:>14,.1f}  {figure.unit:<14}"
            f"{ratio:>11}  {baseline}"
        )
    return "\n".join(lines)


def to_json(figures: list[Figure]) -> str:
    """The figures as JSON (a list of objects, ratios included)."""
    return json.dumps([{**asdict(figure), "ratio": figure.ratio} for figure in figures], indent=2)
