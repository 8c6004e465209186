"""The live inspector: a page in the browser showing servers while a trainer drives them.

``rlenv inspect HOST:PORT [HOST:PORT ...]`` (or :class:`Inspector` from Python) starts a small
web server on 127.0.0.1 that is an *observer* client of each environment server over the
ordinary protocol, so the environment servers gain no HTTP code and no thread. The page draws
the scene from vector draw lists (up to ~30 frames a second, dropped when the browser is slow),
lists the node tree (every second) and the selected node's properties (several times a second,
editable: a setting lasts, any other property lasts its episode), shows camera observations as
images and plots the episodes' returns and lengths, steps per second and restarts. Started with
``--record-demonstrations DIR``, it also lets a person take control and play from the keyboard,
recording their episodes (:mod:`~rlenv_tools.inspector._control`).

- :mod:`~rlenv_tools.inspector._watch`: the observer connections (what the page can ask);
- :mod:`~rlenv_tools.inspector._web`: the HTTP server and its safety rules;
- :mod:`~rlenv_tools.inspector._control`: a person's control, recorded (demonstrations);
- :mod:`~rlenv_tools.inspector._timelines`: recordings as timelines to scrub, step, tick,
  branch and compare (``rlenv replay FILE --inspect``, or a watched instance's recent
  episodes; see docs/time-travel.md);
- ``static/``: the page (one HTML file, its script and its style; no build step).
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import threading
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from rlenv_client.client import Client
from rlenv_client.launcher import end_process
from rlenv_tools.inspector._control import Demonstrator
from rlenv_tools.inspector._timelines import Timelines
from rlenv_tools.inspector._watch import InspectorError, Watcher
from rlenv_tools.inspector._web import InspectorServer

if TYPE_CHECKING:
    from rlenv_client.session import Session

__all__ = [
    "Demonstrator",
    "Inspector",
    "InspectorError",
    "InspectorServer",
    "Timelines",
    "Watcher",
    "inspect_recordings",
    "inspect_sessions",
    "serve",
]

logger = logging.getLogger(__name__)

_READY = "inspector on "


class Inspector:
    """``rlenv inspect`` in a subprocess, watching ``addresses``; its page is at :attr:`url`.

    The subprocess holds the token (passed in its environment, never on its command line) and
    exits when this object is closed or this process dies (its standard input closes). With
    ``recordings`` it is ``rlenv replay FILE ... --inspect`` instead: the page opens those
    recordings as timelines (``addresses`` must then be empty).

    Args:
        addresses: ``HOST:PORT`` of each server to watch.
        token: the servers' secret, if they need one (default ``$RLENV_TOKEN``).
        port: the page's port on 127.0.0.1 (0: a free one).
        timeout: seconds to wait for the subprocess to say where its page is.
        record_demonstrations: let a person take control from the page, and record their
            episodes into this directory (``None``: the page only watches).
        target: the environment's ``MODULE:CLASS``, written into demonstrations.
        demonstration_rate: actions a second while a person plays (``None``: real time).
        recordings: episode files to open as timelines (``rlenv replay FILE --inspect``).
        policies: with ``recordings``, ONNX policy files to branch with (``--policy``).
        trust_target: import the target a recording or a watched server names even where it
            is no installed package (``--trust-target``; see
            :mod:`rlenv_client.trusted_targets`).

    Raises:
        RuntimeError: the subprocess did not start (with what it printed).
        ValueError: both ``addresses`` and ``recordings``, or neither.
    """

    def __init__(
        self,
        addresses: Sequence[str],
        token: str | None = None,
        port: int = 0,
        timeout: float = 30.0,
        *,
        record_demonstrations: str | Path | None = None,
        target: str | None = None,
        demonstration_rate: float | None = None,
        recordings: Sequence[str | Path] = (),
        policies: Sequence[str | Path] = (),
        trust_target: bool = False,
    ) -> None:
        if bool(addresses) == bool(recordings):
            raise ValueError("the inspector watches addresses or opens recordings (one of them)")
        env = dict(os.environ)
        if token is not None:
            env["RLENV_TOKEN"] = token
        options = (
            []
            if record_demonstrations is None
            else ["--record-demonstrations", str(record_demonstrations)]
        )
        options += [] if target is None else ["--target", target]
        options += (
            [] if demonstration_rate is None else ["--demonstration-rate", str(demonstration_rate)]
        )
        for policy in policies:
            options += ["--policy", str(policy)]
        options += ["--trust-target"] if trust_target else []
        command = (
            ["rlenv_tools.inspector", *addresses]
            if addresses
            else ["rlenv", "replay", *map(str, recordings), "--inspect"]
        )
        self._process = subprocess.Popen(
            [sys.executable, "-m", *command, "--port", str(port), "--follow-stdin", *options],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
            start_new_session=True,
        )
        assert self._process.stdout is not None
        self.url = _read_url(self._process.stdout, timeout, self._process)
        self._lines = threading.Thread(target=_drain, args=(self._process.stdout,), daemon=True)
        self._lines.start()

    def follow(self, addresses: Sequence[str]) -> None:
        """Watch these addresses from now on (a restarted server's new address, say).

        An inspector that is gone is let go: watching never stops the training it watches.
        """
        stdin = self._process.stdin
        assert stdin is not None
        try:
            stdin.write(json.dumps(list(addresses)) + "\n")
            stdin.flush()
        except OSError as error:  # it died (killed, say)
            logger.warning("the inspector at %s is gone (%s); training goes on", self.url, error)

    def close(self) -> None:
        """Stop the subprocess (closing its standard input ends it); safe to repeat."""
        if self._process.stdin is not None and not self._process.stdin.closed:
            try:
                self._process.stdin.close()
            except OSError:  # it was gone: the pipe had unflushed lines
                pass
        end_process(self._process, 5.0, first=None)

    def __enter__(self) -> Inspector:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<Inspector {self.url} pid={self._process.pid}>"


def inspect_sessions(sessions: Sequence[Session]) -> Inspector:
    """An :class:`Inspector` watching the servers of ``sessions``, following their restarts.

    Its page's address is logged as a warning, so that it shows on standard error without
    any logging set up (nothing is opened by itself).

    Raises:
        ValueError: a session runs its environment in this process (there is no server).
    """
    clients = [session.client for session in sessions]
    if not all(isinstance(client, Client) for client in clients):
        raise ValueError(
            "the inspector watches served environments: in_process=True has no server to watch"
        )
    inspector = Inspector([client.address for client in clients], token=sessions[0].token)

    def follow() -> None:
        inspector.follow([session.client.address for session in sessions])

    for session in sessions:
        session.on_restart = follow
    logger.warning("rlenv inspector: %s", inspector.url)
    return inspector


def inspect_recordings(
    paths: Sequence[str | Path],
    *,
    policies: Mapping[str, Callable[[Any], Any]] | None = None,
    target: str | None = None,
    trust_target: bool = False,
    port: int = 0,
) -> InspectorServer:
    """The page with ``paths`` as timelines, served by a thread of this process.

    What ``rlenv replay FILE ... --inspect`` serves, with Python callables as policies to
    branch with (``policies={"name": callable}``, each ``callable(observation) -> action``).
    Its address (:attr:`InspectorServer.url`) is logged as a warning; :meth:`~InspectorServer.
    close` ends it and the timelines' processes.

    ``target`` and ``trust_target``: see :class:`~rlenv_tools.inspector._timelines.Timelines`.

    Raises:
        ValueError: a file is not an rlenv episode.
    """
    server = InspectorServer(
        Watcher([]),
        port=port,
        timelines=Timelines(paths, policies=policies, target=target, trust_target=trust_target),
    )
    server.start()
    logger.warning("rlenv inspector: %s", server.url)
    return server


def _read_url(stdout: IO[str], timeout: float, process: subprocess.Popen[str]) -> str:
    """The URL the subprocess prints first (a reader thread bounds the wait)."""
    said: list[str] = []
    reader = threading.Thread(target=_until_ready, args=(stdout, said), daemon=True)
    reader.start()
    reader.join(timeout)
    if said and said[-1].startswith(_READY):
        return said[-1][len(_READY) :].strip()
    end_process(process, 0.0, first=None)
    raise RuntimeError("rlenv inspect did not start: " + "".join(said).strip())


def _until_ready(stdout: IO[str], lines: list[str]) -> None:
    for line in stdout:
        lines.append(line)
        if line.startswith(_READY):
            return


def _drain(stdout: IO[str]) -> None:
    for line in stdout:
        sys.stderr.write(line)


def serve(
    addresses: Sequence[str],
    *,
    token: str | None,
    port: int,
    follow_stdin: bool,
    ready: Callable[[str], None],
    record_demonstrations: str | Path | None = None,
    target: str | None = None,
    demonstration_rate: float | None = None,
    recordings: Sequence[str | Path] = (),
    policies: Mapping[str, Callable[[Any], Any]] | None = None,
    unavailable: Mapping[str, str] | None = None,
    trust_target: bool = False,
) -> None:
    """Serve the page (``rlenv inspect``); ``ready(line)`` once it listens, with its address.

    Until interrupted, or until standard input closes with ``follow_stdin`` (address lists,
    one JSON list a line, are followed meanwhile). ``token`` ``None``: ``$RLENV_TOKEN``.
    ``record_demonstrations``, ``target`` and ``demonstration_rate``: see :class:`Inspector`.
    ``recordings`` (``rlenv replay FILE --inspect``): episode files the page opens as timelines
    (with the watched instances' recent episodes), re-simulated on ``target`` (default: each
    episode's, where it is installed or ``trust_target``); ``policies`` and ``unavailable``: see
    :class:`~rlenv_tools.inspector._timelines.Timelines`.

    Raises:
        ValueError: an address is not ``HOST:PORT``, the rate is not positive, or a recording
            is not an rlenv episode.
    """
    timelines = Timelines(
        recordings,
        policies=policies,
        unavailable=unavailable,
        target=target,
        trust_target=trust_target,
    )
    watcher = Watcher(addresses, token=token)
    demonstrator = (
        None
        if record_demonstrations is None
        else Demonstrator(
            watcher, record_demonstrations, target=target, rate=demonstration_rate, token=token
        )
    )
    server = InspectorServer(watcher, port=port, demonstrator=demonstrator, timelines=timelines)
    ready(f"{_READY}{server.url}")
    if follow_stdin:
        threading.Thread(target=_follow, args=(server,), daemon=True).start()
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
        if demonstrator is not None:
            demonstrator.close()
        timelines.close()
        watcher.close()


def _follow(server: InspectorServer) -> None:
    """Address lists from standard input; at its end, stop the server."""
    for line in sys.stdin:
        try:
            addresses = json.loads(line)
            server.watcher.follow(addresses)
        except (ValueError, TypeError) as error:
            logger.warning("rlenv inspect: ignored %.80r: %s", line.strip(), error)
    server.shutdown()
