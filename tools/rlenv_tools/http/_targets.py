"""What an ``env_id`` names, and how a session's environment is opened.

A session's ``env_id`` is the command line's TARGET or an id registered by
:mod:`rlenv_client.registration` (``rlenv/CartPole-v0`` ..., with its time limit; a TARGET
may be one of them too). Nothing else: a request never names a module to import or an address
to connect to.

Where the environment runs: never in the gateway's process (see ``docs/http.md`` for the
measurements behind this), so that a deadline holds whatever its code does and a hung
environment can be ended (:mod:`rlenv_tools.http._runners`):

- ``MODULE:CLASS`` and registered ids: in an ``rlenv serve`` subprocess of the session's own
  (:class:`~rlenv_client.launcher.ServerProcess`), relayed over TCP: an environment that
  crashes its process, hangs or loops takes only its session with it (502, 504), and its
  process is ended.
- ``HOST:PORT``: a running server, relayed over TCP (one connection per session; a server of
  one instance has one controller, so a second session's reset is told ``busy``).

The relay's client keeps its answers on the socket (no shared-memory lane), where the event
loop awaits them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

from rlenv.protocol import Hello
from rlenv.protocol.errors import ConnectionLost, ErrorCode, RemoteError, RequestTimeout
from rlenv_client._addresses import is_address
from rlenv_client.client import Client
from rlenv_client.launcher import ServerProcess, ServerStartError
from rlenv_client.registration import ENVIRONMENTS
from rlenv_client.session import parse_address
from rlenv_tools.http._runners import Runner
from rlenv_tools.http.problems import Problem

__all__ = ["Catalog", "Entry", "Opened", "is_address"]

_T = TypeVar("_T")
_STARTUP_TIMEOUT = 60.0  # seconds a session's server may take to start
_CLOSING_GRACE = 5.0  # seconds a session's server has to exit on SIGTERM before SIGKILL


@dataclass(frozen=True)
class Entry:
    """One ``env_id`` the gateway serves.

    Attributes:
        env_id: as clients name it.
        target: ``MODULE:CLASS`` or ``HOST:PORT``.
        max_episode_steps: the registered time limit (steps), if any.
    """

    env_id: str
    target: str
    max_episode_steps: int | None = None


class Opened:
    """A session's environment: its client, the runner that calls it, its server subprocess."""

    def __init__(
        self, client: Client, runner: Runner, process: ServerProcess | None = None
    ) -> None:
        self.client, self.runner, self.process = client, runner, process

    def close(self, grace: float = _CLOSING_GRACE) -> None:
        """Close the client and end the server subprocess, if any (blocking).

        Args:
            grace: seconds the subprocess has to exit on SIGTERM before SIGKILL (a hung
                environment's process gets little: its code may never see the signal).
        """
        try:
            self.client.close()
        finally:
            self.runner.close()
            if self.process is not None:
                self.process.close(grace)


class Catalog:
    """The ``env_id`` values served and how each is opened; see the module docstring.

    Args:
        target: the command line's TARGET (``MODULE:CLASS``, ``HOST:PORT`` or a registered id,
            which keeps its time limit), or ``None``.
        timeout: seconds an environment may take to answer one request.
    """

    def __init__(self, target: str | None, *, timeout: float = 30.0) -> None:
        self.target = target
        self.timeout = timeout
        self._entries = {
            env_id: Entry(env_id, r.target, r.max_episode_steps)
            for env_id, r in ENVIRONMENTS.items()
        }
        if target is not None and target not in self._entries:
            self._entries[target] = Entry(target, target)

    def ids(self) -> list[str]:
        """Every ``env_id`` a session may be created with, the TARGET first."""
        return sorted(self._entries, key=lambda env_id: (env_id != self.target, env_id))

    def entry(self, env_id: object) -> Entry:
        """The entry of ``env_id``.

        Raises:
            Problem: ``bad_request`` naming the ids served.
        """
        entry = self._entries.get(env_id) if isinstance(env_id, str) else None
        if entry is None:
            raise Problem(
                ErrorCode.BAD_REQUEST,
                f"unknown env_id {env_id!r:.80}: this gateway serves {self.ids()}",
            )
        return entry

    def describe(self) -> Hello | None:
        """What the TARGET's environment says on connecting (its spaces), or ``None``.

        Blocking: for the gateway's start, before it serves.

        Raises:
            Exception: the TARGET cannot be served (import error, unreachable server ...).
        """
        if self.target is None:
            return None
        opened = self._open_blocking(self._entries[self.target], Runner(self.timeout))
        try:
            return opened.client.hello
        finally:
            opened.close()

    async def open(self, entry: Entry) -> Opened:
        """Open ``entry``'s environment for a new session (on the session's thread).

        Raises:
            Problem: ``environment_error`` (its constructor raised), ``environment_lost`` (its
                server did not start or cannot be reached), ``timeout``, ``busy``.
        """
        runner = Runner(self.timeout)
        try:
            return await runner.call(
                _guarded(lambda: self._open_blocking(entry, runner)),
                timeout=_STARTUP_TIMEOUT + self.timeout,
            )
        except BaseException:
            runner.close()
            raise

    def _open_blocking(self, entry: Entry, runner: Runner) -> Opened:
        """Open ``entry`` from this thread (see :meth:`open`)."""
        if is_address(entry.target):
            return Opened(_connect(*parse_address(entry.target), self.timeout), runner)
        try:
            process = ServerProcess(entry.target, startup_timeout=_STARTUP_TIMEOUT)
        except ServerStartError as error:
            raise Problem(
                "environment_lost", f"the server of {entry.env_id} did not start: {error}"
            ) from None
        try:
            return Opened(_connect(process.host, process.port, self.timeout), runner, process)
        except BaseException:
            process.close()
            raise


def _connect(host: str, port: int, timeout: float) -> Client:
    """A client of the server at ``host:port``, its failures as problems."""
    try:
        return Client(host, port, timeout=timeout)
    except RequestTimeout as error:
        raise Problem(ErrorCode.TIMEOUT, str(error)) from None
    except ConnectionLost as error:
        raise Problem("environment_lost", str(error)) from None
    except RemoteError as error:  # busy, or a token this gateway lacks
        code = error.code if error.code == ErrorCode.BUSY else "environment_lost"
        raise Problem(code, f"{host}:{port} refused the connection: {error.message}") from None


def _guarded(open_client: Callable[[], _T]) -> Callable[[], _T]:
    """``open_client`` whose failures (the environment's own code raising) are problems."""

    def call() -> _T:
        try:
            return open_client()
        except (Problem, TimeoutError):
            raise
        except Exception as error:
            raise Problem(
                ErrorCode.ENVIRONMENT_ERROR, f"the environment could not be created: {error!r:.400}"
            ) from None

    return call
