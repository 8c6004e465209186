"""A vector's servers and the sub-environments each hosts; a step sent to all of them at once.

:class:`ServerGroups` is what a :class:`~rlenv_client.vector.RemoteVectorEnv` holds of the
layout of its servers: which consecutive sub-environments each session hosts (its group), whose
each sub-environment is, whether the servers agree on the spaces, and the order in which a
step's answers are awaited. :meth:`ServerGroups.step` sends every server its share of a step in
one ``steps`` request, then gathers their answers into
:class:`~rlenv_client._step_columns.StepColumns`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from itertools import accumulate
from typing import Any

import numpy as np

from rlenv.protocol.errors import RemoteError
from rlenv_client._rows import rows
from rlenv_client._step_columns import StepColumns
from rlenv_client.base import BaseClient
from rlenv_client.session import LOST, Session

__all__ = ["ServerGroups"]


class ServerGroups:
    """The sub-environments of ``sessions``, each session's consecutive to the previous one's.

    Args:
        sessions: the vector's sessions, connected (the list itself is held: a restarted
            server's session stays in its place).
    """

    def __init__(self, sessions: list[Session]) -> None:
        self.sessions = sessions
        sizes = [session.client.hello.instances for session in sessions]
        self.groups = [
            range(end - size, end)  # the sub-environments each session hosts
            for size, end in zip(sizes, accumulate(sizes), strict=True)
        ]
        self._owner = [number for number, group in enumerate(self.groups) for _ in group]
        self.gather_order = list(range(len(sessions)))[::-1]
        """The order in which a step's answers are awaited: the server that answered last comes
        first, so that this process sleeps until all have answered rather than waking for
        each (on a small machine, it shares a core with a server it would slow down)."""

    @property
    def num_envs(self) -> int:
        """How many sub-environments the servers host in all."""
        return len(self._owner)

    def client_of(self, index: int) -> BaseClient:
        """The client of the server that hosts sub-environment ``index``."""
        return self.sessions[self._owner[index]].client

    def check(self, num_envs: int | None) -> None:
        """Check that the servers declare the same spaces, and host ``num_envs`` if given.

        Raises:
            ValueError: a server declares other spaces than the first, or the servers host
                another number of sub-environments than ``num_envs``.
        """
        clients = [session.client for session in self.sessions]
        first = clients[0]
        for client in clients[1:]:
            if (client.action_space, client.observation_space) != (
                first.action_space,
                first.observation_space,
            ):
                raise ValueError(f"{client.address} has other spaces than {first.address}")
        if num_envs is not None and num_envs != self.num_envs:
            raise ValueError(
                f"num_envs={num_envs}, but the servers given host {self.num_envs} sub-environments"
            )

    def step(
        self,
        actions: Any,
        resetting: np.ndarray,
        repeat_action: int | None,
        starts: Sequence[Mapping[str, Any] | None] | None,
        columns: StepColumns,
        last: Any,
    ) -> None:
        """Send every server its share of a step, then fill ``columns`` with their answers.

        Args:
            actions: every sub-environment's action (the driven agents' included).
            resetting: which sub-environments reset instead of stepping.
            repeat_action: physics ticks per step (``None``: the servers' default).
            starts: the parts of each sub-environment's reset (``reset_with``), or ``None``.
            columns: the step's columns, filled here.
            last: the last batch of observations returned (``None`` before any): a server
                lost and restarted gives its sub-environments their row of it, truncated,
                with ``info["server_restarted"]``.

        Raises:
            RemoteError: a server refused its share (the first server's refusal is raised),
                once every server's answer was read.
            ConnectionLost: a server went away before any observation, or for good.
        """
        for session, group in zip(self.sessions, self.groups, strict=True):
            try:
                session.client.send_steps(
                    rows(actions, group.start, group.stop),
                    resetting[group.start : group.stop],
                    repeat_action,
                    None if starts is None else starts[group.start : group.stop],
                )
            except LOST as error:
                raise session.failure(error) from None
        refusals: dict[int, RemoteError] = {}  # by server: the first one's is raised
        order = self.gather_order
        late: list[int] = []
        for turn, number in enumerate(order):
            if turn == 1:  # the first awaited answered: are any of the others still at work?
                late = [
                    other for other in order[1:] if not self.sessions[other].client.answer_arrived()
                ]
            session, group = self.sessions[number], self.groups[number]
            try:
                answer = session.client.receive_steps(copy=False)  # copied into columns
                refused = columns.fill(group, answer)
                if refused is not None:
                    refusals[number] = refused
            except RemoteError as error:  # read every server's answer before raising
                refusals[number] = error
            except LOST as error:
                if last is None:
                    raise session.failure(error) from None
                columns.cut_short(group, last, {"server_restarted": session.restart(error)})
        if late:  # it answered after the one awaited first: await it first next time
            self.gather_order = [late[-1], *(n for n in order if n != late[-1])]
        if refusals:
            raise refusals[min(refusals)]
