"""LocalClient: the same client API, with the environment inside this process and no socket.

The environment runs in its own :class:`~rlenv.tree.SceneTree` exactly as under ``rlenv serve``:
requests go through the same ``RLEnvironment`` code (checks, order, repeat_action, episode
state), only the transport differs (see :class:`rlenv.instance.Instance`). Use it to debug an
environment with a debugger and breakpoints, and as the baseline that remote figures are
compared with. It imports the server runtime (and pymunk) only when created. With
``instances=K`` it holds K instances as ``rlenv serve --instances K`` does (batch and ``steps``
requests; :class:`~rlenv_client.vector.RemoteVectorEnv` uses it for ``in_process=True``).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

from rlenv.errors import ConnectionLost
from rlenv.protocol import Reply, Request
from rlenv_client.base import BaseClient

if TYPE_CHECKING:
    from rlenv.environment import RLEnvironment
    from rlenv.group import InstanceGroup
    from rlenv.instance import Instance

__all__ = ["LocalClient"]


class LocalClient(BaseClient):
    """Drive an environment class in this process, through the client API.

    Args:
        environment: an environment instance, its class, or ``MODULE:CLASS``.
        world_data: also ask for the world's data on reset and step (``info["world"]``).
        clock: the tree's clock for real-time mode (e.g. ``rlenv.testing.ManualClock``).
        instances: how many instances of the environment class to hold (see the module
            docstring); a plain request goes to the first.
    """

    def __init__(
        self, environment: RLEnvironment | type[RLEnvironment] | str, *, world_data: bool = False,
        clock: Callable[[], float] | None = None, instances: int = 1,
    ) -> None:
        from rlenv.group import InstanceGroup
        from rlenv.instance import Instance

        super().__init__(world_data=world_data)
        self._instance: Instance | None = None
        self._group: InstanceGroup | None = None
        self._replies: deque[Reply] = deque()  # the group's answers, until received
        if instances == 1:  # as a single-instance server: no batch, no steps
            self._instance = Instance(environment, clock or time.monotonic)
            self.environment = self._instance.environment
            self._set_hello(self._instance.hello)
        else:
            if not isinstance(environment, type | str):
                raise TypeError("several instances need the environment class, not an instance")
            self._group = InstanceGroup(environment, instances, clock or time.monotonic)
            self.environment = self._group.instances[0].environment
            self._set_hello(self._group.hello)
        self.address = f"in-process {self.environment.name}"

    def close(self) -> None:
        """Take the environments out of their trees; safe to repeat."""
        for holder in (self._instance, self._group):
            if holder is not None:
                holder.close()
        self._instance = self._group = None

    def __enter__(self) -> LocalClient:
        return self

    def _send(self, request: Request) -> None:
        if self._group is not None:
            self._replies.append(self._group.answer(request))
        elif self._instance is not None:
            self._instance.submit(request)
        else:
            raise ConnectionLost(f"{self.address} is closed")

    def _receive(self) -> Reply:
        if self._group is not None:
            return self._replies.popleft()
        if self._instance is None:
            raise ConnectionLost(f"{self.address} is closed")
        return self._instance.wait()
