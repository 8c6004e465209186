"""Host an environment: build its tree, open its endpoint, run the loop."""

from __future__ import annotations

import importlib
import logging
from dataclasses import replace
from pathlib import Path
from typing import Any

from rlenv.communication import DEFAULT_HOST, Communication, Limits
from rlenv.environment import RLEnvironment
from rlenv.errors import ErrorCode
from rlenv.protocol import BatchResponse, ErrorReply, Request, Response
from rlenv.tree import SceneTree

__all__ = ["Server", "load_environment"]

logger = logging.getLogger(__name__)


def load_environment(target: str) -> type[RLEnvironment]:
    """Import the environment class named ``MODULE:CLASS``.

    Raises:
        ValueError: ``target`` is not of the form ``MODULE:CLASS``.
        ImportError: the module cannot be imported.
        TypeError: the attribute is not an RLEnvironment subclass.
    """
    module_name, _, class_name = target.partition(":")
    if not module_name or not class_name:
        raise ValueError(f"expected MODULE:CLASS, e.g. examples.cartpole:CartPoleEnvironment, "
                         f"got {target!r}")
    module = importlib.import_module(module_name)
    try:
        environment_class = getattr(module, class_name)
    except AttributeError:
        raise ImportError(f"module {module_name!r} has no attribute {class_name!r}") from None
    if not (isinstance(environment_class, type) and issubclass(environment_class, RLEnvironment)):
        raise TypeError(f"{target} is not an RLEnvironment subclass")
    return environment_class


class Server:
    """Environments in scene trees, listening for their client.

    With ``instances=1`` (the default) the environment drives its own endpoint, as the Godot
    seed's RLEnvironment does. With more, the server hosts that many independent instances of the
    environment class (each its own tree and pymunk space) and answers a batch request (one part
    per instance) with one batch response: one round trip steps them all. A plain request goes to
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
        if instances > 1:
            if not isinstance(environment, type):
                raise TypeError("several instances need the environment class, not an instance")
            from rlenv.instance import Instance

            self.instances = [Instance(environment) for _ in range(instances)]
            hello = replace(self.instances[0].hello, instances=instances)
            self.environment = self.instances[0].environment
            self.tree = self.instances[0].tree
            self.communication = Communication(lambda: hello, limits=limits or Limits(),
                                               token=token)
        else:
            if isinstance(environment, type):
                environment = environment()
            self.instances = []
            self.environment = environment
            self.tree = SceneTree(environment.physics_ticks_per_second)
            self.tree.root.add_child(environment)
            environment.hello()  # fail here, not at the first client, if it is incomplete
            self.communication = Communication(environment.hello, limits=limits or Limits(),
                                               token=token)
            environment.communication = self.communication
        for hosted in [instance.environment for instance in self.instances] or [self.environment]:
            hosted.record_dir = record_dir
            hosted.real_time = real_time
        self.address = self.communication.start_server(port, host)
        if lifeline is not None:
            self.communication.watch_lifeline(lifeline)

    def serve_forever(self) -> None:
        """Serve until :meth:`SceneTree.quit` (one instance) or an interrupt.

        An exception raised by user code while a request is being served is answered with an
        ``environment_error`` reply and the server goes on; any other exception propagates.
        """
        if not self.instances:
            self.tree.run(self.environment.iterate)
            return
        from rlenv.instance import drive

        while True:
            request = self.communication.poll(None)
            if request is not None:
                self.communication.send(self._answer(request, drive))

    def _answer(self, request: Request, drive: Any) -> Response | BatchResponse | ErrorReply:
        if request.batch is None:
            if request.asks_nothing:
                return Response(id=request.id)  # e.g. the token
            reply = drive(self.instances[:1], [request])[0]
            assert reply is not None
            return reply
        if len(request.batch) > len(self.instances):
            return ErrorReply(request.id, ErrorCode.BAD_REQUEST,
                              f"a batch of {len(request.batch)} requests for "
                              f"{len(self.instances)} instances")
        return BatchResponse(request.id, tuple(drive(self.instances, list(request.batch))))

    def close(self) -> None:
        """Close the endpoint (every client is disconnected)."""
        self.communication.close()

    def __enter__(self) -> Server:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
