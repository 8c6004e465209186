"""LocalClient: the same client API, with the environment inside this process and no socket.

The environment runs in its own :class:`~rlenv.tree.SceneTree` exactly as under ``rlenv serve``:
requests go through the same ``RLEnvironment`` code (checks, order, repeat_action, episode
state), only the transport differs. Use it to debug an environment with a debugger and
breakpoints, and as the baseline that remote figures are compared with. It imports the server
runtime (and pymunk) only when created.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING

from rlenv.errors import ConnectionLost
from rlenv.protocol import ErrorReply, Request, Response
from rlenv_client.base import BaseClient

if TYPE_CHECKING:
    from rlenv.environment import RLEnvironment

__all__ = ["LocalClient"]


class _LocalEndpoint:
    """The environment's side of the in-process transport (see ``rlenv.communication.Endpoint``)."""

    def __init__(self) -> None:
        self.requests: deque[Request] = deque()
        self.replies: deque[Response | ErrorReply] = deque()

    def poll(self, timeout: float | None) -> Request | None:
        return self.requests.popleft() if self.requests else None

    def send(self, message: Response | ErrorReply) -> None:
        self.replies.append(message)

    def close(self) -> None:
        self.requests.clear()


class LocalClient(BaseClient):
    """Drive an environment class in this process, through the client API.

    Args:
        environment: an environment instance, its class, or ``MODULE:CLASS``.
        world_data: also ask for the world's data on reset and step (``info["world"]``).
    """

    def __init__(
        self, environment: RLEnvironment | type[RLEnvironment] | str, *, world_data: bool = False
    ) -> None:
        from rlenv.server import load_environment
        from rlenv.tree import SceneTree

        super().__init__(world_data=world_data)
        if isinstance(environment, str):
            environment = load_environment(environment)
        if isinstance(environment, type):
            environment = environment()
        self.environment = environment
        self._endpoint = _LocalEndpoint()
        environment.communication = self._endpoint
        self._tree: SceneTree | None = SceneTree(environment.physics_ticks_per_second)
        self._tree.root.add_child(environment)
        self.address = f"in-process {environment.name}"
        self._set_hello(environment.hello())

    def close(self) -> None:
        """Take the environment out of its tree; safe to repeat."""
        if self._tree is not None:
            self._tree.root.remove_child(self.environment)
            self._tree = None

    def __enter__(self) -> LocalClient:
        return self

    def _send(self, request: Request) -> None:
        if self._tree is None:
            raise ConnectionLost(f"{self.address} is closed")
        self._endpoint.requests.append(request)

    def _receive(self) -> Response | ErrorReply:
        if self._tree is None:
            raise ConnectionLost(f"{self.address} is closed")
        replies = self._endpoint.replies
        while not replies:
            self.environment.iterate()
        return replies.popleft()
