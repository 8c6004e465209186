"""A headless Chromium driven over the DevTools protocol, through a pipe (no extra package).

``chromium --remote-debugging-pipe`` reads DevTools commands on its fd 3 and writes answers and
events on its fd 4, each a JSON message ended by a NUL byte. :class:`Browser` opens one page and
evaluates JavaScript in it: enough to load a page, read its DOM, click and type, and take a
screenshot.
"""

from __future__ import annotations

import base64
import itertools
import json
import os
import select
import shutil
import subprocess
import tempfile
import time
from typing import Any

from rlenv_client.launcher import end_process

__all__ = ["Browser", "BrowserError", "find_chromium"]

_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


class BrowserError(Exception):
    """The browser failed a command, or its page raised."""


def find_chromium() -> str | None:
    """The path of a Chromium (or Chrome) executable, or ``None``."""
    for name in _NAMES:
        path = shutil.which(name)
        if path is not None:
            return path
    return None


class Browser:
    """One headless page of a fresh Chromium; close it to end the browser.

    Args:
        executable: the browser to run.
        width: the page's width in CSS pixels.
        height: its height.
        host_rules: ``--host-resolver-rules`` (``"MAP name 127.0.0.1"``: a DNS name that
            rebinds to loopback, say).
    """

    def __init__(
        self, executable: str, width: int = 1400, height: int = 1000, host_rules: str | None = None
    ) -> None:
        self._profile = tempfile.mkdtemp(prefix="rlenv-chromium-")
        commands_read, self._commands = os.pipe()
        self._answers, answers_write = os.pipe()
        arguments = [
            executable,
            "--headless=new",
            "--remote-debugging-pipe",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            "--no-default-browser-check",
            "--disable-extensions",
            "--disable-background-networking",
            "--disable-dev-shm-usage",
            "--mute-audio",
            "--disable-background-timer-throttling",
            "--disable-renderer-backgrounding",
            "--disable-backgrounding-occluded-windows",
            f"--user-data-dir={self._profile}",
            f"--window-size={width},{height}",
            "about:blank",
        ]
        if host_rules:
            arguments.insert(1, f"--host-resolver-rules={host_rules}")

        def pipes_as_fd_3_and_4() -> None:
            read, write = os.dup(commands_read), os.dup(answers_write)
            os.dup2(read, 3)
            os.dup2(write, 4)

        self._process = subprocess.Popen(
            arguments,
            preexec_fn=pipes_as_fd_3_and_4,
            pass_fds=(3, 4),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        os.close(commands_read)
        os.close(answers_write)
        self._ids = itertools.count(1)
        self._buffer = b""
        self.console: list[str] = []
        try:
            target = self.command("Target.createTarget", url="about:blank")["targetId"]
            self._session = self.command("Target.attachToTarget", targetId=target, flatten=True)[
                "sessionId"
            ]
            self.command("Page.enable", session=True)
            self.command("Runtime.enable", session=True)
            self.command(
                "Emulation.setDeviceMetricsOverride",
                session=True,
                width=width,
                height=height,
                deviceScaleFactor=1,
                mobile=False,
            )
        except BaseException:
            self.close()
            raise

    def command(
        self, method: str, *, session: bool = False, timeout: float = 30.0, **params: Any
    ) -> dict[str, Any]:
        """Send a DevTools command (to the page with ``session``); its result."""
        number = next(self._ids)
        message: dict[str, Any] = {"id": number, "method": method, "params": params}
        if session:
            message["sessionId"] = self._session
        os.write(self._commands, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            answer = self._next(deadline)
            if answer.get("method") == "Runtime.consoleAPICalled":
                self.console.append(
                    " ".join(
                        str(arg.get("value", arg.get("description")))
                        for arg in answer["params"]["args"]
                    )
                )
            if answer.get("id") == number:
                if "error" in answer:
                    raise BrowserError(f"{method}: {answer['error']}")
                return dict(answer.get("result", {}))

    def open(self, url: str) -> None:
        """Load ``url`` in the page (returns once it has started loading)."""
        self.command("Page.navigate", session=True, url=url)

    def evaluate(self, expression: str) -> Any:
        """The value of a JavaScript expression in the page (promises awaited).

        Raises:
            BrowserError: the expression threw.
        """
        result = self.command(
            "Runtime.evaluate",
            session=True,
            expression=expression,
            awaitPromise=True,
            returnByValue=True,
        )
        if "exceptionDetails" in result:
            details = result["exceptionDetails"]
            raise BrowserError(
                details.get("exception", {}).get("description") or details.get("text")
            )
        return result["result"].get("value")

    def wait_for(self, expression: str, message: str, seconds: float = 30.0) -> Any:
        """Evaluate ``expression`` until it is truthy (polled, with a deadline); its value."""
        deadline = time.monotonic() + seconds
        while True:
            try:
                value = self.evaluate(expression)
            except BrowserError:
                value = None  # the page is still loading
            if value:
                return value
            assert time.monotonic() < deadline, f"{message} (console: {self.console[-5:]})"
            time.sleep(0.05)

    def screenshot(self) -> bytes:
        """The page as a PNG."""
        return base64.b64decode(
            self.command("Page.captureScreenshot", session=True, format="png")["data"]
        )

    def close(self) -> None:
        """End the browser and remove its profile; safe to repeat."""
        end_process(self._process, 0.0, first=None, group=True)
        for fd in (self._commands, self._answers):
            try:
                os.close(fd)
            except OSError:
                pass
        shutil.rmtree(self._profile, ignore_errors=True)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _next(self, deadline: float) -> dict[str, Any]:
        """The next message from the browser."""
        while b"\0" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._answers], [], [], left)[0]:
                raise BrowserError("the browser did not answer in time")
            chunk = os.read(self._answers, 1 << 16)
            if not chunk:
                raise BrowserError("the browser closed its pipe (it exited)")
            self._buffer += chunk
        message, _, self._buffer = self._buffer.partition(b"\0")
        return dict(json.loads(message))
