"""Host an environment: build its tree, open its endpoint, run the loop."""

from __future__ import annotations

import logging
from pathlib import Path

from rlenv.communication import DEFAULT_HOST, Communication, Limits
from rlenv.environment import RLEnvironment
from rlenv.group import InstanceGroup
from rlenv.instance import Instance, load_environment

__all__ = ["Server", "load_environment"]

logger = logging.getLogger(__name__)


class Server:
    """Environments in scene trees, listening for their client.

    With ``instances=1`` (the default) the environment drives its own endpoint, as the Godot
    seed's RLEnvironment does. With more, the server hosts that many independent instances of the
    environment class (each its own tree and pymunk space) and answers a batch request (one part
    per instance) with one batch response, and a ``steps`` request (every instance steps, in
    columns) with one steps response: one round trip steps them all. A plain request goes to
    instance 0.

    Args:
        environment: an environment instance, its class, or ``MODULE:CLASS`` (a class or
            ``MODULE:CLASS`` when ``instances`` > 1).
        host: address to bind; 127.0.0.1 unless the environment must be reachable from
            other machines.
        port: port to bind; 0 picks a free one (see :attr:`address`).
        lifeline: read end of a pipe whose write end the starting process holds; the server
            exits when that process is gone (see ``rlenv_client.ServerProcess``).
        token: the secret clients must present; required to bind a non-loopback address.
        limits: frame sizes and deadlines (see :class:`~rlenv.communication.Limits`); the
            defaults if ``None``.
        instances: how many environment instances to host.
        record_dir: where clients may have the environment record videos (``None``: nowhere).
        real_time: start in real-time mode (ticks follow the wall clock).

    Raises:
        InsecureBindError: a non-loopback ``host`` without a ``token``.
    """

    def __init__(
        self, environment: RLEnvironment | type[RLEnvironment] | str, host: str = DEFAULT_HOST,
        port: int = 0, lifeline: int | None = None, token: str | None = None,
        limits: Limits | None = None, instances: int = 1, record_dir: Path | None = None,
        real_time: bool = False,
    ) -> None:
        if isinstance(environment, str):
            environment = load_environment(environment)
        if instances < 1:
            raise ValueError("a server hosts at least one instance")
        if instances > 1 and not isinstance(environment, type):
            raise TypeError("several instances need the environment class, not an instance")
        # Each Instance checks its environment's hello here, not at the first client.
        self._group: InstanceGroup | None = None
        if instances == 1:  # the environment drives the endpoint itself, as in the Godot seed
            self.instances = [Instance(environment)]
            self.communication = Communication(self.instances[0].environment.hello,
                                               limits=limits or Limits(), token=token)
            self.instances[0].environment.communication = self.communication
        else:
            assert isinstance(environment, type)
            group = self._group = InstanceGroup(environment, instances)
            self.instances = group.instances
            self.communication = Communication(lambda: group.hello, limits=limits or Limits(),
                                               token=token)
        self.environment = self.instances[0].environment
        self.tree = self.instances[0].tree
        for instance in self.instances:
            instance.environment.record_dir = record_dir
            instance.environment.real_time = real_time
        self.address = self.communication.start_server(port, host)
        if lifeline is not None:
            self.communication.watch_lifeline(lifeline)

    def serve_forever(self) -> None:
        """Serve until :meth:`SceneTree.quit` (one instance) or an interrupt.

        An exception raised by user code while a request is being served is answered with an
        ``environment_error`` reply and the server goes on; any other exception propagates.
        """
        if self._group is None:
            self.tree.run()
            return
        while True:
            request = self.communication.poll(None)
            if request is not None:
                self.communication.send(self._group.answer(request))

    def close(self) -> None:
        """Close the endpoint (every client is disconnected)."""
        self.communication.close()

    def __enter__(self) -> Server:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
