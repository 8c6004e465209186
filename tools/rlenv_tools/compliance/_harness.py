"""What every probe of the compliance suite runs in: the controller, raw connections, the tap.

- :class:`Harness`: the well-behaved controller and the shared state of a run; it runs each
  probe (a failure or a skip becomes a line of the report) and steps the controller after it,
  and opens raw connections whose frames it reads for the probes;
- :class:`ReplyTap` and :class:`TappedClient`: every frame the server sends the suite, on raw
  connections and well-behaved clients alike, is decoded once more to find foreign ext types;
- :func:`assert_error`, :func:`connection_closed`: what the probes check a raw connection's
  answer with; :func:`peak_rss_kib`: the server's peak memory.
"""

from __future__ import annotations

import random
import socket
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import msgpack

from rlenv.protocol import pack
from rlenv.protocol.codec import HEADER, NDARRAY_EXT
from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv.testing import frame, read_body
from rlenv.transport import _procfs as procfs
from rlenv_client.client import Client

if TYPE_CHECKING:
    from rlenv_tools.compliance import ComplianceReport

__all__ = [
    "Harness",
    "Probes",
    "ReplyTap",
    "Skipped",
    "TappedClient",
    "assert_error",
    "connection_closed",
    "peak_rss_kib",
]

Probes = list[tuple[str, Callable[[], None]]]
"""Probes to run, each with its name (the start of its failure and skip lines)."""

_MAX_DEPTH = 64
"""How deep :class:`ReplyTap` looks into a message for timestamps."""


class Skipped(Exception):
    """The probe does not apply to this server; the message says why."""


class ReplyTap:
    """Decodes, once more, every frame the server sends the suite, noting foreign ext types.

    The server may only ever send ext type 1 (arrays); msgpack's timestamp (ext type -1) is
    decoded as :class:`msgpack.Timestamp` and found by walking the message.

    Attributes:
        frames: frames read.
        foreign: one line per foreign ext type found (each type once), in the order found.
    """

    def __init__(self) -> None:
        self.frames = 0
        self.foreign: list[str] = []
        self._codes: set[int] = set()
        self._reported = 0

    def read(self, body: bytes, where: str) -> Any:
        """``body`` decoded (ext types other than 1 as :class:`msgpack.ExtType`), noted.

        Raises:
            ValueError: ``body`` is not one msgpack object.
        """
        codes: list[int] = []

        def hook(code: int, data: bytes) -> msgpack.ExtType:
            codes.append(code)
            return msgpack.ExtType(code, data)

        self.frames += 1
        message = msgpack.unpackb(body, ext_hook=hook, timestamp=0)
        if _holds_timestamp(message):
            codes.append(-1)
        for code in codes:
            if code != NDARRAY_EXT and code not in self._codes:
                self._codes.add(code)
                self.foreign.append(
                    f"the server sent ext type {code} (only ext type 1 may "
                    f"travel) to {where}: {message!r:.160}"
                )
        return message

    def unreported(self) -> list[str]:
        """The findings not returned before; marks them returned."""
        lines, self._reported = self.foreign[self._reported :], len(self.foreign)
        return lines


def _holds_timestamp(value: Any, depth: int = 0) -> bool:
    """Whether a decoded message holds a timestamp within :data:`_MAX_DEPTH` levels.

    msgpack decodes maps (whose keys are strings: it refuses others) and lists only.
    """
    if isinstance(value, msgpack.Timestamp):
        return True
    if depth >= _MAX_DEPTH:
        return False
    if isinstance(value, dict):
        value = list(value.values())
    return isinstance(value, list) and any(_holds_timestamp(item, depth + 1) for item in value)


class TappedClient(Client):
    """A :class:`Client` whose received bytes also go, frame by frame, to a :class:`ReplyTap`.

    It overrides :meth:`Client._recv`, the one place the client's received bytes pass (the
    hook is documented there): the tap sees the hello too, as the override is in place before
    :class:`Client` connects. It splits the bytes into frames by the codec's :data:`HEADER`
    itself rather than through a :class:`~rlenv.protocol.Connection` (which the client reads
    with already): the tap wants each body undecoded, to decode it with its own ext hook and
    note what the client's strict decoding would refuse before anything saw it.
    """

    def __init__(self, tap: ReplyTap, where: str, host: str, port: int, **kwargs: Any) -> None:
        self._tap, self._where, self._stream = tap, where, bytearray()
        kwargs.setdefault("shared_memory", False)  # every answer on the wire, for the tap
        super().__init__(host, port, **kwargs)

    def _recv(self) -> bytes:
        data = super()._recv()
        stream = self._stream
        stream += data
        while len(stream) >= HEADER.size:
            (length,) = HEADER.unpack_from(stream)
            if len(stream) < HEADER.size + length:
                break
            body = bytes(stream[HEADER.size : HEADER.size + length])
            del stream[: HEADER.size + length]
            try:
                self._tap.read(body, self._where)
            except (ValueError, msgpack.UnpackException):
                pass  # not msgpack: the client itself refuses it
        return data


class Harness:
    """The controller and the state the probes share, for one run of the suite.

    Attributes:
        address: the server's ``(host, port)``.
        token: the server's token, if given.
        timeout: seconds to wait for any answer.
        controller: the well-behaved client that controls the environment.
        report: the report the probes fill.
        rng: the source of every random choice (frames, actions, seeds), in the order drawn.
        tap: reads every frame the server sends the suite.
        started: whether the controller has started an episode (the probes need one).
        hello: the last hello a raw connection read.
        seed: the seed of the episodes the contract probes compare (the rng's first draw).
    """

    def __init__(
        self,
        host: str,
        port: int,
        token: str | None,
        timeout: float,
        controller: Client,
        report: ComplianceReport,
        rng: random.Random,
        action: Callable[[], Any] | None,
        tap: ReplyTap,
    ) -> None:
        self.address = (host, port)
        self.token = token
        self.timeout = timeout
        self.controller = controller
        self.report = report
        self.rng = rng
        self.tap = tap
        self.started = False
        self.hello: dict[str, Any] = {}
        self.seed = rng.randrange(2**31 - 2)
        self.environment_errors = 0  # the controller's steps the environment failed
        self._action = action

    # --- running probes ---

    def run(self, name: str, probe: Callable[[], None]) -> None:
        """Run ``probe``, report its failure or skip as ``name``, then step the controller."""
        self.report.probes += 1
        try:
            probe()
        except Skipped as reason:
            self.report.skipped.append(f"{name}: {reason}")
        except AssertionError as failure:
            self.report.failures.append(f"{name}: {failure}")
        except Exception as error:  # a probe that cannot even run is a failure too
            self.report.failures.append(f"{name}: {type(error).__name__}: {error}")
        if not self.started:
            return
        try:
            self.step_controller()
        except RemoteError as error:
            if error.code == ErrorCode.ENVIRONMENT_ERROR:
                if not self.environment_errors:  # the environment's own fault, said once
                    self.report.failures.append(
                        f"after {name}, the environment raised on an action of its space "
                        f"(pass action=... to step with others): "
                        f"{error.message.splitlines()[0]}"
                    )
                self.environment_errors += 1
            else:
                self.report.failures.append(f"after {name}, the controller could not step: {error}")
            self.start_episode()  # what a trainer does: the next probes go on
        except Exception as error:
            self.report.failures.append(f"after {name}, the controller could not step: {error}")

    def start_episode(self) -> None:
        """Reset the controller's environment with a fresh seed."""
        self.controller.reset(seed=self.rng.randrange(2**31))
        self.started = True

    def step_controller(self) -> None:
        """One step of the controller (a new episode if that one ended)."""
        _, _, terminated, truncated, _ = self.controller.step(self.valid_action())
        self.report.controller_steps += 1
        if terminated or truncated:
            self.start_episode()

    def valid_action(self) -> Any:
        """An action the environment must accept."""
        if self._action is not None:
            return self._action()
        space = self.controller.action_space
        space.seed(self.rng.randrange(2**31))
        return space.sample()

    def client(self) -> Client:
        """Another well-behaved client (its replies are tapped too)."""
        return TappedClient(
            self.tap, "another client", *self.address, timeout=self.timeout, token=self.token
        )

    # --- raw connections ---

    def connect(self, *, authenticate: bool = True) -> socket.socket:
        """A raw connection, past the hello (and the token, unless told not to send it).

        The hello is kept in :attr:`hello`.
        """
        sock = socket.create_connection(self.address, timeout=self.timeout)
        try:
            hello = self.read_frame(sock)
            assert "hello" in hello, f"expected a hello, got {hello!r:.100}"
            if authenticate and hello["hello"].get("token_required"):
                sock.sendall(frame(pack({"id": 0, "token": self.token or ""})))
                reply = self.read_frame(sock)
                assert "error" not in reply, f"authentication failed: {reply!r:.200}"
        except BaseException:
            sock.close()
            raise
        self.hello = hello["hello"]
        return sock

    def send_probe(self, sock: socket.socket, data: bytes) -> None:
        """Send a probe's bytes on a raw connection; they count as one frame tried."""
        sock.sendall(data)
        self.report.frames_tried += 1

    def read_frame(self, sock: socket.socket) -> dict[str, Any]:
        """One frame from a raw connection, decoded (and checked for foreign ext types).

        Raises:
            AssertionError: the server closed the connection first, or sent no map.
        """
        body = read_body(sock)
        try:
            message = self.tap.read(body, "a raw connection")
        except (ValueError, msgpack.UnpackException) as error:
            raise AssertionError(f"the server sent a frame that is not msgpack: {error}") from None
        assert isinstance(message, dict), f"the server sent a non-map {message!r:.100}"
        return message


def connection_closed(sock: socket.socket) -> bool:
    """Whether the server closed a raw connection (it sends nothing more)."""
    try:
        return sock.recv(1) == b""
    except (ConnectionResetError, TimeoutError):
        return True


def assert_error(reply: dict[str, Any], code: ErrorCode, words: str, *, fatal: bool) -> None:
    """``reply`` (as read on a raw connection) is a ``code`` error whose message has ``words``.

    Raises:
        AssertionError: it is not.
    """
    error = reply.get("error")
    assert error is not None, f"expected a {code} error, got {reply!r:.200}"
    assert error["code"] == code, f"expected {code}, got {error['code']}: {error['message']}"
    assert words in error["message"], f"{words!r} not in {error['message']!r}"
    assert error["fatal"] is fatal, f"expected fatal={fatal}: {error!r:.200}"


def peak_rss_kib(pid: int | None) -> int | None:
    """The peak resident memory of process ``pid``, in KiB (Linux only; else ``None``)."""
    return None if pid is None else procfs.status_kib(pid, "VmHWM")
