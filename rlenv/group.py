"""InstanceGroup: K instances of one environment answering requests as one multi-instance server.

A plain request goes to instance 0; a batch carries one request per instance and is answered
with one reply per instance (:func:`rlenv.instance.drive`); ``steps`` steps them all in columns
(:class:`rlenv.columns.ColumnStepper`). ``rlenv serve --instances K`` puts a group behind a TCP
endpoint; ``LocalClient(..., instances=K)`` drives one in this process.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

from rlenv.columns import ColumnStepper
from rlenv.environment import RLEnvironment
from rlenv.errors import ErrorCode
from rlenv.instance import Instance, drive, load_environment
from rlenv.protocol import BatchResponse, ErrorReply, Hello, Reply, Request, Response

__all__ = ["InstanceGroup"]


class InstanceGroup:
    """``count`` instances of an environment class, each in its own tree, seeded apart.

    Args:
        environment: the environment class, or ``MODULE:CLASS``.
        count: how many instances.
        clock: the trees' clock, for real-time mode.
    """

    def __init__(self, environment: type[RLEnvironment] | str, count: int,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if isinstance(environment, str):
            environment = load_environment(environment)
        if count < 1:
            raise ValueError("a group holds at least one instance")
        self.instances = [Instance(environment, clock) for _ in range(count)]
        self.hello: Hello = replace(self.instances[0].hello, instances=count)
        self._columns = ColumnStepper(self.instances)

    def answer(self, request: Request) -> Reply:
        """The one answer to ``request`` (plain, batch or steps)."""
        if request.steps is not None:
            return self._columns.answer(request)
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
        """Take every environment out of its tree."""
        for instance in self.instances:
            instance.close()
