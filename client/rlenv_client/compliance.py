"""The compliance suite: check any running rlenv server the way a network service is checked.

:func:`check_server` connects a well-behaved client that controls the environment and steps
between every probe, while hostile connections send what a network service must survive (an
HTTP request, a TLS hello, a 4 GiB length prefix, random frames, invalid msgpack, wrong types,
a slow drip); the controller itself sends wrong actions and out-of-order calls. Every probe
must get its error, and the controller must keep stepping (like dm_env_rpc's ``compliance``
and trio's ``check_two_way_stream``). ``rlenv check HOST:PORT --compliance`` runs it.
"""

from __future__ import annotations

import random
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector.utils import concatenate, create_empty_array

from rlenv.errors import ErrorCode, RemoteError
from rlenv.protocol import pack
from rlenv.testing import frame, read_frame
from rlenv_client.client import Client

__all__ = ["ComplianceReport", "check_server"]


@dataclass
class ComplianceReport:
    """What :func:`check_server` tried and found.

    Attributes:
        failures: one line per probe that did not get the answer it should have.
        frames_tried: hostile or malformed frames sent.
        probes: probes run.
        controller_steps: steps the well-behaved controller took between the probes.
        rss_growth_kib: growth of the server's peak resident memory over the run, when its pid
            was given (Linux only).
    """

    failures: list[str] = field(default_factory=list)
    frames_tried: int = 0
    probes: int = 0
    controller_steps: int = 0
    rss_growth_kib: int | None = None

    @property
    def passed(self) -> bool:
        """Whether every probe got its answer."""
        return not self.failures

    def summary(self) -> str:
        """One line of figures."""
        memory = "" if self.rss_growth_kib is None else \
            f", server peak memory grew {self.rss_growth_kib} KiB"
        return (f"{self.probes} probes, {self.frames_tried} malformed frames, "
                f"{self.controller_steps} controller steps, {len(self.failures)} failures"
                f"{memory}")


def check_server(
    host: str, port: int, *, token: str | None = None, pid: int | None = None,
    random_frames: int = 200, frame_deadline: float | None = None, seed: int = 0,
    timeout: float = 10.0, action: Callable[[], Any] | None = None,
) -> ComplianceReport:
    """Run the compliance suite against a running server (which must have no controller).

    Args:
        host: the server's address.
        port: the server's port.
        token: the server's token, if it requires one.
        pid: the server's process id, to report its memory growth.
        random_frames: how many random frames to send.
        frame_deadline: the server's frame deadline; when given, a slow-drip client checks that
            the server drops it in time (keep it short: the probe waits for it).
        seed: seed of the random frames.
        timeout: seconds to wait for any answer.
        action: gives the controller's actions between probes; by default samples of the
            action space.

    Returns:
        The report; :attr:`ComplianceReport.passed` says whether the server complied.
    """
    report = ComplianceReport()
    peak_before = _peak_rss_kib(pid)
    with Client(host, port, timeout=timeout, token=token) as controller:
        suite = _Suite(host, port, token, timeout, controller, report, random.Random(seed),
                       action)
        suite.start_episode()
        for name, probe in suite.raw_probes(random_frames):
            suite.run(name, probe)
        if frame_deadline is not None:
            suite.run("slow drip", lambda: suite.slow_drip(frame_deadline))
        for name, probe in suite.controller_probes():
            suite.run(name, probe)
    peak_after = _peak_rss_kib(pid)
    if peak_before is not None and peak_after is not None:
        report.rss_growth_kib = peak_after - peak_before
    return report


class _Suite:
    def __init__(self, host: str, port: int, token: str | None, timeout: float,
                 controller: Any, report: ComplianceReport, rng: random.Random,
                 action: Callable[[], Any] | None) -> None:
        self.action = action
        self.address = (host, port)
        self.token = token
        self.timeout = timeout
        self.controller = controller
        self.report = report
        self.rng = rng

    # --- running probes ---

    def run(self, name: str, probe: Callable[[], None]) -> None:
        self.report.probes += 1
        try:
            probe()
        except AssertionError as failure:
            self.report.failures.append(f"{name}: {failure}")
        except Exception as error:  # a probe that cannot even run is a failure too
            self.report.failures.append(f"{name}: {type(error).__name__}: {error}")
        try:
            self.step_controller()
        except Exception as error:
            self.report.failures.append(f"after {name}, the controller could not step: {error}")

    def start_episode(self) -> None:
        self.controller.reset(seed=self.rng.randrange(2**31))

    def step_controller(self) -> None:
        _, _, terminated, truncated, _ = self.controller.step(self.valid_action())
        self.report.controller_steps += 1
        if terminated or truncated:
            self.start_episode()

    def valid_action(self) -> Any:
        if self.action is not None:
            return self.action()
        space = self.controller.action_space
        space.seed(self.rng.randrange(2**31))
        return space.sample()

    # --- hostile connections ---

    def raw_probes(self, random_frames: int) -> list[tuple[str, Callable[[], None]]]:
        def fatal(data: bytes, code: ErrorCode, words: str) -> Callable[[], None]:
            return lambda: self.expect_fatal(data, code, words)

        def answered(body: bytes, code: ErrorCode, words: str) -> Callable[[], None]:
            return lambda: self.expect_error(body, code, words)

        http = b"GET / HTTP/1.1\r\nHost: localhost\r\n\r\n"
        tls = b"\x16\x03\x01\x00\xa5\x01\x00\x00\xa1\x03\x03" + bytes(range(32))
        return [
            ("an HTTP request", fatal(http, ErrorCode.BAD_FRAME, "exceeds the limit")),
            ("a TLS client hello", fatal(tls, ErrorCode.BAD_FRAME, "exceeds the limit")),
            ("a 4 GiB length prefix",
             fatal(b"\xff\xff\xff\xff", ErrorCode.BAD_FRAME, "exceeds the limit")),
            ("invalid msgpack", answered(b"\xc1", ErrorCode.BAD_FRAME, "not valid msgpack")),
            ("an empty frame", answered(b"", ErrorCode.BAD_FRAME, "not valid msgpack")),
            ("trailing bytes",
             answered(pack({"id": 1}) + b"\x00", ErrorCode.BAD_FRAME, "trailing bytes")),
            ("a frame that is not a map",
             answered(pack([1, 2, 3]), ErrorCode.BAD_FRAME, "must hold a map")),
            ("a foreign ext type",
             answered(b"\x81\xa2id\xd4\x07\x00", ErrorCode.BAD_FRAME, "ext type")),
            ("an unknown key",
             answered(pack({"id": 1, "launch": True}), ErrorCode.BAD_REQUEST, "'launch'")),
            ("an id that is not an integer",
             answered(pack({"id": "one"}), ErrorCode.BAD_REQUEST, "'id'")),
            ("a config that is not a map",
             answered(pack({"id": 1, "config": [1]}), ErrorCode.BAD_REQUEST, "'config'")),
            ("repeat_action 0",
             answered(pack({"id": 1, "action": 0, "repeat_action": 0}), ErrorCode.BAD_REQUEST,
                      "repeat_action")),
            ("steps that are not a map",
             answered(pack({"id": 1, "steps": [1]}), ErrorCode.BAD_REQUEST, "'steps'")),
            ("steps without actions",
             answered(pack({"id": 1, "steps": {"reset": [True]}}), ErrorCode.BAD_REQUEST,
                      "'action'")),
            ("steps with a reset mask of numbers",
             answered(pack({"id": 1, "steps": {"action": [0], "reset": [2]}}),
                      ErrorCode.BAD_REQUEST, "steps.reset")),
            ("deeply nested msgpack",
             answered(b"\x91" * 5000 + b"\xc0", ErrorCode.BAD_FRAME, "")),
            (f"{random_frames} random frames", lambda: self.random_frames(random_frames)),
            ("a frame cut short by a hang-up", self.truncated_then_gone),
        ]

    def connect(self) -> socket.socket:
        sock = socket.create_connection(self.address, timeout=self.timeout)
        hello = read_frame(sock)
        assert "hello" in hello, f"expected a hello, got {hello!r:.100}"
        if hello["hello"].get("token_required"):
            sock.sendall(frame(pack({"id": 0, "token": self.token or ""})))
            reply = read_frame(sock)
            assert "error" not in reply, f"authentication failed: {reply!r:.200}"
        return sock

    def expect_fatal(self, data: bytes, code: ErrorCode, words: str) -> None:
        with self.connect() as sock:
            sock.sendall(data)
            self.report.frames_tried += 1
            reply = read_frame(sock)
            _assert_error(reply, code, words, fatal=True)
            assert _closed(sock), "the server kept a connection whose framing broke"

    def expect_error(self, body: bytes, code: ErrorCode, words: str) -> None:
        with self.connect() as sock:
            sock.sendall(frame(body))
            self.report.frames_tried += 1
            _assert_error(read_frame(sock), code, words, fatal=False)

    def random_frames(self, count: int) -> None:
        with self.connect() as sock:
            for _ in range(count):
                body = self.rng.randbytes(self.rng.randrange(0, 256))
                sock.sendall(frame(body))
                self.report.frames_tried += 1
                reply = read_frame(sock)
                assert "error" in reply or "id" in reply, f"odd reply {reply!r:.100}"
                if reply.get("error", {}).get("fatal"):
                    return  # a frame that broke the framing ends this connection, as it must

    def truncated_then_gone(self) -> None:
        with self.connect() as sock:
            sock.sendall(frame(pack({"id": 1, "observation": {"agent": {}}}))[:-3])
            self.report.frames_tried += 1

    def slow_drip(self, deadline: float) -> None:
        with self.connect() as sock:
            sock.settimeout(deadline * 3 + self.timeout)
            started = time.monotonic()
            sock.sendall(b"\x00\x00")  # half a length prefix, and never the rest
            self.report.frames_tried += 1
            reply = read_frame(sock)
            waited = time.monotonic() - started
            _assert_error(reply, ErrorCode.TIMEOUT, "not completed", fatal=True)
            assert waited < deadline * 3 + 1, f"dropped only after {waited:.1f} s"

    # --- the controller's own mistakes ---

    def controller_probes(self) -> list[tuple[str, Callable[[], None]]]:
        space = self.controller.action_space
        probes = [
            ("an action of the wrong shape",
             lambda: self.refused(np.zeros((7, 3)), ErrorCode.INVALID_ACTION, "action")),
            ("an action that is text",
             lambda: self.refused("jump", ErrorCode.INVALID_ACTION, "action")),
            ("an unknown configuration key",
             lambda: self.refused_config(ErrorCode.INVALID_CONFIG, "no_such_setting")),
        ]
        if isinstance(space, spaces.Box) and space.dtype.kind == "f":
            nan = np.full(space.shape, np.nan, dtype=space.dtype)
            probes.append(("a NaN action",
                           lambda: self.refused(nan, ErrorCode.INVALID_ACTION, "finite")))
            probes.append(("an infinite action",
                           lambda: self.refused(np.full(space.shape, np.inf, space.dtype),
                                                ErrorCode.INVALID_ACTION, "finite")))
            if np.isfinite(space.high).all():
                above = (space.high + np.abs(space.high) + 1).astype(space.dtype)
                probes.append(("an action out of bounds",
                               lambda: self.refused(above, ErrorCode.INVALID_ACTION, "bounds")))
        if isinstance(space, spaces.Discrete):
            beyond = int(space.start + space.n)
            probes.append(("an action out of range",
                           lambda: self.refused(beyond, ErrorCode.INVALID_ACTION, "outside")))
        instances = self.controller.hello.instances
        probes.append(("steps with a reset mask of the wrong length",
                       lambda: self.steps_refused(instances, [True] * (instances + 1),
                                                  ErrorCode.BAD_REQUEST, "flags for")))
        if instances > 1:  # the controller resets instance 0 only
            probes.append(("steps before every instance was reset",
                           lambda: self.steps_refused(instances, None, ErrorCode.RESET_REQUIRED,
                                                      "steps: instance 1")))
        return probes

    def steps_refused(self, instances: int, reset: list[bool] | None, code: ErrorCode,
                      words: str) -> None:
        space = self.controller.action_space
        actions = concatenate(space, [self.valid_action() for _ in range(instances)],
                              create_empty_array(space, instances))

        def attempt() -> object:
            self.controller.send_steps(actions, None if reset is None else np.array(reset))
            return self.controller.receive_steps()
        self.refused_unchanged(attempt, code, words, "the steps")

    def refused(self, action: Any, code: ErrorCode, words: str) -> None:
        self.refused_unchanged(lambda: self.controller.step(action), code, words,
                               f"the action {action!r:.60}")

    def refused_unchanged(self, attempt: Callable[[], object], code: ErrorCode, words: str,
                          what: str) -> None:
        """``attempt()`` must be refused (``code``, ``words`` in the message), changing nothing."""
        before = self.controller.observe()["agent"]
        try:
            answer = attempt()
        except RemoteError as error:
            assert error.code == code, f"expected {code}, got {error.code}: {error.message}"
            assert words in error.message, f"{words!r} not in {error.message!r}"
        else:
            raise AssertionError(f"{what} was accepted: {answer!r:.80}")
        after = self.controller.observe()["agent"]
        assert _same(before, after), f"{what} was refused but changed the environment"

    def refused_config(self, code: ErrorCode, key: str) -> None:
        try:
            self.controller.configure(**{key: 1})
        except RemoteError as error:
            assert error.code == code and key in error.message, error.message
        else:
            raise AssertionError(f"configuration {key!r} was accepted")


def _closed(sock: socket.socket) -> bool:
    try:
        return sock.recv(1) == b""
    except (ConnectionResetError, TimeoutError):
        return True


def _assert_error(reply: dict[str, Any], code: ErrorCode, words: str, *, fatal: bool) -> None:
    error = reply.get("error")
    assert error is not None, f"expected a {code} error, got {reply!r:.200}"
    assert error["code"] == code, f"expected {code}, got {error['code']}: {error['message']}"
    assert words in error["message"], f"{words!r} not in {error['message']!r}"
    assert error["fatal"] is fatal, f"expected fatal={fatal}: {error!r:.200}"


def _same(a: Any, b: Any) -> bool:
    """Whether two observations are equal (maps and sequences of arrays, element by element)."""
    if isinstance(a, dict) or isinstance(b, dict):
        return isinstance(a, dict) and isinstance(b, dict) and a.keys() == b.keys() and \
            all(_same(a[key], b[key]) for key in a)
    if isinstance(a, tuple | list) and isinstance(b, tuple | list) and \
            not all(np.isscalar(item) for item in (*a, *b)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return bool(np.array_equal(np.asarray(a), np.asarray(b)))


def _peak_rss_kib(pid: int | None) -> int | None:
    if pid is None:
        return None
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None

