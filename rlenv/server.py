"""Host an environment: build its tree, open its endpoint, run the loop."""

from __future__ import annotations

import importlib
import logging

from rlenv.communication import DEFAULT_HOST, Communication
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
    """

    def __init__(
        self, environment: RLEnvironment | type[RLEnvironment] | str, host: str = DEFAULT_HOST,
        port: int = 0, lifeline: int | None = None,
    ) -> None:
        if isinstance(environment, str):
            environment = load_environment(environment)
        if isinstance(environment, type):
            environment = environment()
        self.environment = environment
        self.tree = SceneTree(environment.physics_ticks_per_second)
        self.tree.root.add_child(environment)
        environment.hello()  # fail here, not at the first client, if the environment is incomplete
        if not isinstance(environment.communication, Communication):
            raise TypeError(f"{environment!r} already has an in-process endpoint")
        self.address = environment.communication.start_server(port, host)
        if lifeline is not None:
            environment.communication.watch_lifeline(lifeline)

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
