"""Sessions: one environment each, gym-http-api style, with limits and an idle reaper.

A :class:`Session` holds a TCP :class:`~rlenv_client.client.Client` of its environment's
server and the :class:`~rlenv_tools.http._runners.Runner` that calls it under a deadline. Its
answers are JSON values (:mod:`rlenv_tools.http.json_spaces`); its refusals are problems
(:class:`~rlenv_tools.http.problems.Problem`).

A session's ``status``:

- ``ready``: created, no episode yet; ``running``: an episode is under way; ``ended``: the
  episode terminated or was truncated (a step is refused until a reset);
- ``timed_out`` (504) and ``lost`` (502, its server died): the session is over and says so
  in every answer until it is deleted; its environment is released at once (a timed-out
  environment's process is killed, on a thread: the event loop never waits for it), and the
  other sessions go on.

Watchers follow a session's transitions through :meth:`Session.watch` (server-sent events:
``id`` is the step's index in the episode, 0 for a reset); a watcher that falls behind loses
the oldest events, never slows the session.

:class:`Sessions` is the table: at most ``max_sessions`` (``session_limit``, 503 with
``Retry-After``: when the first idle session will be reaped), at most
``max_sessions_per_client`` of them created by one client (its address: every client of a
gateway with a token holds the same token), and sessions idle for ``idle_timeout`` seconds are
closed by :meth:`Sessions.reap`. A creation whose client left before its answer was sent is
deleted at once (:meth:`Sessions.abandon`), never left to the reaper.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import math
import secrets
import time
from collections.abc import Callable, Mapping
from enum import StrEnum
from typing import Any, TypeVar

import numpy as np

from rlenv.protocol.errors import ConnectionLost, ErrorCode, RemoteError
from rlenv_client.time_limits import truncate_agents
from rlenv_tools.http._targets import Catalog, Entry, Opened
from rlenv_tools.http.json_spaces import (
    action_decoder,
    dumps,
    space_to_json,
    to_json,
    value_encoder,
)
from rlenv_tools.http.problems import Problem, from_remote_error

__all__ = ["MAX_SESSIONS_PER_CLIENT", "Session", "Sessions", "Status"]

logger = logging.getLogger(__name__)

MAX_SESSIONS_PER_CLIENT = 16
"""Sessions one client (one address) may hold at once by default (``--max-sessions-per-client``)."""

_T = TypeVar("_T")
_WATCH_BACKLOG = 64  # events a watcher may fall behind before the oldest are dropped
_HUNG_GRACE = 0.2  # seconds a timed-out session's server has to exit on SIGTERM (its code
# may never see the signal: a loop inside a pymunk callback) before SIGKILL


class Status(StrEnum):
    """Where a session stands (see the module docstring)."""

    READY = "ready"
    RUNNING = "running"
    ENDED = "ended"
    TIMED_OUT = "timed_out"
    LOST = "lost"


class Session:
    """One environment, driven through its client; see the module docstring.

    Args:
        session_id: the session's id in URLs.
        entry: what ``env_id`` it was created with.
        opened: its environment (client and runner).
        clock: monotonic seconds, for idleness.
        owner: the address of the client that created it (``None``: shared, bevy_rl's).
    """

    def __init__(
        self,
        session_id: str,
        entry: Entry,
        opened: Opened,
        clock: Callable[[], float] = time.monotonic,
        owner: str | None = None,
    ) -> None:
        self.id = session_id
        self.owner = owner
        self.env_id = entry.env_id
        self.max_episode_steps = entry.max_episode_steps
        self.client = opened.client
        self._opened: Opened | None = opened
        self._clock = clock
        self.last_used = clock()
        self.created = time.time()
        self.status = Status.READY
        self.episode = 0
        self.step_index = 0
        self.failure: Problem | None = None
        self.websockets = 0  # open WebSocket conversations: the session is in use
        self._ending = ""
        self._watchers: set[asyncio.Queue[bytes | None]] = set()
        self._encode_observation = value_encoder(self.client.observation_space)
        self._encode_action = value_encoder(self.client.action_space, images=False)
        self._decode_action = action_decoder(self.client.action_space)

    def touch(self) -> None:
        """A request addressed the session: it is not idle."""
        self.last_used = self._clock()

    @property
    def agents(self) -> tuple[str, ...]:
        """The environment's agents, in order."""
        return self.client.hello.agents

    def describe(self) -> dict[str, Any]:
        """The session as ``GET /v1/envs/{id}`` shows it."""
        described: dict[str, Any] = {
            "id": self.id,
            "env_id": self.env_id,
            "status": self.status.value,
            "episode": self.episode,
            "step": self.step_index,
            "agents": list(self.agents),
            "idle_seconds": round(self._clock() - self.last_used, 3),
            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(self.created)),
        }
        if self.max_episode_steps is not None:
            described["max_episode_steps"] = self.max_episode_steps
        if self.failure is not None:
            described["problem"] = self.failure.to_json()
        return described

    def spaces(self) -> dict[str, Any]:
        """The action and observation spaces, as JSON (:func:`space_to_json`)."""
        return {
            "action_space": space_to_json(self.client.action_space),
            "observation_space": space_to_json(self.client.observation_space),
        }

    # --- what clients ask -------------------------------------------------------------------

    async def configure(self, settings: Mapping[str, Any]) -> None:
        """Configure the environment as ``BaseClient.configure(**settings)`` does."""
        await self.call(lambda: self.client.configure(**settings))

    async def reset(
        self, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> dict[str, Any]:
        """Start an episode: ``{"observation", "info"}`` (seed 0 is a seed)."""
        client = self.client
        observation, info = await self.call(
            client.receive_reset, lambda: client.send_reset(seed=seed, options=options)
        )
        self._begin(0)
        answer = {"observation": self._encode_observation(observation), "info": to_json(info)}
        self._publish("reset", answer)
        return answer

    async def step(self, action: Any, repeat_action: int | None = None) -> dict[str, Any]:
        """Act: ``{"observation", "reward", "terminated", "truncated", "info"}``.

        Raises:
            Problem: ``reset_required`` once the episode ended (or before a reset, as the
                environment says), ``invalid_action``, ``bad_request``, and the session's own.
        """
        if self.status is Status.ENDED and self.failure is None:
            raise Problem(ErrorCode.RESET_REQUIRED, f"the episode {self._ending}: reset first")
        action = self._decode_action(action)
        client = self.client
        observation, reward, terminated, truncated, info = await self.call(
            client.receive_step, lambda: client.send_step(action, repeat_action)
        )
        self.step_index += 1
        if (
            self.max_episode_steps is not None
            and self.step_index >= self.max_episode_steps
            and not terminated
        ):
            truncated, info = True, truncate_agents(info)  # each agent still in it too
        if terminated or truncated:
            self.status = Status.ENDED
            self._ending = (
                "terminated"
                if terminated
                else (
                    "was truncated"
                    if self.max_episode_steps is None or self.step_index < self.max_episode_steps
                    else f"reached its time limit of {self.max_episode_steps} steps"
                )
            )
        answer = {
            "observation": self._encode_observation(observation),
            "reward": float(reward),
            "terminated": bool(terminated),
            "truncated": bool(truncated),
            "info": to_json(info),
        }
        self._publish("step", answer)
        return answer

    async def observe(self) -> Any:
        """The agent's current observation, as JSON, without stepping."""
        observed = await self.call(self.client.observe)
        return self._encode_observation(observed["agent"])

    async def render(self, width: int | None = None, height: int | None = None) -> np.ndarray:
        """A frame: ``(height, width, 3)`` uint8."""
        return await self.call(lambda: self.client.render(width, height))

    async def snapshot(self) -> Any:
        """The state as data (``BaseClient.snapshot``), as JSON."""
        return to_json(await self.call(self.client.snapshot))

    async def restore(self, snapshot: Mapping[str, Any]) -> dict[str, Any]:
        """Bring the environment to a snapshot's state: ``{"observation", "info"}``."""
        observation, info = await self.call(lambda: self.client.restore(snapshot))
        events = snapshot.get("events")
        self._begin(
            sum(1 for event in events if event and event[0] == "action")
            if isinstance(events, list)
            else 0
        )
        answer = {"observation": self._encode_observation(observation), "info": to_json(info)}
        self._publish("restore", answer)
        return answer

    def sample(self) -> Any:
        """A random action of the action space, as JSON."""
        return self._encode_action(self.client.action_space.sample())

    # --- the environment's calls, failures --------------------------------------------------

    async def call(self, function: Callable[[], _T], send: Callable[[], None] | None = None) -> _T:
        """``function()`` (a call to :attr:`client`) through the runner, failures as problems.

        With ``send``, ``send()`` sends the request and ``function()`` receives its answer,
        both on the event loop (:meth:`Runner.exchange`); otherwise ``function()`` runs on the
        session's thread (:meth:`Runner.call`).

        Raises:
            Problem: the environment's refusal (its code), or the session's failure:
                ``timeout`` (504) or ``environment_lost`` (502), this time and every next.
        """
        if self.failure is not None or self._opened is None:
            failure = self.failure or Problem("environment_lost", "the session is closed")
            raise Problem(failure.code, failure.detail)
        self.last_used = self._clock()
        runner = self._opened.runner
        try:
            if send is None:
                return await runner.call(function)
            return await runner.exchange(send, function, self.client)
        except RemoteError as error:
            if error.fatal:
                raise await self._fail(
                    Status.LOST,
                    "environment_lost",
                    f"the environment's server closed the connection: {error}",
                ) from None
            raise from_remote_error(error) from None
        except TimeoutError as error:
            raise await self._fail(Status.TIMED_OUT, ErrorCode.TIMEOUT, str(error)) from None
        except ConnectionLost as error:
            raise await self._fail(
                Status.LOST, "environment_lost", f"the environment's server died: {error}"
            ) from None

    async def _fail(self, status: Status, code: str, why: str) -> Problem:
        """Mark the session over (it says so until deleted) and release its environment."""
        self.status = status
        self.failure = Problem(
            code, f"{why}; this session is over: DELETE it and create another (the others go on)"
        )
        logger.warning("session %s (%s): %s", self.id, self.env_id, why)
        self._publish("status", self.describe())
        await self.close(keep_watchers=True, hung=status is Status.TIMED_OUT)
        return Problem(code, self.failure.detail)

    async def close(self, keep_watchers: bool = False, hung: bool = False) -> None:
        """Release the environment (and end its server subprocess); safe to repeat.

        Args:
            keep_watchers: leave the watchers subscribed (they are told of the failure).
            hung: the environment timed out: kill its process almost at once.
        """
        opened, self._opened = self._opened, None
        if not keep_watchers:
            self.end_watches()
        if opened is None:
            return
        try:
            close = functools.partial(opened.close, _HUNG_GRACE) if hung else opened.close
            await asyncio.get_running_loop().run_in_executor(None, close)
        except Exception:  # a half-interrupted environment may fail to close: it is gone anyway
            logger.warning("session %s: closing its environment failed", self.id, exc_info=True)

    # --- watchers ---------------------------------------------------------------------------

    def watch(self) -> asyncio.Queue[bytes | None]:
        """A queue of server-sent events (bytes), ``None`` when the session ends."""
        queue: asyncio.Queue[bytes | None] = asyncio.Queue(_WATCH_BACKLOG)
        self._watchers.add(queue)
        return queue

    def unwatch(self, queue: asyncio.Queue[bytes | None]) -> None:
        """Stop filling ``queue``."""
        self._watchers.discard(queue)

    def end_watches(self) -> None:
        """Tell every watcher the session ended."""
        for queue in self._watchers:
            _offer(queue, None)
        self._watchers.clear()

    def _begin(self, step: int) -> None:
        self.episode += 1
        self.step_index = step
        self.status = Status.RUNNING

    def _publish(self, event: str, data: dict[str, Any]) -> None:
        if not self._watchers:
            return
        body = dumps({"episode": self.episode, "step": self.step_index, **data})
        message = b"id: %d\nevent: %s\ndata: %s\n\n" % (self.step_index, event.encode(), body)
        for queue in self._watchers:
            _offer(queue, message)


def _offer(queue: asyncio.Queue[bytes | None], item: bytes | None) -> None:
    """Put ``item``, dropping the oldest event of a full queue (a watcher never blocks)."""
    if queue.full():
        queue.get_nowait()
    queue.put_nowait(item)


class Sessions:
    """The sessions, by id; see the module docstring.

    Args:
        catalog: the ``env_id`` values served and how they open.
        max_sessions: sessions at once.
        max_sessions_per_client: sessions at once created by one client (one address).
        idle_timeout: seconds without a request after which a session is closed (``None``:
            never).
        clock: monotonic seconds.
    """

    def __init__(
        self,
        catalog: Catalog,
        *,
        max_sessions: int = 32,
        max_sessions_per_client: int = MAX_SESSIONS_PER_CLIENT,
        idle_timeout: float | None = 600.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.catalog = catalog
        self.max_sessions = max_sessions
        self.max_sessions_per_client = max_sessions_per_client
        self.idle_timeout = idle_timeout
        self._clock = clock
        self._sessions: dict[str, Session] = {}
        self._opening: dict[str | None, int] = {}  # creations under way, by client
        self._creating_shared = asyncio.Lock()

    def __len__(self) -> int:
        return len(self._sessions)

    def all(self) -> list[Session]:
        """Every session, oldest first."""
        return list(self._sessions.values())

    def get(self, session_id: str) -> Session:
        """The session ``session_id``.

        Raises:
            Problem: ``unknown_session`` (404).
        """
        session = self._sessions.get(session_id)
        if session is None:
            raise Problem(
                "unknown_session",
                f"no session {session_id!r:.80} (deleted, reaped "
                "after being idle, or never created)",
            )
        return session

    def find(self, session_id: str) -> Session | None:
        """The session ``session_id``, or ``None``."""
        return self._sessions.get(session_id)

    async def create(
        self,
        env_id: object,
        settings: Mapping[str, Any] | None = None,
        session_id: str | None = None,
        owner: str | None = None,
    ) -> Session:
        """Open a session on ``env_id``, configured with ``settings`` (``kwargs``).

        Args:
            env_id: what to open.
            settings: its ``kwargs``.
            session_id: its id (a new random one if ``None``).
            owner: the creating client's address, whose sessions are bounded (``None``: a
                shared session, counted in ``max_sessions`` only).

        Raises:
            Problem: ``bad_request`` (unknown ``env_id``), ``session_limit`` (503 with
                ``Retry-After``: the gateway's limit, or the client's), and the environment's
                failures to open or configure.
        """
        entry = self.catalog.entry(env_id)
        if len(self._sessions) + sum(self._opening.values()) >= self.max_sessions:
            raise Problem(
                "session_limit",
                f"this gateway holds at most {self.max_sessions} sessions; delete "
                "one, or retry once an idle one is reaped",
                headers={"Retry-After": str(self.retry_after())},
            )
        if owner is not None:
            held = [s for s in self._sessions.values() if s.owner == owner]
            if len(held) + self._opening.get(owner, 0) >= self.max_sessions_per_client:
                raise Problem(
                    "session_limit",
                    f"this gateway holds at most {self.max_sessions_per_client} "
                    f"sessions per client, and {owner} has as many; delete one, or "
                    "retry once an idle one is reaped",
                    headers={"Retry-After": str(self.retry_after(held))},
                )
        # counted from now on: concurrent creations respect the limits
        self._opening[owner] = self._opening.get(owner, 0) + 1
        try:
            session = Session(
                session_id or secrets.token_hex(8),
                entry,
                await self.catalog.open(entry),
                self._clock,
                owner,
            )
            if settings:
                try:
                    await session.configure(settings)
                except BaseException:
                    await session.close()
                    raise
            self._sessions[session.id] = session
        finally:
            self._opening[owner] -= 1
            if not self._opening[owner]:
                del self._opening[owner]
        logger.info("session %s created on %s", session.id, env_id)
        return session

    async def shared(self, session_id: str, env_id: str, *, reset: bool = False) -> Session:
        """The shared session ``session_id`` (owned by no client), created on first use.

        Two first requests at once create one session. Its ``last_used`` is now.

        Args:
            session_id: its id (bevy_rl's ``bevy``, OpenEnv's ``openenv``).
            env_id: what it is created on.
            reset: reset it once created.

        Raises:
            Problem: as :meth:`create`, and the reset's.
        """
        async with self._creating_shared:
            found = self._sessions.get(session_id)
            if found is None:
                found = await self.create(env_id, session_id=session_id)
                if reset:
                    await found.reset()
        found.touch()
        return found

    async def abandon(self, session: Session) -> None:
        """Delete ``session``, just created for a client that left before it heard of it."""
        if self._sessions.get(session.id) is session:
            logger.warning(
                "session %s deleted: its client left before it was told of it", session.id
            )
            await self.delete(session.id)

    async def delete(self, session_id: str) -> None:
        """Close and forget the session.

        Raises:
            Problem: ``unknown_session``.
        """
        session = self.get(session_id)
        del self._sessions[session_id]
        await session.close()

    def retry_after(self, among: list[Session] | None = None) -> int:
        """Seconds until the first idle session (of ``among``, else any) is reaped (>= 1)."""
        candidates = list(self._sessions.values()) if among is None else among
        if self.idle_timeout is None or not candidates:
            return 1
        now = self._clock()
        soonest = min(session.last_used + self.idle_timeout - now for session in candidates)
        return max(1, math.ceil(soonest))

    async def reap(self) -> list[str]:
        """Close the sessions idle for longer than ``idle_timeout``; returns their ids."""
        if self.idle_timeout is None:
            return []
        deadline = self._clock() - self.idle_timeout
        idle = [
            s.id for s in self._sessions.values() if s.last_used < deadline and not s.websockets
        ]
        for session_id in idle:
            logger.info("session %s reaped after %.0f s idle", session_id, self.idle_timeout)
            await self.delete(session_id)
        return idle

    async def close_all(self) -> None:
        """Close every session at once (the gateway is stopping)."""
        closing, self._sessions = list(self._sessions.values()), {}
        await asyncio.gather(*(session.close() for session in closing))

    def end_watches(self) -> None:
        """Tell every watcher of every session that the gateway is stopping."""
        for session in self._sessions.values():
            session.end_watches()
