"""The token guards a server across two real network hosts.

Two network namespaces, A and B, joined by a veth pair (``10.123.0.1/24`` in A, ``10.123.0.2/24``
in B), stand for two hosts: each has its own interfaces, routes and loopback, so the addresses
cannot clash with the machine's own networks. ``rlenv serve`` runs in A, bound to A's veth
address with a token; the clients run in B (``tests/hosts_probe.py``, over real TCP across the
veth) and must present the token before the server does anything for them.

Needs root and ``ip`` (iproute2); the module skips itself otherwise, or when a namespace cannot
be created (a container without ``CAP_SYS_ADMIN``). The namespaces are named after this process
and a random suffix; they, and every process left inside them, are removed when the module ends,
whatever its outcome. Namespaces left by a run that was killed outright are removed at the next
run. Every wait polls against a deadline.
"""

from __future__ import annotations

import json
import os
import queue
import re
import secrets
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from conftest import alive

from examples.cartpole import TARGET


def _find_ip() -> str | None:
    return shutil.which("ip") or shutil.which("ip", path="/usr/sbin:/sbin:/usr/bin:/bin")


IP = _find_ip()
PREFIX = "rlenvtest"
"""Every namespace this module creates is called ``PREFIX-<pid>-<hex>-<a|b>``."""
HOST_A = "10.123.0.1"
HOST_B = "10.123.0.2"
NETMASK = 24
FIRST_FRAME_LIMIT = 64 * 1024
"""Largest frame body a server takes before a client has presented the right token."""
PROBE = Path(__file__).with_name("hosts_probe.py")
ROOT = Path(__file__).resolve().parent.parent
DEADLINE = 20.0
"""Seconds any one step (a server starting, a probe running) may take before the test fails."""
CHILD_ENV = {name: value for name, value in os.environ.items() if name != "RLENV_TOKEN"}
"""The environment of every process started here: no token but the ones passed explicitly."""


def _why_skip() -> str | None:
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        return "needs root to create network namespaces (ip netns)"
    if IP is None:
        return "needs the ip command (iproute2) to create network namespaces"
    return None


pytestmark = pytest.mark.skipif(_why_skip() is not None, reason=_why_skip() or "")


# --- namespaces ---------------------------------------------------------------------------------


def ip(*args: str) -> subprocess.CompletedProcess[str]:
    """Run ``ip ARGS``; the completed process (never raises on a failure exit)."""
    assert IP is not None
    return subprocess.run(
        [IP, *args],
        capture_output=True,
        text=True,
        timeout=DEADLINE,
        check=False,
        stdin=subprocess.DEVNULL,
    )


def ip_ok(*args: str) -> str:
    """Run ``ip ARGS``; its output. Raises ``RuntimeError`` with ``ip``'s message on failure."""
    done = ip(*args)
    if done.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)} failed ({done.returncode}): {done.stderr.strip()}")
    return done.stdout


def poll(condition: Callable[[], bool], what: str, timeout: float = DEADLINE) -> None:
    """Return once ``condition()`` holds; fail naming ``what`` after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(f"{what}: not within {timeout}s")
        time.sleep(0.005)  # a polling interval, not a wait for something to happen


def namespace_pids(name: str) -> list[int]:
    """The processes inside namespace ``name``."""
    return [int(pid) for pid in ip("netns", "pids", name).stdout.split()]


def delete_namespace(name: str) -> None:
    """Kill every process in namespace ``name``, then delete it."""

    def emptied() -> bool:
        pids = namespace_pids(name)
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        return not pids

    try:
        poll(emptied, f"emptying network namespace {name}")
    finally:
        ip("netns", "delete", name)


def our_namespaces() -> list[str]:
    """The namespaces on this machine that this module created (in any run)."""
    names = (line.split()[0] for line in ip("netns", "list").stdout.splitlines() if line.split())
    return [name for name in names if re.fullmatch(rf"{PREFIX}-\d+-[0-9a-f]+-[ab]", name)]


def delete_stale_namespaces() -> None:
    """Delete namespaces left by runs whose process is gone (killed before their cleanup)."""
    for name in our_namespaces():
        pid = int(name.split("-")[1])
        if pid != os.getpid() and not alive(pid):
            delete_namespace(name)


@dataclass(frozen=True)
class Hosts:
    """Namespaces joined by a veth pair: ``a`` holds :data:`HOST_A`, ``b`` :data:`HOST_B`."""

    a: str
    b: str

    def run(self, namespace: str, *argv: str) -> list[str]:
        """The command running ``argv`` inside ``namespace``."""
        assert IP is not None
        return [IP, "netns", "exec", namespace, *argv]


def _link_up(namespace: str, device: str) -> bool:
    shown = json.loads(ip_ok("-n", namespace, "-j", "link", "show", device))
    return bool(shown) and shown[0].get("operstate") == "UP"


@pytest.fixture(scope="module")
def hosts() -> Iterator[Hosts]:
    """Namespaces A and B joined by a veth pair, up; deleted (and emptied) at the end."""
    delete_stale_namespaces()
    stem = f"{PREFIX}-{os.getpid()}-{secrets.token_hex(3)}"
    pair = Hosts(f"{stem}-a", f"{stem}-b")
    created: list[str] = []
    try:
        for name in (pair.a, pair.b):
            done = ip("netns", "add", name)
            if done.returncode != 0:
                pytest.skip(
                    f"cannot create a network namespace ({done.stderr.strip()}); "
                    "needs CAP_SYS_ADMIN outside a restricted container"
                )
            created.append(name)
        ip_ok(
            "-n",
            pair.a,
            "link",
            "add",
            "veth-a",
            "type",
            "veth",
            "peer",
            "name",
            "veth-b",
            "netns",
            pair.b,
        )
        for name, device, address in ((pair.a, "veth-a", HOST_A), (pair.b, "veth-b", HOST_B)):
            ip_ok("-n", name, "addr", "add", f"{address}/{NETMASK}", "dev", device)
            ip_ok("-n", name, "link", "set", "lo", "up")
            ip_ok("-n", name, "link", "set", device, "up")
        for name, device in ((pair.a, "veth-a"), (pair.b, "veth-b")):
            poll(
                lambda name=name, device=device: _link_up(name, device),
                f"{device} in {name} coming up",
            )
        yield pair
    finally:
        for name in reversed(created):
            delete_namespace(name)


# --- servers ------------------------------------------------------------------------------------


class NamespacedServer:
    """``rlenv serve`` for CartPole inside a namespace, in a process group of its own.

    Its output is pumped into :attr:`lines` by a thread; :meth:`wait_listening` waits for the
    ``listening on HOST:PORT`` line. The server holds the read end of a pipe (``--lifeline``)
    whose write end only this process holds: if this process dies, so does the server.
    """

    def __init__(self, hosts: Hosts, namespace: str, host: str, token: str | None) -> None:
        lifeline, self._lifeline = os.pipe()
        command = hosts.run(
            namespace,
            sys.executable,
            "-m",
            "rlenv",
            "serve",
            TARGET,
            "--host",
            host,
            "--port",
            "0",
            "--lifeline",
            str(lifeline),
            *([f"--token={token}"] if token is not None else []),
        )
        try:
            self.process = subprocess.Popen(
                command,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                text=True,
                bufsize=1,
                start_new_session=True,
                pass_fds=(lifeline,),
                cwd=ROOT,
                env=CHILD_ENV,
            )
        finally:
            os.close(lifeline)
        self.lines: list[str] = []
        self._listening: queue.Queue[str | None] = queue.Queue()
        self._pump = threading.Thread(target=self._read_output, daemon=True)
        self._pump.start()

    @property
    def output(self) -> str:
        """Everything the server wrote so far (stdout and stderr)."""
        return "".join(self.lines)

    def _read_output(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.append(line)
            if line.startswith("listening on "):
                self._listening.put(line)
        self._listening.put(None)

    def wait_listening(self, timeout: float = DEADLINE) -> tuple[str, int] | None:
        """The address from the ``listening on`` line; ``None`` if the server exited first."""
        try:
            line = self._listening.get(timeout=timeout)
        except queue.Empty:
            raise TimeoutError(
                f"the server did not listen within {timeout}s; its output:\n{self.output}"
            ) from None
        if line is None:
            return None
        host, _, port = line.removeprefix("listening on ").strip().rpartition(":")
        return host, int(port)

    def is_alive(self) -> bool:
        """Whether the server process still runs."""
        return self.process.poll() is None

    def close(self, timeout: float = 5.0) -> None:
        """End the server's process group: SIGTERM, then SIGKILL after ``timeout`` seconds."""
        try:
            os.close(self._lifeline)
        except OSError:  # closed already
            pass
        for sig in (signal.SIGTERM, signal.SIGKILL):
            if self.process.poll() is not None:
                break
            try:
                os.killpg(self.process.pid, sig)
            except ProcessLookupError:
                break
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                continue
        self.process.wait(timeout)
        self._pump.join(timeout)
        if self.process.stdout is not None:
            self.process.stdout.close()


@dataclass(frozen=True)
class Guarded:
    """A server in A bound to :data:`HOST_A` with a token."""

    process: NamespacedServer
    port: int
    token: str


@pytest.fixture(scope="module")
def guarded(hosts: Hosts) -> Iterator[Guarded]:
    """CartPole served in A on ``HOST_A:<free port>``, requiring a fresh random token."""
    token = secrets.token_urlsafe(24)
    server = NamespacedServer(hosts, hosts.a, HOST_A, token)
    try:
        address = server.wait_listening()
        assert address is not None, f"the server exited before listening:\n{server.output}"
        assert address[0] == HOST_A, address
        yield Guarded(server, address[1], token)
    finally:
        server.close()
    assert not namespace_pids(hosts.a), "a process outlived the server in namespace A"


def probe(hosts: Hosts, namespace: str, *argv: str) -> dict[str, Any]:
    """Run ``tests/hosts_probe.py ARGV`` inside ``namespace``; its JSON report."""
    done = subprocess.run(
        hosts.run(namespace, sys.executable, str(PROBE), *argv),
        capture_output=True,
        text=True,
        timeout=DEADLINE,
        check=False,
        cwd=ROOT,
        env=CHILD_ENV,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode == 0, f"probe {argv} failed ({done.returncode}):\n{done.stderr}"
    return json.loads(done.stdout.strip().splitlines()[-1])


def probe_guarded(hosts: Hosts, guarded: Guarded, mode: str, *args: str) -> dict[str, Any]:
    """Run probe ``mode`` from B against the guarded server; check that it still serves."""
    result = probe(hosts, hosts.b, mode, HOST_A, str(guarded.port), guarded.token, *args)
    assert_served(result["afterwards"])
    assert guarded.process.is_alive(), guarded.process.output
    return result


def assert_served(result: dict[str, Any]) -> None:
    """``result`` is a CartPole episode that was reset and stepped (see ``serve_cartpole``)."""
    assert "refused" not in result, result
    assert len(result["observation"]) == 5 and len(result["stepped"]) == 5, result
    assert result["stepped"] != result["observation"], result
    assert result["frames"] >= 1 and result["reward"] >= 0.0, result


def assert_refused(
    reply: dict[str, Any] | None, code: str, request_id: int | None, message: str | None = None
) -> None:
    """``reply`` is a fatal error ``code`` for ``request_id`` (containing ``message``)."""
    assert reply is not None, "the server closed the connection without an answer"
    assert reply["id"] == request_id, reply
    assert reply["error"]["code"] == code and reply["error"]["fatal"] is True, reply
    if message is not None:
        assert message in reply["error"]["message"], reply


# --- tests --------------------------------------------------------------------------------------


def test_the_hosts_are_apart(hosts: Hosts) -> None:
    addresses = ip_ok("-n", hosts.b, "-4", "-o", "addr", "show")
    assert HOST_B in addresses and HOST_A not in addresses


def test_right_token_resets_and_steps(hosts: Hosts, guarded: Guarded) -> None:
    result = probe_guarded(hosts, guarded, "client", guarded.token)
    assert_served(result["client"])


def test_client_without_token_is_refused(hosts: Hosts, guarded: Guarded) -> None:
    refused = probe_guarded(hosts, guarded, "client", "-")["client"]["refused"]
    assert refused["code"] == "unauthorized" and refused["fatal"] is True, refused


def test_request_without_token_is_refused(hosts: Hosts, guarded: Guarded) -> None:
    result = probe_guarded(hosts, guarded, "request", "-")
    assert result["hello"]["token_required"] is True
    assert_refused(result["reply"], "unauthorized", 1, "requires a token")
    assert result["closed"]


def test_client_with_wrong_token_is_refused(hosts: Hosts, guarded: Guarded) -> None:
    refused = probe_guarded(hosts, guarded, "client", "not-" + guarded.token)["client"]["refused"]
    assert refused == {"code": "unauthorized", "message": "wrong token", "fatal": True}


def test_request_with_wrong_token_is_refused(hosts: Hosts, guarded: Guarded) -> None:
    result = probe_guarded(hosts, guarded, "request", guarded.token[:-1])
    assert_refused(result["reply"], "unauthorized", 1, "wrong token")
    assert result["closed"]


def test_token_outside_a_request_does_not_authenticate(hosts: Hosts, guarded: Guarded) -> None:
    result = probe_guarded(hosts, guarded, "non-request-token")
    first = result["first"]
    assert first["id"] is None and first["error"]["fatal"] is False, first
    assert_refused(result["reply"], "unauthorized", 2, "requires a token")
    assert result["closed"]


@pytest.mark.parametrize("size", [2**32 - 1, FIRST_FRAME_LIMIT + 1])
def test_large_frame_before_token_is_refused(hosts: Hosts, guarded: Guarded, size: int) -> None:
    result = probe_guarded(hosts, guarded, "prefix", str(size))
    assert result["hello"]["max_first_frame_size"] == FIRST_FRAME_LIMIT
    assert_refused(result["reply"], "bad_frame", None)
    assert result["closed"]


def test_frames_grow_after_the_token(hosts: Hosts, guarded: Guarded) -> None:
    result = probe_guarded(hosts, guarded, "after-auth", str(FIRST_FRAME_LIMIT))
    assert result["first"] == {"id": 1, "error": None}
    assert result["size"] > FIRST_FRAME_LIMIT
    assert result["reply"] == {"id": 2, "error": None}


def test_bound_address_only(hosts: Hosts, guarded: Guarded) -> None:
    port = str(guarded.port)
    from_b = probe(hosts, hosts.b, "connect", f"{HOST_A}:{port}", f"127.0.0.1:{port}")
    assert from_b["connect"] == {f"{HOST_A}:{port}": "connected", f"127.0.0.1:{port}": "refused"}
    from_a = probe(hosts, hosts.a, "connect", f"127.0.0.1:{port}")
    assert from_a["connect"] == {f"127.0.0.1:{port}": "refused"}  # not even on A's own loopback
    assert guarded.process.is_alive(), guarded.process.output


def test_no_token_refuses_to_start(hosts: Hosts) -> None:
    server = NamespacedServer(hosts, hosts.a, HOST_A, token=None)
    try:
        assert server.wait_listening() is None, f"it listened:\n{server.output}"
        assert server.process.wait(DEADLINE) == 2, server.output
        assert f"refusing to listen on {HOST_A}" in server.output, server.output
        assert "token" in server.output
    finally:
        server.close()
