"""Test support for the inspector: raw HTTP requests (any Host, any Origin) and a trainer."""

from __future__ import annotations

import http.client
import json
import threading
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from rlenv_client import Client


def fetch(
    url: str,
    path: str = "",
    *,
    method: str = "GET",
    body: Any = None,
    headers: dict[str, str] | None = None,
    raw: bytes | None = None,
) -> tuple[int, dict[str, str], Any]:
    """``method`` of ``url + path``: (status, headers, JSON body or bytes).

    ``headers`` may replace ``Host`` (sent as given, unlike urllib's).
    """
    parts = urlsplit(url + path)
    connection = http.client.HTTPConnection(parts.hostname, parts.port, timeout=10)
    try:
        target = parts.path + (f"?{parts.query}" if parts.query else "")
        connection.putrequest(method, target, skip_host=True, skip_accept_encoding=True)
        sent = {"Host": f"{parts.hostname}:{parts.port}", **(headers or {})}
        data = raw if raw is not None else (None if body is None else json.dumps(body).encode())
        if data is not None:
            sent.setdefault("Content-Type", "application/json")
            sent.setdefault("Content-Length", str(len(data)))
        for name, value in sent.items():
            connection.putheader(name, value)
        connection.endheaders(data)
        response = connection.getresponse()
        content = response.read()
        answer_headers = {name.lower(): value for name, value in response.getheaders()}
    finally:
        connection.close()
    if answer_headers.get("content-type") == "application/json":
        return response.status, answer_headers, json.loads(content)
    return response.status, answer_headers, content


class Trainer:
    """A controller stepping a CartPole server as fast as it can, in a thread, until stopped."""

    def __init__(self, host: str, port: int, token: str | None = None) -> None:
        self.client = Client(host, port, token=token)
        self.steps = 0
        self.episodes = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self.error: BaseException | None = None

    def __enter__(self) -> Trainer:
        self._thread.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._stop.set()
        self._thread.join(10)
        self.client.close()

    def _run(self) -> None:
        random = np.random.default_rng(0)
        try:
            while not self._stop.is_set():
                self.client.reset()
                self.episodes += 1
                done = False
                while not done and not self._stop.is_set():
                    action = random.uniform(-1, 1, 1).astype(np.float32)
                    _, _, terminated, truncated, _ = self.client.step(action)
                    self.steps += 1
                    done = terminated or truncated
        except BaseException as error:  # the test reads it
            self.error = error
