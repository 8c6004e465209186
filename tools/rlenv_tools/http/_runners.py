"""How a call reaches a session's environment, and the deadline every call has.

Every environment runs in a process other than the gateway's (an ``rlenv serve`` subprocess
of the session's own, or the TARGET ``HOST:PORT``), reached by a TCP
:class:`~rlenv_client.client.Client`; the gateway's event loop never runs an environment's
code. So a deadline holds whatever that code does (loops, blocks, raises half-way, loops
inside a pymunk callback, where cffi swallows exceptions and a ``SIGALRM`` was lost), a hung
environment is ended by ending its process, and no session ever waits for another.

A :class:`Runner` serves a session's calls one at a time, in order, in two ways:

- :meth:`Runner.exchange` (steps and resets, the hot path): the request is sent from the
  event loop, which then awaits the socket's answer among everything else it serves and reads
  it once it has arrived: no thread hand-off (which cost a relayed step about as much as the
  HTTP layer). When the session's answers came quickly, the loop first looks for the answer
  for a bounded while (:class:`~rlenv.transport.sockets.AnswerWaiter`'s spin, yielding the
  core, at most :data:`~rlenv.transport.sockets.SPIN_WINDOW`): the answer to a quick step is
  then read without the loop sleeping and being woken for it.
- :meth:`Runner.call` (the rest: configure, observe, render, snapshots): a blocking client
  call on the session's own thread.

Past the deadline either raises :class:`EnvironmentTimeout` at once; the session then ends
its environment's process (see :mod:`rlenv_tools.http._sessions`).
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Protocol, TypeVar

from rlenv.transport.sockets import AnswerWaiter

__all__ = ["AnswerSource", "EnvironmentTimeout", "Runner"]

_T = TypeVar("_T")


class AnswerSource(Protocol):
    """What :meth:`Runner.exchange` awaits answers from (a :class:`~rlenv_client.Client`)."""

    def answer_arrived(self) -> bool: ...  # noqa: D102

    def answer_descriptors(self) -> tuple[int, ...]: ...  # noqa: D102

    def wake(self) -> bool: ...  # noqa: D102


class EnvironmentTimeout(TimeoutError):
    """A call to an environment did not return within its deadline."""


class Runner:
    """Runs a session's calls to its environment, one at a time, under a deadline.

    Args:
        timeout: seconds a call may take (its default deadline).
    """

    def __init__(self, timeout: float) -> None:
        self.timeout = timeout
        self._turn = asyncio.Lock()
        self._executor = ThreadPoolExecutor(1, thread_name_prefix="rlenv-http-session")
        self._waiter = AnswerWaiter()

    async def exchange(
        self, send: Callable[[], None], receive: Callable[[], _T], client: AnswerSource
    ) -> _T:
        """``send()``, then ``receive()`` once ``client``'s answer has arrived.

        Both run on the event loop's thread: ``send`` must not block (a small request on a
        connected socket, or in a lane's slots), and ``receive`` reads an answer that has
        arrived.

        Raises:
            EnvironmentTimeout: no answer within the deadline; the environment's state is
                unknown.
        """
        async with self._turn:
            send()
            waiter = self._waiter
            waiter.sent()
            if waiter.spin(lambda: True if client.answer_arrived() else None):
                waiter.ended()
                return receive()
            loop = asyncio.get_running_loop()
            arrived = loop.create_future()
            descriptors = client.answer_descriptors()
            blocking = [os.get_blocking(descriptor) for descriptor in descriptors]
            for descriptor in descriptors:
                loop.add_reader(descriptor, _woken, arrived, client)
            deadline = loop.call_later(self.timeout, _settle, arrived, False)
            try:
                answered = await arrived
            finally:
                waiter.ended()
                deadline.cancel()
                for descriptor, was_blocking in zip(descriptors, blocking, strict=True):
                    loop.remove_reader(descriptor)
                    os.set_blocking(descriptor, was_blocking)  # as uvloop found it: the
                    # client reads its socket with kernel timeouts (a non-blocking read would
                    # look like one)
            if not answered:
                raise self._late()
            return receive()

    async def call(self, function: Callable[[], _T], *, timeout: float | None = None) -> _T:
        """``function()`` on the session's thread, within ``timeout`` seconds (or the runner's).

        Raises:
            EnvironmentTimeout: the deadline passed (the call is abandoned; ending the
                environment's process ends it).
        """
        limit = self.timeout if timeout is None else timeout
        async with self._turn:
            future = asyncio.get_running_loop().run_in_executor(self._executor, function)
            done, _ = await asyncio.wait((future,), timeout=limit)
            if not done:
                future.add_done_callback(_consume)
                raise self._late(limit)
            return future.result()

    def _late(self, limit: float | None = None) -> EnvironmentTimeout:
        return EnvironmentTimeout(
            f"the environment did not answer within {limit or self.timeout:g} s"
        )

    def close(self) -> None:
        """Let the session's thread end once its last call returns."""
        self._executor.shutdown(wait=False, cancel_futures=True)


def _woken(future: asyncio.Future[bool], client: AnswerSource) -> None:
    """One of the client's descriptors is readable: settled once its answer is there."""
    if not future.done() and client.wake():
        future.set_result(True)


def _settle(future: asyncio.Future[bool], answered: bool) -> None:
    """The first of the answer (``True``) and the deadline (``False``) decides."""
    if not future.done():
        future.set_result(answered)


def _consume(future: asyncio.Future[Any]) -> None:
    """Retrieve an abandoned call's outcome (its environment was ended meanwhile)."""
    if not future.cancelled():
        future.exception()
