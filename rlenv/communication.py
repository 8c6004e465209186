"""Communication: an environment's link to its clients (the seed's ``communication``).

Every :class:`~rlenv.environment.RLEnvironment` has one, as ``environment.communication``. As in
the Godot seed, the environment's ``_ready`` starts the server::

    def _ready(self):
        self.world = self.get_node("World")
        self.agent = self.get_node("Agent")
        self.communication.start_server(9090, "127.0.0.1")

and :func:`rlenv.run` runs the main loop: the communication polls for requests in its
``_process`` while the tree stays paused, and the environment serves each one through the same
path as ``rlenv serve`` (the serving host of :mod:`rlenv.serving`: checks, episode state,
snapshots, one answer per request).

When something else hosts the environment (``rlenv serve``, ``ServerProcess``, a vector
environment, a Ray pool, ``LocalClient``), the host's address wins:
:meth:`Communication.start_server` binds nothing more and logs what was asked. There is only
ever one server, the host's.

The communication is also how an environment's default hooks reach the serving path
(:meth:`Communication.dispatch`, :meth:`Communication.configure`,
:meth:`Communication.send_response`): an override of a hook calls ``super()``, which calls
these.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any, Protocol

from rlenv.node import Node, ProcessMode

__all__ = ["Communication", "Served"]

logger = logging.getLogger(__name__)


class Served(Protocol):
    """What serves an environment's requests (:class:`rlenv.serving._instance.Instance`)."""

    def dispatch(self, request: Mapping[str, Any]) -> None:
        """Apply every part of a checked request in order, and answer it."""

    def apply_config(self, configuration_request: Mapping[str, Any]) -> None:
        """Apply a checked ``config`` part to the environment, its agents and its world."""

    def respond(self, observation_request: Mapping[str, Any] | None) -> None:
        """Gather the answer (the observation asked for, rewards, flags, info) and send it."""


class SelfHosting(Protocol):
    """The server :func:`rlenv.run` builds around an environment it hosts itself."""

    def listen(self, port: int, host: str) -> tuple[str, int]:
        """Bind ``host:port``; the bound address."""

    def poll(self) -> None:
        """Wait for the next request (until the next tick is due, in real time); serve it."""


class Communication(Node):
    """The environment's TCP server, as the seed's environment holds it.

    A node, so that when the environment hosts itself (:func:`rlenv.run`) it polls in its own
    ``_process`` in every frame, paused or not (its process mode is ``ALWAYS``), while the
    agents and the world stay pausable; it is in the tree only then.

    Attributes:
        address: the (host, port) the environment listens on, once :meth:`start_server` bound
            it (``None`` when hosted by something else, or before).
    """

    def __init__(self, name: str = "Communication") -> None:
        super().__init__(name, process_mode=ProcessMode.ALWAYS)
        self.address: tuple[str, int] | None = None
        self._served: Served | None = None
        self._self_hosting: SelfHosting | None = None
        self.set_process(False)

    def start_server(self, port: int, host: str = "127.0.0.1") -> None:
        """Listen for clients on ``host:port`` (port 0 picks a free one; see :attr:`address`).

        Call it from the environment's ``_ready``. Under :func:`rlenv.run` it binds the socket
        (a token from ``$RLENV_TOKEN`` is required to bind beyond loopback); when ``rlenv
        serve``, a launcher, a vector or a pool hosts the environment, their address wins and
        this only logs what was asked.

        Raises:
            OSError: the address cannot be bound (the port is in use, say).
            rlenv.serving._endpoint.InsecureBindError: a non-loopback ``host`` without a token.
        """
        if self._self_hosting is None:
            logger.info(
                "%s asked to listen on %s:%s; it is hosted by a server whose address "
                "wins, so nothing more is bound",
                self.name if self.parent is None else self.parent.name,
                host,
                port,
            )
            return
        self.address = self._self_hosting.listen(port, host)

    def poll(self) -> None:
        """Serve the next request if one comes (blocking while the tree has nothing to do).

        Only under :func:`rlenv.run`; a hosted environment's requests are served by its host.
        """
        if self._self_hosting is not None:
            self._self_hosting.poll()

    def _process(self, delta: float) -> None:
        self.poll()

    # --- what the environment's default hooks call ------------------------------------------

    def dispatch(self, request: Mapping[str, Any]) -> None:
        """Serve a request: apply its parts in order through the hooks, then answer it.

        The default of :meth:`RLEnvironment._on_got_connection
        <rlenv.environment.RLEnvironment._on_got_connection>`.
        """
        self._serving().dispatch(request)

    def configure(self, configuration_request: Mapping[str, Any]) -> None:
        """Apply a checked configuration to the environment, its agents and its world.

        The default of :meth:`RLEnvironment._configure
        <rlenv.environment.RLEnvironment._configure>`.
        """
        self._serving().apply_config(configuration_request)

    def send_response(self, observation_request: Mapping[str, Any] | None) -> None:
        """Gather the answer (what ``observation_request`` asks for, rewards, flags, info).

        The default of :meth:`RLEnvironment._send_response
        <rlenv.environment.RLEnvironment._send_response>`; the answer goes out once the
        request has been served, then ``_after_send_response`` runs.
        """
        self._serving().respond(observation_request)

    # --- binding (by the serving path) ------------------------------------------------------

    def bind(self, served: Served) -> None:
        """Attach to what serves the environment's requests (its serving instance)."""
        self._served = served

    def host_itself(self, self_hosting: SelfHosting) -> None:
        """Make :meth:`start_server` bind, and :meth:`poll` serve, through ``self_hosting``.

        :func:`rlenv.run` calls it before the environment enters its tree.
        """
        self._self_hosting = self_hosting
        self.set_process(True)

    def _serving(self) -> Served:
        if self._served is None:
            raise RuntimeError(
                "the environment is not served: host it with rlenv.run, "
                "rlenv serve or a client (LocalClient, RemoteEnv)"
            )
        return self._served
