"""Instance: one environment in its own scene tree, fed requests directly (no socket).

The environment answers exactly as it does under a TCP endpoint (same checks, same order, same
episode state); only the transport differs: requests are queued on an in-process endpoint and
the tree is iterated until the answer appears. ``rlenv_client.LocalClient`` drives one instance;
a server that hosts several instances (``rlenv serve --instances K``, :mod:`rlenv.group`)
drives K of them, each with its own tree and pymunk space, stepped together by one batch or
``steps`` request.
"""

from __future__ import annotations

import importlib
import time
from collections import deque
from collections.abc import Callable

from rlenv.environment import RLEnvironment
from rlenv.protocol import ErrorReply, Hello, Request, Response
from rlenv.tree import SceneTree

__all__ = ["Instance", "drive", "load_environment"]

Reply = Response | ErrorReply


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



class _DirectEndpoint:
    """The environment's side of the in-process transport (a ``communication.Endpoint``)."""

    def __init__(self) -> None:
        self.requests: deque[Request] = deque()
        self.replies: deque[Reply] = deque()

    def poll(self, timeout: float | None) -> Request | None:
        return self.requests.popleft() if self.requests else None

    def send(self, message: Reply) -> None:
        self.replies.append(message)

    def close(self) -> None:
        self.requests.clear()


class Instance:
    """An environment in a tree of its own, answering requests handed to it.

    Args:
        environment: an environment instance, its class, or ``MODULE:CLASS``.
        clock: the tree's clock, for real-time mode (tests pass a manual one).
    """

    def __init__(self, environment: RLEnvironment | type[RLEnvironment] | str,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if isinstance(environment, str):
            environment = load_environment(environment)
        if isinstance(environment, type):
            environment = environment()
        self.environment = environment
        self._endpoint = _DirectEndpoint()
        environment.communication = self._endpoint
        self.tree = SceneTree(environment.physics_ticks_per_second, clock=clock)
        self.tree.root.add_child(environment)
        self.hello: Hello = environment.hello()

    def submit(self, request: Request) -> None:
        """Queue ``request``; its answer comes out of :meth:`turn` or :meth:`call`."""
        self._endpoint.requests.append(request)

    def turn(self) -> Reply | None:
        """Run one turn of the tree's loop; the oldest answer, if one is ready."""
        replies = self._endpoint.replies
        if not replies:
            self.tree.iteration()
        return replies.popleft() if replies else None

    def call(self, request: Request) -> Reply:
        """Submit ``request`` and run the tree until it is answered."""
        self.submit(request)
        return self.wait()

    def wait(self) -> Reply:
        """Run the tree until the oldest submitted request is answered; that answer."""
        while (reply := self.turn()) is None:
            pass
        return reply

    def close(self) -> None:
        """Take the environment out of its tree."""
        if self.environment.parent is not None:
            self.tree.root.remove_child(self.environment)


def drive(instances: list[Instance], requests: list[Request | None]) -> list[Reply | None]:
    """Answer one request per instance (``None``: leave that instance alone), in order.

    Returns one answer per instance (``None`` where none was asked).
    """
    replies: list[Reply | None] = [None] * len(instances)
    for index, (instance, request) in enumerate(zip(instances, requests, strict=False)):
        if request is not None:
            replies[index] = instance.call(request)
    return replies
