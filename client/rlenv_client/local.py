"""LocalClient: the same client API, with the environment inside this process and no socket.

The environment runs in its own :class:`~rlenv.tree.SceneTree` exactly as under ``rlenv serve``:
requests go through the same ``RLEnvironment`` code (checks, order, repeat_action, episode
state), only the transport differs (see :class:`rlenv.instance.Instance`). Use it to debug an
environment with a debugger and breakpoints, and as the baseline that remote figures are
compared with. It imports the server runtime (and pymunk) only when created.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from rlenv.errors import ConnectionLost
from rlenv.protocol import ErrorReply, Request, Response
from rlenv_client.base import BaseClient

if TYPE_CHECKING:
    from rlenv.environment import RLEnvironment
    from rlenv.instance import Instance

__all__ = ["LocalClient"]


class LocalClient(BaseClient):
    """Drive an environment class in this process, through the client API.

    Args:
        environment: an environment instance, its class, or ``MODULE:CLASS``.
        world_data: also ask for the world's data on reset and step (``info["world"]``).
        clock: the tree's clock for real-time mode (e.g. ``rlenv.testing.ManualClock``).
    """

    def __init__(
        self, environment: RLEnvironment | type[RLEnvironment] | str, *, world_data: bool = False,
        clock: Callable[[], float] | None = None,
    ) -> None:
        from rlenv.instance import Instance

        super().__init__(world_data=world_data)
        self._instance: Instance | None = Instance(environment, clock or time.monotonic)
        self.environment = self._instance.environment
        self.address = f"in-process {self.environment.name}"
        self._set_hello(self._instance.hello)

    def close(self) -> None:
        """Take the environment out of its tree; safe to repeat."""
        if self._instance is not None:
            self._instance.close()
            self._instance = None

    def __enter__(self) -> LocalClient:
        return self

    def _send(self, request: Request) -> None:
        if self._instance is None:
            raise ConnectionLost(f"{self.address} is closed")
        self._instance.submit(request)

    def _receive(self) -> Response | ErrorReply:
        instance = self._instance
        if instance is None:
            raise ConnectionLost(f"{self.address} is closed")
        return instance.wait()
