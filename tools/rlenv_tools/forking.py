"""An environment in a process of its own that copies itself, whole, by ``fork``.

A :class:`ForkedEnvironment` runs one environment (a :class:`~rlenv_client.local.LocalClient`,
so requests take the same door as under ``rlenv serve``) in a process started for it, and
answers calls over a Unix socket pair that only its owner holds. :meth:`~ForkedEnvironment.fork`
copies that process: the copy holds the same state to the bit (pymunk's contact caches and
sleeping bodies, the generators, every Python object), which no snapshot taken as data holds,
and it costs about a millisecond however large the scene. Timelines park such copies as
checkpoints (:mod:`rlenv_tools.timeline`).

Every call is a frame of the protocol's codec (:func:`rlenv.protocol.codec.frame`, read with
:func:`rlenv.transport.frames.receive_frame` and :func:`~rlenv.protocol.codec.unpack`) naming
one of a few operations (``call`` a method of the LocalClient, ``run`` many steps, ``fork``),
and every answer ``[status, value]``; nothing is ever unpickled. These are not the protocol's
requests: a call reaches the LocalClient's own methods (``snapshot``, ``restore``, ``tree``
...) between two processes of one owner, and a fork answers with a file descriptor. A process
ends when its socket closes, so closing the owner's end ends it. POSIX only (``os.fork``); the
environment must not rely on threads of its own, which a fork does not copy.

Every copy dies with its owner, whatever it is doing (a hung ``step`` included): the first
process and all its copies form a process group of their own, and hold the read end of a pipe,
the lifeline, whose only write end the owner holds. On Linux the lifeline is armed
(``O_ASYNC`` with ``F_SETSIG``): when its write end closes, because the owner closed the first
process or died (``SIGKILL`` included), the kernel sends ``SIGKILL`` to the whole group. (Not
``PR_SET_PDEATHSIG``: that fires when the parent *thread* ends, and a copy's parent is a
checkpoint, not the owner.) Elsewhere a process ends when it next reads its closed socket.
"""

from __future__ import annotations

import fcntl
import gc
import os
import select
import signal
import socket
import struct
import subprocess
import sys
import time
import traceback
from collections.abc import Sequence
from typing import Any, NoReturn

from rlenv.protocol.codec import frame, unpack
from rlenv.protocol.errors import RemoteError
from rlenv.protocol.messages import Hello
from rlenv.transport import _procfs as procfs
from rlenv.transport.frames import receive_frame
from rlenv_client.launcher import ServerStartError, end_process

__all__ = ["ForkedEnvironment", "StepRecord"]

StepRecord = tuple[str, float, bool, bool, Any]
"""What :meth:`ForkedEnvironment.run` tells of each step: the observation's digest, the reward,
terminated, truncated, and with several agents ``info["agents"]`` (each agent of the answer's
reward and flags; ``None`` with one agent)."""

_CALLS = frozenset(
    {"configure", "draw", "node", "restore", "set_property", "snapshot", "step", "tree"}
)
_FORKED = struct.Struct("<i")  # the copy's pid, in the message that carries its socket
_FAILED = _FORKED.pack(-1)  # no copy: the error's frame follows


class ForkedEnvironment:
    """One environment process (or a copy of one), driven over its socket.

    Start one with :meth:`start`; copy it with :meth:`fork`. Not thread-safe: one call at a
    time.

    Attributes:
        pid: the process's id.
        hello: what the environment says first, as a client of its server sees it (its agents
            and spaces); a copy's is its original's.
    """

    def __init__(
        self,
        sock: socket.socket,
        pid: int,
        hello: Hello | None,
        process: subprocess.Popen[bytes] | None = None,
        lifeline: int | None = None,
    ) -> None:
        self._socket = sock
        self.pid = pid
        self.hello = hello
        self._process = process  # the first process only: a copy is not this process's child
        self._lifeline = lifeline  # the first's only: closing it ends the group
        self.closed = False

    @classmethod
    def start(cls, target: str, *, timeout: float = 120.0) -> ForkedEnvironment:
        """Start a process serving ``target`` (``MODULE:CLASS``), reset by no one yet.

        Closing it (:meth:`close`) ends its copies too, as the owner's death does.

        Args:
            target: the environment class.
            timeout: seconds any call may take before the process is ended.

        Raises:
            ServerStartError: the class did not load (with why).
        """
        mine, theirs = socket.socketpair()
        lifeline, held = os.pipe()
        try:
            process = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "rlenv_tools.forking",
                    str(theirs.fileno()),
                    str(lifeline),
                    target,
                ],
                pass_fds=(theirs.fileno(), lifeline),
                stdin=subprocess.DEVNULL,
                process_group=0,
            )
        except BaseException:
            os.close(held)
            raise
        finally:
            theirs.close()
            os.close(lifeline)
        mine.settimeout(timeout)
        environment = cls(mine, process.pid, None, process, held)
        try:
            environment.hello = Hello.from_wire(environment._receive())
        except (RemoteError, ConnectionError, OSError) as error:
            environment.close()
            raise ServerStartError(f"{target} did not start: {error}") from None
        return environment

    def call(self, name: str, *args: Any, **kwargs: Any) -> Any:
        """The client method ``name`` (``step``, ``restore``, ``tree`` ...) called there.

        Raises:
            RemoteError: the environment refused the call (as its server would).
            ConnectionError: the process is gone or did not answer in time (it is ended).
        """
        self._send(["call", name, list(args), kwargs])
        return self._receive()

    def run(
        self,
        steps: Sequence[Sequence[Any]],
        *,
        stop_at_end: bool = False,
        observations: bool = False,
        driven: Sequence[str] = (),
    ) -> tuple[list[StepRecord], Any, dict[str, Any]]:
        """Take ``steps`` there, each a list of events ending with ``["action", action, frames]``.

        The events before a step's action are ``["config", part]`` (a ``configure``) and
        ``["set", path, property, value]``, as an episode's snapshot records them; after it may
        come the parts of a step that went on while driven agents decided (``["action",
        action, frames, true]``), each taken as a request of its own and their answers merged
        (:func:`rlenv_client._recorded_parts.take_step`).

        Args:
            steps: the steps, in order.
            stop_at_end: stop after a step that ended the episode.
            observations: return every step's observation (else only the last one's).
            driven: the agents the recording's server drove, left out of each step's
                observation and reward as its adaptor left them out
                (:func:`rlenv_client._recorded_parts.as_recorded`).

        Returns:
            Each step's record (digest, reward, terminated, truncated); the last step's
            observation (every step's, as a list, with ``observations``) and info.
        """
        self._send(["run", [list(step) for step in steps], stop_at_end, observations, list(driven)])
        records, observation, info = self._receive()
        return [tuple(record) for record in records], observation, info

    def fork(self) -> ForkedEnvironment:
        """A copy of this process, at this state, with a socket of its own."""
        self._send(["fork"])
        try:
            message, fds, _, _ = socket.recv_fds(self._socket, _FORKED.size, 1)
        except OSError as error:
            self._lost(error)
        if len(message) != _FORKED.size or len(fds) != 1:
            for fd in fds:
                os.close(fd)
            if message == _FAILED:
                self._receive()  # raises the error it sent
            self._lost(ConnectionResetError("it did not fork"))
        sock = socket.socket(fileno=fds[0])
        sock.settimeout(self._socket.gettimeout())
        return ForkedEnvironment(sock, _FORKED.unpack(message)[0], self.hello)

    def close(self) -> None:
        """Close the socket, which ends the process (the first's copies too); safe to repeat."""
        if self.closed:
            return
        self.closed = True
        self._socket.close()
        if self._lifeline is not None:
            os.close(self._lifeline)
            self._lifeline = None
        if self._process is not None:
            end_process(self._process, 5.0, first=None)  # it ends once its socket closes

    def end(self) -> None:
        """Close, and make sure the process is gone (killed after a few seconds)."""
        self.close()
        if self._process is None:
            _wait_gone(self.pid)

    def memory(self) -> int:
        """The process's proportional share of memory (PSS), in bytes.

        0 where ``/proc`` says none (not Linux, or the process is gone).
        """
        try:
            return procfs.rollup_kib(self.pid).get("Pss", 0) * 1024
        except OSError:
            return 0

    def _send(self, message: Any) -> None:
        if self.closed:
            raise ConnectionError("the environment process is closed")
        try:
            self._socket.sendall(frame(message))
        except OSError as error:
            self._lost(error)

    def _receive(self) -> Any:
        try:
            body = receive_frame(self._socket)
            if body is None:
                raise ConnectionResetError("the environment process ended")
            status, value = unpack(body)
        except OSError as error:
            self._lost(error)
        if status == "error":
            raise RemoteError(*value)
        return value

    def _lost(self, error: OSError) -> NoReturn:
        what = "did not answer in time" if isinstance(error, TimeoutError) else f"is gone ({error})"
        if self._process is None:
            _kill(self.pid)
        else:
            end_process(self._process, 0.0, first=None)
        self.close()
        raise ConnectionError(f"the environment process {self.pid} {what}") from None


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def _wait_gone(pid: int, timeout: float = 5.0) -> None:
    """Wait for a process that is not our child to end; kill it at the deadline."""
    deadline = time.monotonic() + timeout
    while procfs.alive(pid):
        if time.monotonic() > deadline:
            _kill(pid)
            deadline = float("inf")
        time.sleep(0.001)


def _serve(sock: socket.socket, target: str) -> None:
    """The process's loop: answer calls until the socket closes."""
    from rlenv.protocol.errors import RlenvError
    from rlenv_client._recorded_parts import as_recorded, split_step, take_step
    from rlenv_client.local import LocalClient
    from rlenv_client.replay import apply_change, digest

    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # copies of copies are reaped by the kernel
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the owner's Ctrl-C is the owner's
    try:
        client = LocalClient(target)
    except Exception as error:  # noqa: BLE001 (told to the owner, whatever it is)
        _reply(sock, "error", ["start_failed", _described(error)])
        return
    _reply(sock, "ok", client.hello.to_wire())

    def run(
        steps: list[list[Any]], stop_at_end: bool, every: bool, driven: list[str]
    ) -> tuple[list[StepRecord], Any, dict[str, Any]]:
        left_out = frozenset(driven)
        records: list[StepRecord] = []
        seen = []
        observation: Any = None
        info: dict[str, Any] = {}
        for step in steps:
            changes, actions = split_step(step)
            for change in changes:
                apply_change(client, change)
            observation, reward, terminated, truncated, info = as_recorded(
                take_step(client, actions), client.hello, left_out
            )
            records.append(
                (
                    digest(observation),
                    float(reward),
                    bool(terminated),
                    bool(truncated),
                    info.get("agents"),
                )
            )
            seen.append(observation)
            if stop_at_end and (terminated or truncated):
                break
        return records, seen if every else observation, info

    while True:
        request = _request(sock)
        if request is None:
            return
        try:
            if request[0] == "call" and request[1] in _CALLS:
                _reply(sock, "ok", getattr(client, request[1])(*request[2], **request[3]))
            elif request[0] == "run":
                _reply(sock, "ok", run(*request[1:]))
            elif request[0] == "fork":
                sock = _fork(sock) or sock
            else:
                _reply(sock, "error", ["bad_request", f"no operation {request[0]!r:.40}"])
        except RlenvError as error:
            _reply(
                sock,
                "error",
                [getattr(error, "code", "bad_request"), getattr(error, "message", str(error))],
            )
        except Exception as error:  # noqa: BLE001 (the owner is told; the process goes on)
            _reply(sock, "error", ["environment_error", _described(error)])


def _described(error: BaseException) -> str:
    """``Type: message``, then the traceback of where it was raised in this process.

    The owner raises the text, as gymnasium's AsyncVectorEnv workers send theirs.
    """
    trace = "".join(traceback.format_exception(error)).rstrip()
    return f"{type(error).__name__}: {error}\n{trace}"


def _fork(sock: socket.socket) -> socket.socket | None:
    """Fork; in the copy, the copy's socket (``None`` in the original, which sent it)."""
    mine, theirs = socket.socketpair()
    gc.freeze()  # the copy's collector would otherwise touch (and so copy) every page
    try:
        pid = os.fork()
    except OSError:
        gc.unfreeze()
        mine.close()
        theirs.close()
        sock.sendall(_FAILED)  # then the error's frame
        raise
    if pid == 0:  # the copy keeps what it inherited frozen: those pages stay shared
        sock.close()
        theirs.close()
        return mine
    gc.unfreeze()  # the original collects its own objects again
    mine.close()
    socket.send_fds(sock, [_FORKED.pack(pid)], [theirs.fileno()])
    theirs.close()
    return None


def _request(sock: socket.socket) -> Any:
    body = receive_frame(sock)
    return None if body is None else unpack(body)


def _reply(sock: socket.socket, status: str, value: Any) -> None:
    sock.sendall(frame([status, value]))


def _arm(lifeline: int) -> None:
    """Have the kernel kill this process group once the lifeline's write end closes (Linux)."""
    set_signal = getattr(fcntl, "F_SETSIG", None)
    if set_signal is None:
        return
    fcntl.fcntl(lifeline, fcntl.F_SETOWN, -os.getpgrp())
    fcntl.fcntl(lifeline, set_signal, signal.SIGKILL)
    fcntl.fcntl(lifeline, fcntl.F_SETFL, fcntl.fcntl(lifeline, fcntl.F_GETFL) | os.O_ASYNC)
    if select.select([lifeline], [], [], 0)[0]:  # the owner was gone before it was armed
        os.killpg(os.getpgrp(), signal.SIGKILL)


def main(argv: Sequence[str] | None = None) -> None:
    """``python -m rlenv_tools.forking FD LIFELINE MODULE:CLASS``: serve the socket ``FD``."""
    fd, lifeline, target = sys.argv[1:] if argv is None else argv
    _arm(int(lifeline))
    sock = socket.socket(fileno=int(fd))
    try:
        _serve(sock, target)
    except (ConnectionError, KeyboardInterrupt):
        pass
    finally:
        os._exit(0)  # a copy must not run its original's exit handlers


if __name__ == "__main__":
    main()
