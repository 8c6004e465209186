"""The HTTP gateway's runner of a session's calls (``rlenv_tools.http._runners``)."""

from __future__ import annotations

import asyncio
import threading

import pytest

pytest.importorskip("starlette")

from rlenv_tools.http._runners import EnvironmentTimeout, Runner  # noqa: E402


def test_a_call_given_no_time_is_late_at_once_not_given_the_default() -> None:
    release = threading.Event()
    runner = Runner(timeout=600.0)

    async def late() -> None:
        with pytest.raises(EnvironmentTimeout):
            await runner.call(lambda: release.wait(600.0), timeout=0.0)

    try:  # 0 was read as "the default": the call waited its 600 s
        asyncio.run(asyncio.wait_for(late(), timeout=60.0))
        release.set()  # the abandoned call ends; the session's thread takes the next
        assert asyncio.run(runner.call(lambda: 7, timeout=None)) == 7  # None: the default
    finally:
        release.set()
        runner.close()
