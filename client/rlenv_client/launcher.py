"""Start an environment server in a subprocess and stop it, leaving nothing behind.

The server runs ``python -m rlenv serve MODULE:CLASS --port 0`` in a process group of its own.
:class:`ServerProcess` waits for its ``listening on HOST:PORT`` line, keeps the last lines of its
output for error messages, and on :meth:`~ServerProcess.close` (or at interpreter exit, or when
garbage collected) ends the whole group. If this process dies without any of that (SIGKILL),
the server still exits: it holds the read end of a pipe (``--lifeline``) whose write end only
this process holds, and the kernel closes it on death.
"""

from __future__ import annotations

import collections
import logging
import os
import queue
import signal
import subprocess
import sys
import threading
import time
import weakref
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from rlenv.protocol.errors import ConnectionLost, RlenvError
from rlenv_client._addresses import format_address, parse_address

__all__ = ["ServerProcess", "ServerStartError", "end_process", "with_server_story"]

logger = logging.getLogger(__name__)

_LISTENING = "listening on "
_KEPT_LINES = 200
_FAILED = "rlenv serve: "  # how rlenv serve says, in one line, why it could not start


class ServerStartError(RlenvError):
    """The server process exited or stayed silent before it was listening."""


class ServerProcess:
    """A server subprocess for the environment ``target`` (``MODULE:CLASS``).

    It runs ``rlenv serve`` in its own process group and returns once the server listens. The
    server exits when this process is gone (a lifeline pipe), and :meth:`close` (or leaving a
    ``with`` block, or garbage collection) ends its whole process group::

        with ServerProcess("examples.cartpole:CartPoleEnvironment") as server:
            with Client(server.host, server.port) as client:
                client.reset(seed=0)

    Args:
        target: the environment class, as ``MODULE:CLASS``.
        host: address for the server to bind.
        port: port for the server to bind; 0 picks a free one.
        startup_timeout: seconds to wait for the server to listen.
        args: extra command-line arguments for ``rlenv serve``.
        env: extra environment variables for the server (e.g. ``PYTHONPATH``).

    Attributes:
        target: the environment class it serves.
        host: the address the server listens on.
        port: the port the server listens on (the free one it picked for ``port=0``).
        process: the ``subprocess.Popen`` of the server.

    Raises:
        ServerStartError: the server died or did not listen in time; the message holds its
            output.
    """

    def __init__(
        self,
        target: str,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        startup_timeout: float = 60.0,
        args: Sequence[str] = (),
        env: Mapping[str, str] | None = None,
    ) -> None:
        self.target = target
        lifeline, self._lifeline = os.pipe()  # the server exits when this process is gone
        command = [
            sys.executable,
            "-m",
            "rlenv",
            "serve",
            target,
            "--host",
            host,
            "--port",
            str(port),
            "--lifeline",
            str(lifeline),
            *args,
        ]
        self._lines: collections.deque[str] = collections.deque(maxlen=_KEPT_LINES)
        self._events: queue.Queue[str | None] = queue.Queue()
        try:
            self.process = subprocess.Popen(
                command,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                text=True,
                bufsize=1,
                start_new_session=True,
                env={**os.environ, **(env or {})},
                pass_fds=(lifeline,),
            )
        finally:
            os.close(lifeline)
        self._pump_thread = threading.Thread(
            target=self._pump, daemon=True, name=f"rlenv-server-{self.pid}"
        )
        self._finalizer = weakref.finalize(
            self, _terminate, self.process, self._lifeline, self._pump_thread
        )
        self._pump_thread.start()
        try:
            self.host, self.port = self._wait_until_listening(startup_timeout)
        except BaseException:
            self.close()
            raise
        logger.info("server %s (pid %d) listening on %s:%d", target, self.pid, self.host, self.port)

    @property
    def pid(self) -> int:
        """The server's process id (also its process group id)."""
        return self.process.pid

    @property
    def address(self) -> str:
        """``HOST:PORT`` of the server (``[HOST]:PORT`` for IPv6), as ``Client`` takes it."""
        return format_address(self.host, self.port)

    @property
    def output(self) -> str:
        """The last lines the server wrote (stdout and stderr)."""
        return "".join(self._lines)

    def describe_exit(self, wait: float = 2.0) -> str | None:
        """How the server exited, with its last output; ``None`` while it runs.

        Waits up to ``wait`` seconds for a server that is dying to finish.
        """
        try:
            code = self.process.wait(wait)
        except subprocess.TimeoutExpired:
            return None
        self._pump_thread.join(wait)
        return (
            f"server {self.target} (pid {self.pid}) exited with code {code}; its last "
            f"output:\n{self.output}"
        )

    def is_alive(self) -> bool:
        """Whether the server process is still running."""
        return self.process.poll() is None

    def close(self, timeout: float = 5.0) -> None:
        """End the server's whole process group: SIGTERM, then SIGKILL after ``timeout``."""
        self._finalizer.detach()
        _terminate(self.process, self._lifeline, self._pump_thread, timeout)

    def __enter__(self) -> ServerProcess:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<ServerProcess {self.target} pid={self.pid}>"

    def _pump(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self._lines.append(line)
            if line.startswith(_LISTENING):
                self._events.put(line)
        self._events.put(None)

    def _wait_until_listening(self, timeout: float) -> tuple[str, int]:
        deadline = time.monotonic() + timeout
        while True:
            try:
                line = self._events.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise ServerStartError(
                    f"server {self.target} did not listen within {timeout}s; its output:\n"
                    f"{self.output}"
                ) from None
            if line is None:
                code = self.process.wait()
                self._pump_thread.join(1.0)
                reasons = [
                    line[len(_FAILED) :].strip() for line in self._lines if line.startswith(_FAILED)
                ]
                first = f"could not start: {reasons[-1]}" if reasons else "exited before listening"
                raise ServerStartError(
                    f"server {self.target} {first}\n(exit code {code}; its "
                    f"output:\n{self.output.rstrip()})"
                )
            return parse_address(line[len(_LISTENING) :].strip())


def with_server_story(error: ConnectionLost, servers: Iterable[ServerProcess]) -> ConnectionLost:
    """``error``, extended with how each of ``servers`` that died exited and what it last said."""
    stories = [story for server in servers if (story := server.describe_exit()) is not None]
    if not stories:
        return error
    return ConnectionLost("\n".join([str(error), *stories]))


def _terminate(
    process: subprocess.Popen[str], lifeline: int, pump: threading.Thread, timeout: float = 5.0
) -> None:
    try:
        os.close(lifeline)
    except OSError:  # closed already
        pass
    if process.poll() is None:
        end_process(process, timeout, group=True)
    pump.join(timeout)  # the output pipe reaches its end once the group is gone
    if process.stdout is not None and not pump.is_alive():
        process.stdout.close()


def end_process(
    process: subprocess.Popen[Any],
    timeout: float | None = 5.0,
    *,
    first: int | None = signal.SIGTERM,
    group: bool = False,
) -> int:
    """End the child ``process`` and reap it: every layer's one way to end a process it started.

    Sends ``first`` (SIGTERM), waits up to ``timeout`` seconds (``None``: as long as it takes)
    for the process to end, then sends SIGKILL and reaps it. A process that ended already is
    only reaped.

    Args:
        process: a child of this process.
        timeout: how long it has to end once asked; 0 kills it at once.
        first: the signal that asks it to end; ``None`` where it ends by itself (its input or
            its socket closed before the call) and is only waited for.
        group: signal its whole process group (a process started with
            ``start_new_session=True`` leads one) rather than the process alone.

    Returns:
        Its exit code (``-SIGKILL`` where it had to be killed).
    """
    if first is not None:
        _send_signal(process, first, group)
    try:
        return process.wait(timeout)
    except subprocess.TimeoutExpired:
        _send_signal(process, signal.SIGKILL, group)
        return process.wait()


def _send_signal(process: subprocess.Popen[Any], sig: int, group: bool) -> None:
    if process.poll() is not None:
        return  # reaped: its pid (and group id) may be another's by now
    try:
        if group:
            os.killpg(process.pid, sig)
        else:
            process.send_signal(sig)
    except ProcessLookupError:  # gone meanwhile
        pass
