"""Host an environment: build its tree, open its endpoint, run the loop."""

from __future__ import annotations

import importlib
import logging

from rlenv.communication import DEFAULT_HOST, Communication, Limits
from rlenv.environment import RLEnvironment
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
    """One environment in its own scene tree, listening for its client.

    Args:
        environment: an environment instance, its class, or ``MODULE:CLASS``.
        host: address to bind; 127.0.0.1 unless the environment must be reachable from
            other machines.
        port: port to bind; 0 picks a free one (see :attr:`address`).
        lifeline: read end of a pipe whose write end the starting process holds; the server
            exits when that process is gone (see ``rlenv_client.ServerProcess``).
        token: the secret clients must present; required to bind a non-loopback address.
        limits: frame sizes and deadlines (see :class:`~rlenv.communication.Limits`); the
            defaults if ``None``.

    Raises:
        InsecureBindError: a non-loopback ``host`` without a ``token``.
    """

    def __init__(
        self, environment: RLEnvironment | type[RLEnvironment] | str, host: str = DEFAULT_HOST,
        port: int = 0, lifeline: int | None = None, token: str | None = None,
        limits: Limits | None = None,
    ) -> None:
        if isinstance(environment, str):
            environment = load_environment(environment)
        if isinstance(environment, type):
            environment = environment()
        self.environment = environment
        self.tree = SceneTree(environment.physics_ticks_per_second)
        self.tree.root.add_child(environment)
        environment.hello()  # fail here, not at the first client, if the environment is incomplete
        communication = Communication(environment.hello, limits=limits or Limits(), token=token)
        environment.communication = communication
        self.address = communication.start_server(port, host)
        if lifeline is not None:
            communication.watch_lifeline(lifeline)

    def serve_forever(self) -> None:
        """Run the tree until :meth:`SceneTree.quit` or an interrupt.

        An exception raised by user code while a request is being served is answered with an
        ``environment_error`` reply and the server goes on; any other exception propagates.
        """
        self.tree.run(self.environment.iterate)

    def close(self) -> None:
        """Close the endpoint (the client is disconnected)."""
        self.environment.communication.close()

    def __enter__(self) -> Server:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
