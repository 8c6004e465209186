"""``rlenv.run``: an environment that hosts itself, as a Godot project does.

The environment's ``_ready`` calls ``self.communication.start_server(port, host)`` (the Godot
seed's way); :func:`run` builds its tree, runs the main loop and serves every request through
the same path as ``rlenv serve`` (:class:`~rlenv.serving._host.Host`: the same checks, episode
state, hooks and answers; there is no second server). In the loop the tree stays paused between
actions and the communication node polls in its ``_process`` (process mode ``ALWAYS``), blocking
until a request comes (in lockstep) or the next tick is due (in real time); each request is
served in a deferred call, outside the processing pass, so that ``_reset`` may build nodes.

SIGINT or SIGTERM ends the loop, or the start (once the tree is being built): the socket is
closed and :func:`run` returns, so a script that ends with it exits with status 0. An address
that cannot be bound (a port in use, say) ends the script with status 2 and one line on
standard error, as ``rlenv serve`` says it.
"""

from __future__ import annotations

import logging
import os
import signal
from collections.abc import Callable
from types import FrameType
from typing import TYPE_CHECKING

from rlenv.protocol import Request
from rlenv.serving._access import InsecureBindError
from rlenv.serving._endpoint import Endpoint, Limits, Peer
from rlenv.serving._host import Host

if TYPE_CHECKING:
    from rlenv.environment import RLEnvironment

__all__ = ["run"]

logger = logging.getLogger(__name__)


class _Stopped(BaseException):
    """SIGTERM arrived (a BaseException, so that no ``except Exception`` swallows it)."""


class SelfHosting:
    """The server of an environment that hosts itself: its endpoint, bound by ``start_server``.

    Args:
        token: the secret clients must present (required to bind beyond loopback).
        limits: frame sizes and deadlines.
    """

    def __init__(self, token: str | None, limits: Limits) -> None:
        self.endpoint = Endpoint(None, limits, token)
        self.host: Host | None = None  # set once the environment's tree is built
        self.refused: Exception | None = None  # why binding failed, if it did
        self._serving = False

    def listen(self, port: int, host: str) -> tuple[str, int]:
        """Bind ``host:port`` (what ``communication.start_server`` does here)."""
        try:
            return self.endpoint.start_server(port, host)
        except (OSError, InsecureBindError) as error:
            self.refused = error
            raise

    def poll(self) -> None:
        """Wait for the next request and serve it after the current processing pass.

        Nothing is received while a request is being served (its action's ticks run frames
        too, and they poll).
        """
        host = self.host
        if host is None or self._serving:
            return
        got = self.endpoint.receive(host.time_to_next_tick())
        if got is not None:
            self._serving = True
            host.instances[0].tree.call_deferred(self._serve, host, *got)

    def _serve(self, host: Host, peer: Peer, request: Request) -> None:
        try:
            host.handle(self.endpoint, peer, request)
        finally:
            self._serving = False


def run(environment: RLEnvironment | type[RLEnvironment]) -> None:
    """Host ``environment`` itself and serve its clients until SIGINT or SIGTERM.

    The environment's ``_ready`` must call ``self.communication.start_server(port, host)``. A
    token in ``$RLENV_TOKEN`` is required of clients (and needed to bind beyond loopback). If
    no logging is configured, rlenv's messages (``listening on HOST:PORT``, clients coming and
    going) go to standard error.

    Raises:
        RuntimeError: the environment's ``_ready`` did not call ``start_server``.
        SystemExit: status 2, the address cannot be bound (a port in use, say); why is said in
            one line on standard error.
    """
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, format="%(message)s")
    if isinstance(environment, type):
        environment = environment()
    hosting = SelfHosting(os.environ.get("RLENV_TOKEN"), Limits())
    communication = environment.communication
    communication.host_itself(hosting)
    try:
        _until_stopped(lambda: _serve(environment, hosting))
    except (OSError, InsecureBindError) as error:
        if error is not hosting.refused:
            raise
        logger.debug("rlenv.run could not listen", exc_info=error)
        logger.error("rlenv.run: %s", error)  # one line on stderr (run configures logging)
        raise SystemExit(2) from None
    finally:
        hosting.endpoint.close()
        if hosting.refused is None:
            logger.info("stopped")


def _serve(environment: RLEnvironment, hosting: SelfHosting) -> None:
    """Build the environment's tree (its ``_ready`` binds) and run its main loop."""
    host = Host(environment)
    try:
        communication = environment.communication
        if communication.address is None:
            raise RuntimeError(
                f"{type(environment).__name__}._ready did not call "
                "self.communication.start_server(port, host): rlenv.run needs "
                "it (or serve the class with rlenv serve)"
            )
        hosting.endpoint.hello = host.hello
        hosting.host = host
        tree = host.instances[0].tree
        tree.root.add_child(communication)
        tree.run()
    finally:
        host.close()


def _until_stopped(work: Callable[[], None]) -> None:
    """Run ``work()`` until it returns, or until SIGINT or SIGTERM (then return)."""

    def stop(signum: int, frame: FrameType | None) -> None:
        raise _Stopped

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        work()
    except (KeyboardInterrupt, _Stopped):
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
