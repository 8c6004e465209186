"""LocalClient: the same client API, with the environment inside this process and no socket.

The environment runs exactly as under ``rlenv serve``: requests enter the same
:class:`~rlenv.serving._host.Host` by the same door (checks, order, repeat_action, episode
state, values in packed form); only the transport differs. Use it to debug an environment with
a debugger and breakpoints, and as the baseline that remote figures are compared with. It
imports the server runtime (and pymunk) only when created. With ``instances=K`` it holds K
instances as ``rlenv serve --instances K`` does (:class:`~rlenv_client.vector.RemoteVectorEnv`
uses it for ``in_process=True``).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from rlenv.protocol import Reply, Request
from rlenv.protocol.errors import ConnectionLost
from rlenv_client.base import BaseClient

if TYPE_CHECKING:
    from rlenv.environment import RLEnvironment
    from rlenv.serving._host import Host

__all__ = ["LocalClient"]


class LocalClient(BaseClient):
    """Drive an environment class in this process, through the client API.

    Args:
        environment: an environment instance, its class, or ``MODULE:CLASS``.
        world_data: also ask for the world's data on reset and step (``info["world"]``).
        clock: the trees' clock for real-time mode (e.g. ``rlenv.testing.ManualClock``).
        instances: how many instances of the environment class to hold; a plain request goes
            to the first.
        policies: what drives agents, by agent name, as ``rlenv serve --policy`` (an ONNX
            file, or ``"heuristic"``; see :mod:`rlenv.serving.policy_driver`). The hello's
            ``driven`` names them. They may not drive every agent.

    Attributes:
        host: the instances and how requests reach them (``None`` once closed).
    """

    def __init__(
        self,
        environment: RLEnvironment | type[RLEnvironment] | str,
        *,
        world_data: bool = False,
        clock: Callable[[], float] | None = None,
        instances: int = 1,
        policies: Mapping[str, str | Path] | None = None,
    ) -> None:
        from rlenv.serving._host import Host
        from rlenv.serving.policy_driver import load_policies

        super().__init__(world_data=world_data)
        self.host: Host | None = Host(
            environment,
            instances,
            clock=clock or time.monotonic,
            policies=load_policies(policies or {}),
        )
        if self.host.driver is not None:
            self.host.close()
            raise ValueError(
                "policies drive every agent, so nothing is left to control in "
                "process; serve it (rlenv serve --policy) to watch it play"
            )
        self._replies: deque[Reply] = deque()  # answers not received yet
        self._first = self.host.instances[0]
        self.address = f"in-process {self.environment.name}"
        self._set_hello(self.host.hello)

    @property
    def environment(self) -> RLEnvironment:
        """The first instance's environment node (a new one once rebuilt after an error)."""
        return self._first.environment

    def close(self) -> None:
        """Take the environments out of their trees; safe to repeat."""
        if self.host is not None:
            self.host.close()
            self.host = None

    def __enter__(self) -> LocalClient:
        return self

    def _send(self, request: Request) -> None:
        host = self.host
        if host is None:
            raise ConnectionLost(f"{self.address} is closed")
        try:
            reply = host.answer(request)
        except BaseException as error:  # interrupted (KeyboardInterrupt) half way
            host.abandon(
                f"a request was interrupted ({type(error).__name__}) while the "
                "environment served it"
            )
            raise
        self._replies.append(reply)

    def _receive(self, copy: bool = True) -> Reply:
        if not self._replies:
            raise ConnectionLost(f"{self.address} is closed")
        return self._replies.popleft()
