"""The hostile-input probes: what a network service must survive, and the controller's mistakes.

Raw connections send an HTTP request, a TLS hello, a 4 GiB length prefix, invalid msgpack, a
foreign ext type, malformed requests, deeply nested msgpack, random frames, a frame cut short
by a hang-up and (when the server's frame deadline is given) a slow drip: each must get its
error, fatal when the framing broke. The controller itself sends wrong actions, steps and
configuration: each must be refused and change nothing.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, cast

import numpy as np
from gymnasium import spaces
from gymnasium.vector.utils import concatenate, create_empty_array

from rlenv.protocol import pack
from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv.testing import frame
from rlenv_tools.compliance._harness import Harness, Probes, assert_error, connection_closed
from rlenv_tools.observations import observation_difference

__all__ = ["HostileProbes"]


class HostileProbes:
    """The hostile-input probes of one run, on ``harness``."""

    def __init__(self, harness: Harness) -> None:
        self.harness = harness
        self.controller = harness.controller

    # --- raw connections ---

    def frame_probes(self) -> Probes:
        """Bytes that are no frame or no msgpack map: a network service's first hazards."""

        def fatal(data: bytes, words: str) -> Callable[[], None]:
            return lambda: self.expect_fatal(data, ErrorCode.BAD_FRAME, words)

        def answered(body: bytes, words: str) -> Callable[[], None]:
            return lambda: self.expect_error(body, ErrorCode.BAD_FRAME, words)

        http = b"GET / HTTP/1.1\r\nHost: localhost\r\n\r\n"
        tls = b"\x16\x03\x01\x00\xa5\x01\x00\x00\xa1\x03\x03" + bytes(range(32))
        return [
            ("an HTTP request", fatal(http, "exceeds the limit")),
            ("a TLS client hello", fatal(tls, "exceeds the limit")),
            ("a 4 GiB length prefix", fatal(b"\xff\xff\xff\xff", "exceeds the limit")),
            ("invalid msgpack", answered(b"\xc1", "not valid msgpack")),
            ("an empty frame", answered(b"", "not valid msgpack")),
            ("trailing bytes", answered(pack({"id": 1}) + b"\x00", "trailing bytes")),
            ("a frame that is not a map", answered(pack([1, 2, 3]), "must hold a map")),
            ("a foreign ext type", answered(b"\x81\xa2id\xd4\x07\x00", "ext type")),
        ]

    def request_probes(self, random_frames: int) -> Probes:
        """Malformed requests, then deeply nested msgpack, random frames, a frame cut short."""

        def refused(request: dict[str, Any], words: str) -> Callable[[], None]:
            return lambda: self.expect_error(pack(request), ErrorCode.BAD_REQUEST, words)

        return [
            ("an unknown key", refused({"id": 1, "launch": True}, "'launch'")),
            ("an id that is not an integer", refused({"id": "one"}, "'id'")),
            ("a config that is not a map", refused({"id": 1, "config": [1]}, "'config'")),
            (
                "repeat_action 0",
                refused({"id": 1, "action": 0, "repeat_action": 0}, "repeat_action"),
            ),
            ("steps that are not a map", refused({"id": 1, "steps": [1]}, "'steps'")),
            ("steps without actions", refused({"id": 1, "steps": {"reset": [True]}}, "'action'")),
            (
                "steps with a reset mask of numbers",
                refused({"id": 1, "steps": {"action": [0], "reset": [2]}}, "steps.reset"),
            ),
            (
                "deeply nested msgpack",
                lambda: self.expect_error(b"\x91" * 5000 + b"\xc0", ErrorCode.BAD_FRAME, ""),
            ),
            (f"{random_frames} random frames", lambda: self.random_frames(random_frames)),
            ("a frame cut short by a hang-up", self.truncated_then_gone),
        ]

    def expect_fatal(self, data: bytes, code: ErrorCode, words: str) -> None:
        """``data`` gets a fatal ``code`` error, and the server closes the connection."""
        with self.harness.connect() as sock:
            self.harness.send_probe(sock, data)
            assert_error(self.harness.read_frame(sock), code, words, fatal=True)
            assert connection_closed(sock), "the server kept a connection whose framing broke"

    def expect_error(self, body: bytes, code: ErrorCode, words: str) -> None:
        """A frame of ``body`` gets a non-fatal ``code`` error."""
        with self.harness.connect() as sock:
            self.harness.send_probe(sock, frame(body))
            assert_error(self.harness.read_frame(sock), code, words, fatal=False)

    def random_frames(self, count: int) -> None:
        """Frames of random bytes each get an answer, until one breaks the framing."""
        rng = self.harness.rng
        with self.harness.connect() as sock:
            for _ in range(count):
                self.harness.send_probe(sock, frame(rng.randbytes(rng.randrange(0, 256))))
                reply = self.harness.read_frame(sock)
                assert "error" in reply or "id" in reply, f"odd reply {reply!r:.100}"
                if reply.get("error", {}).get("fatal"):
                    return  # a frame that broke the framing ends this connection, as it must

    def truncated_then_gone(self) -> None:
        """A frame cut short, then a hang-up (the controller's next step must still work)."""
        whole = frame(pack({"id": 1, "observation": {"agent": {}}}))
        with self.harness.connect() as sock:
            self.harness.send_probe(sock, whole[:-3])

    def slow_drip(self, deadline: float) -> None:
        """Half a length prefix, and never the rest: dropped with a fatal ``timeout`` in time."""
        with self.harness.connect() as sock:
            sock.settimeout(deadline * 3 + self.harness.timeout)
            started = time.monotonic()
            self.harness.send_probe(sock, b"\x00\x00")
            reply = self.harness.read_frame(sock)
            waited = time.monotonic() - started
            assert_error(reply, ErrorCode.TIMEOUT, "not completed", fatal=True)
            assert waited < deadline * 3 + 1, f"dropped only after {waited:.1f} s"

    # --- the controller's own mistakes ---

    def controller_probes(self) -> Probes:
        """Wrong actions, steps and configuration from the controller."""
        space = self.controller.action_space
        probes = [
            (
                "an action of the wrong shape",
                lambda: self.refused(np.zeros((7, 3)), ErrorCode.INVALID_ACTION, "action"),
            ),
            (
                "an action that is text",
                lambda: self.refused("jump", ErrorCode.INVALID_ACTION, "action"),
            ),
            (
                "an unknown configuration key",
                lambda: self.refused_config(ErrorCode.INVALID_CONFIG, "no_such_setting"),
            ),
        ]
        if isinstance(space, spaces.Box) and space.dtype.kind == "f":
            nan = np.full(space.shape, np.nan, dtype=space.dtype)
            probes.append(
                ("a NaN action", lambda: self.refused(nan, ErrorCode.INVALID_ACTION, "finite"))
            )
            probes.append(
                (
                    "an infinite action",
                    lambda: self.refused(
                        np.full(space.shape, np.inf, space.dtype),
                        ErrorCode.INVALID_ACTION,
                        "finite",
                    ),
                )
            )
            if np.isfinite(space.high).all():
                above = (space.high + np.abs(space.high) + 1).astype(space.dtype)
                probes.append(
                    (
                        "an action out of bounds",
                        lambda: self.refused(above, ErrorCode.INVALID_ACTION, "bounds"),
                    )
                )
        if isinstance(space, spaces.Discrete):
            beyond = int(space.start + space.n)
            probes.append(
                (
                    "an action out of range",
                    lambda: self.refused(beyond, ErrorCode.INVALID_ACTION, "outside"),
                )
            )
        instances = self.controller.hello.instances
        probes.append(
            (
                "steps with a reset mask of the wrong length",
                lambda: self.steps_refused(
                    instances, [True] * (instances + 1), ErrorCode.BAD_REQUEST, "flags for"
                ),
            )
        )
        if instances > 1:  # the controller resets instance 0 only
            probes.append(
                (
                    "steps before every instance was reset",
                    lambda: self.steps_refused(
                        instances, None, ErrorCode.RESET_REQUIRED, "steps: instance 1"
                    ),
                )
            )
        return probes

    def steps_refused(
        self, instances: int, reset: list[bool] | None, code: ErrorCode, words: str
    ) -> None:
        """Valid actions for every instance, with ``reset`` as the mask, are refused."""
        space = self.controller.action_space
        out = cast(Any, create_empty_array(space, instances))  # an action space: never None
        actions = concatenate(space, [self.harness.valid_action() for _ in range(instances)], out)

        def attempt() -> object:
            self.controller.send_steps(actions, None if reset is None else np.array(reset))
            return self.controller.receive_steps()

        self.refused_unchanged(attempt, code, words, "the steps")

    def refused(self, action: Any, code: ErrorCode, words: str) -> None:
        """``action`` is refused, changing nothing."""
        self.refused_unchanged(
            lambda: self.controller.step(action), code, words, f"the action {action!r:.60}"
        )

    def refused_unchanged(
        self, attempt: Callable[[], object], code: ErrorCode, words: str, what: str
    ) -> None:
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
        difference = observation_difference(before, after)
        assert difference is None, (
            f"{what} was refused but changed the environment, at {difference}"
        )

    def refused_config(self, code: ErrorCode, key: str) -> None:
        """Configuring ``key`` is refused with ``code``, naming the key."""
        try:
            setting: dict[str, Any] = {key: 1}
            self.controller.configure(**setting)
        except RemoteError as error:
            assert error.code == code and key in error.message, error.message
        else:
            raise AssertionError(f"configuration {key!r} was accepted")
