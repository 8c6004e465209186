"""A vector's reset path: resets in batches, and the starts ``set_next_reset`` sets aside.

:class:`Resets` resets sub-environments of a :class:`~rlenv_client.vector.RemoteVectorEnv`
(all of them at :meth:`~rlenv_client.vector.RemoteVectorEnv.reset`, those that ended within a
``SAME_STEP`` step) with one ``batch`` per server. It keeps each sub-environment's next start,
:meth:`~rlenv_client.vector.RemoteVectorEnv.set_next_reset`'s seed, options and settings,
until the reset that takes it: one of those batches, or an autoreset inside a step (the
``steps`` request's ``reset_with``, protocol 2.4).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from rlenv.protocol import Request
from rlenv_client._messages import reset_part
from rlenv_client._rows import set_row
from rlenv_client.base import BaseClient
from rlenv_client.inspection import config_request
from rlenv_client.session import Session
from rlenv_client.vector_servers import exchange, sure_reply

__all__ = ["Resets"]


class Resets:
    """The resets of a vector's sub-environments (see the module docstring).

    Args:
        sessions: the vector's servers (the list itself: a restarted server's client is found).
        groups: the sub-environments each session hosts.
        client_of: the client of a sub-environment's server.
        complete: while agents come and go, what gives a reset's observation (its starting
            agents') an entry for every agent (zeros); ``None`` otherwise.
    """

    def __init__(
        self,
        sessions: list[Session],
        groups: list[range],
        client_of: Callable[[int], BaseClient],
        complete: Callable[[Mapping[str, Any]], Any] | None = None,
    ) -> None:
        self._sessions, self._groups, self._client_of = sessions, groups, client_of
        self._complete = complete
        count = sum(len(group) for group in groups)
        self._starts: list[dict[str, Any] | None] = [None] * count  # set_next_reset's
        self._pending = 0  # how many of them are set

    def set_next(
        self,
        index: int,
        seed: int | None,
        options: Mapping[str, Any] | None,
        config: Mapping[str, Any] | None,
    ) -> None:
        """Sub-environment ``index``'s next start (see ``RemoteVectorEnv.set_next_reset``)."""
        start: dict[str, Any] = {"reset": reset_part(None if seed is None else int(seed), options)}
        if config:
            arguments = dict(config)
            start["config"] = config_request(
                {key: value for key, value in arguments.items() if key not in ("agent", "world")},
                arguments.get("agent"),
                arguments.get("world"),
            )
        if self._starts[index] is None:
            self._pending += 1
        self._starts[index] = start

    def reset(
        self,
        indices: Iterable[int],
        observations: Any,
        frames: np.ndarray,
        seeds: Sequence[int | None] | None = None,
        options: Mapping[str, Any] | None = None,
        due: Mapping[str, np.ndarray] | None = None,
    ) -> dict[int, dict[str, Any]]:
        """Reset the sub-environments ``indices``, a batch per server, each with its next start.

        A sub-environment without a start set resets with ``seeds[index]`` and ``options``.
        Their observations and ticks are written in their rows of ``observations`` and
        ``frames``; while agents come and go, whether each agent starts in its row of ``due``.

        Returns:
            Each one's info (``frames`` taken out), by sub-environment.

        Raises:
            RemoteError: a reset was refused.
            ConnectionLost: a server went away (with how it exited, if it died).
        """
        plan: list[Request | None] = [None] * len(self._starts)
        for index in indices:
            plan[index] = self._request(index, None if seeds is None else seeds[index], options)
        infos = {}
        for index, reply in enumerate(exchange(self._sessions, self._groups, plan)):
            if plan[index] is not None:
                observation, info = self._client_of(index).reset_result(sure_reply(index, reply))
                if self._complete is not None:
                    for name, column in (due or {}).items():
                        column[index] = name in observation
                    observation = self._complete(observation)
                set_row(observations, index, observation)
                frames[index] = info.pop("frames")
                infos[index] = info
        return infos

    def take_marked(self, resetting: np.ndarray) -> list[dict[str, Any] | None] | None:
        """The starts of the sub-environments ``resetting`` marks (taken), or ``None``.

        They travel in a ``steps`` request's ``reset_with``.
        """
        if not self._pending:
            return None
        starts: list[dict[str, Any] | None] = [None] * len(self._starts)
        for index in np.flatnonzero(resetting):
            starts[index] = self._take(int(index))
        return starts if any(start is not None for start in starts) else None

    def _request(self, index: int, seed: int | None, options: Mapping[str, Any] | None) -> Request:
        """The request that resets sub-environment ``index``: its next start if set, once."""
        client = self._client_of(index)
        start = self._take(index)
        if start is None:
            return client.reset_request(seed, options)
        reset = start["reset"]
        request = client.reset_request(reset.get("seed"), reset.get("options"))
        if "config" in start:
            request = Request(request.id, {"config": start["config"], **request.parts})
        return request

    def _take(self, index: int) -> dict[str, Any] | None:
        """Sub-environment ``index``'s next start, no longer set; ``None`` if none was."""
        start = self._starts[index]
        if start is not None:
            self._starts[index] = None
            self._pending -= 1
        return start
