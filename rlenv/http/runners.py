"""How a session's environment runs, and the deadline every call to it has.

Two runners, measured in ``benchmarks/http_step.py``:

- :class:`InlineRunner` (environments hosted in the gateway's process, the default): a call
  runs on the event loop's own thread, as the TCP server runs a request: no thread hand-off,
  which costs a step about as much as the HTTP layer itself. Its deadline is an interval timer
  (``SIGALRM``): past it, the environment's code is interrupted by :class:`_Interrupted` (a
  ``BaseException``, so that the environment's own ``except Exception`` cannot swallow it) and
  the call raises :class:`EnvironmentTimeout`. Code stuck in native code without returning to
  Python cannot be interrupted: serve such an environment with ``--isolate``. Its code calling
  ``sys.exit`` ends its session (``ConnectionLost``), never the gateway.
- :class:`ThreadRunner` (relays: sessions whose environment is another process): a call runs
  on the session's own thread, one at a time, so that the event loop goes on serving the
  other sessions while a blocking client waits for its server; the client's own timeout ends
  a call that takes too long (``RequestTimeout``, a ``TimeoutError``).

A runner never runs two calls at once: a session's requests are served in order.
"""

from __future__ import annotations

import asyncio
import signal
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from types import FrameType
from typing import Protocol, TypeVar

from rlenv.protocol.errors import ConnectionLost

__all__ = ["EnvironmentTimeout", "InlineRunner", "Runner", "ThreadRunner", "install_alarm"]

_T = TypeVar("_T")


class EnvironmentTimeout(TimeoutError):
    """A call to an environment did not return within its deadline."""


class _Interrupted(BaseException):
    """Raised inside environment code by the alarm (never seen outside this module)."""


class Runner(Protocol):
    """Runs a session's calls to its environment, under a deadline."""

    timeout: float

    async def call(self, function: Callable[[], _T], *, timeout: float | None = None) -> _T:
        """``function()``, within ``timeout`` seconds (default: the runner's).

        Raises:
            TimeoutError: the deadline passed; the environment's state is unknown.
        """
        ...

    def close(self) -> None:
        """Release what the runner holds (its thread)."""
        ...


class _Alarm:
    """The process's ``SIGALRM``, armed around inline calls (main thread only)."""

    def __init__(self) -> None:
        self.armed = False

    def fire(self, signum: int, frame: FrameType | None) -> None:
        if self.armed:  # once per arming: the code that handles it is never interrupted
            self.armed = False
            raise _Interrupted


_ALARM = _Alarm()


def install_alarm() -> bool:
    """Let inline calls have a deadline: install the ``SIGALRM`` handler.

    Returns:
        Whether it could be installed: only the main thread can (where ``rlenv http`` runs its
        event loop), and only where the platform has ``SIGALRM``.
    """
    if threading.current_thread() is not threading.main_thread() or \
            not hasattr(signal, "setitimer"):
        return False
    signal.signal(signal.SIGALRM, _ALARM.fire)
    return True


class InlineRunner:
    """Runs calls on the event loop's thread, interrupted past ``timeout`` seconds.

    Only for a loop on the main thread with :func:`install_alarm` done (the gateway uses a
    :class:`ThreadRunner` otherwise).
    """

    def __init__(self, timeout: float) -> None:
        self.timeout = timeout

    async def call(self, function: Callable[[], _T], *, timeout: float | None = None) -> _T:
        """``function()`` now, on this thread; see :class:`Runner`."""
        _ALARM.armed = True
        signal.setitimer(signal.ITIMER_REAL, timeout or self.timeout)
        try:
            try:
                return function()
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
                _ALARM.armed = False
        except _Interrupted:
            raise EnvironmentTimeout(
                f"the environment did not answer within {timeout or self.timeout:g} s") from None
        except (SystemExit, KeyboardInterrupt) as error:  # its code tried to end the process
            raise ConnectionLost(f"the environment tried to end the gateway's process "
                                 f"({error!r}); it did not") from None

    def close(self) -> None:
        """Nothing to release."""


class ThreadRunner:
    """Runs calls one at a time on a thread of its own; see the module docstring.

    The calls are expected to end by themselves within ``timeout`` (a client's socket
    timeout); a call still running ``grace`` seconds later is abandoned with
    :class:`EnvironmentTimeout` and its thread left to finish.
    """

    def __init__(self, timeout: float, grace: float = 5.0) -> None:
        self.timeout = timeout
        self._grace = grace
        self._executor = ThreadPoolExecutor(1, thread_name_prefix="rlenv-http-session")

    async def call(self, function: Callable[[], _T], *, timeout: float | None = None) -> _T:
        """``function()`` on the runner's thread; see :class:`Runner`."""
        limit = (timeout or self.timeout) + self._grace
        future = asyncio.get_running_loop().run_in_executor(self._executor, function)
        done, _ = await asyncio.wait((future,), timeout=limit)
        if not done:
            raise EnvironmentTimeout(f"the environment did not answer within {limit:g} s")
        return future.result()

    def close(self) -> None:
        """Let the thread end once its last call returns."""
        self._executor.shutdown(wait=False, cancel_futures=True)
