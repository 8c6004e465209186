"""Where a vector's sub-environments live: servers, how many hold how many, and batches to them.

:class:`~rlenv_client.vector.RemoteVectorEnv` steps its servers in columns; what it needs to
lay them out and to send them batches (resets, renders) is here: :func:`default_layout` (one
server per core, or per core but those left to the trainer), :func:`server_places`,
:func:`connect_sessions` and :func:`exchange`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from rlenv.protocol import ErrorReply, Request, Response
from rlenv_client.session import LOST, ServerSource, Session

__all__ = ["connect_sessions", "default_layout", "exchange", "server_places", "sure_reply"]

Reply = Response | ErrorReply


def default_layout(num_envs: int, cores: int | None = None, trainer_cores: int = 0) -> list[int]:
    """Instances per server for ``num_envs`` environments: one server per core, shared fairly.

    ``trainer_cores`` of the ``cores`` (this machine's by default) are left to the trainer,
    but one server there always is.
    """
    servers = max(1, min(num_envs, (cores or os.cpu_count() or 1) - trainer_cores))
    share = math.ceil(num_envs / servers)
    return [min(share, num_envs - start) for start in range(0, num_envs, share)]


def server_places(
    num_envs: int | None,
    target: str | None,
    addresses: Sequence[str] | None,
    pool: ServerSource | None,
    in_process: bool,
    token: str | None,
    instances_per_server: int | None,
    server_args: Sequence[str] = (),
) -> list[dict[str, Any]]:
    """Where each server's share of a vector is: the :class:`Session` arguments of each.

    A pool's servers, running servers by address, or servers to start (``instances_per_server``
    each, or :func:`default_layout`'s; started with ``server_args``), or groups in this process.

    Raises:
        ValueError: no sub-environment at all.
    """
    if pool is not None:
        places: list[dict[str, Any]] = [
            {"pool": pool, "index": index} for index in range(pool.servers)
        ]
    elif addresses is not None:
        places = [{"address": address, "token": token} for address in addresses]
    else:
        num_envs = 1 if num_envs is None else num_envs
        if instances_per_server is not None:
            layout = [
                min(instances_per_server, num_envs - start)
                for start in range(0, num_envs, instances_per_server)
            ]
        else:  # in this process: all in one group; else one server per core
            layout = [num_envs] if in_process else default_layout(num_envs)
        places = [
            {
                "target": target,
                "in_process": in_process,
                "instances": count,
                "server_args": server_args,
            }
            for count in layout
        ]
    if not places:
        raise ValueError("a vector environment needs at least one sub-environment")
    return places


def connect_sessions(sessions: list[Session], places: list[dict[str, Any]], **options: Any) -> None:
    """Open a :class:`Session` for each of ``places`` (in parallel), appended to ``sessions``.

    If any fails, every one opened is closed and the first failure raised: nothing leaks.
    """
    with ThreadPoolExecutor(max_workers=min(len(places), 16)) as pool:
        futures = [pool.submit(Session, **place, **options) for place in places]
        failure: BaseException | None = None
        for future in futures:
            try:
                sessions.append(future.result())
            except BaseException as error:  # keep collecting, so that nothing leaks
                failure = failure or error
    if failure is not None:
        for session in sessions:
            session.close()
        raise failure


def exchange(
    sessions: Sequence[Session], groups: Sequence[range], plan: list[Request | None]
) -> list[Reply | None]:
    """Send every server its share of ``plan`` as a batch, then gather the replies.

    ``groups[i]`` are the sub-environments of ``sessions[i]``; the replies come in
    sub-environment order (``None`` where ``plan`` held none).

    Raises:
        ConnectionLost: a server was lost, with how it exited.
    """
    sent = []
    for session, group in zip(sessions, groups, strict=True):
        parts = [plan[index] for index in group]
        if all(part is None for part in parts):
            sent.append(False)
            continue
        try:
            session.client.send_batch(parts)
        except LOST as error:
            raise session.failure(error) from None
        sent.append(True)
    replies: list[Reply | None] = [None] * len(plan)
    for session, group, was_sent in zip(sessions, groups, sent, strict=True):
        if not was_sent:
            continue
        try:
            answers = session.client.receive_batch()
        except LOST as error:
            raise session.failure(error) from None
        for index, answer in zip(group, answers, strict=False):
            replies[index] = answer
    return replies


def sure_reply(index: int, reply: Reply | None) -> Reply:
    """``reply``, which sub-environment ``index`` must have had."""
    if reply is None:
        raise RuntimeError(f"sub-environment {index} got no reply")
    return reply
