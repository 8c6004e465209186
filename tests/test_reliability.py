"""Bad input gets a clear error and nothing is lost: hostile clients, deadlines, access, faults."""

from __future__ import annotations

import logging
import os
import random
import select
import signal
import socket
import struct
import subprocess
import sys
import threading
from typing import Any

import numpy as np
import pytest
from conftest import Serve, wait_until

from rlenv.protocol import ErrorReply, Hello, Response
from rlenv.protocol.codec import pack
from rlenv.protocol.errors import ErrorCode
from rlenv.serving._endpoint import Endpoint, Limits
from rlenv.serving._penalties import FREE_FAILURES, MAX_HELD, MAX_PENALTY
from rlenv.testing import ManualClock, frame, read_frame
from rlenv_client import Client, ConnectionLost, RemoteEnv, RemoteError
from rlenv_tools.compliance import check_server
from rlenv_tools.compliance._harness import peak_rss_kib


def test_compliance_suite_on_cartpole(serve: Serve, figures: dict[str, str]) -> None:
    server = serve(args=["--frame-deadline", "0.5"])
    report = check_server(
        server.host, server.port, pid=server.pid, frame_deadline=0.5, random_frames=300
    )
    figures["compliance (CartPole)"] = report.summary()
    assert report.passed, "\n".join(report.failures)
    assert report.frames_tried >= 300 and report.controller_steps == report.probes
    assert report.rss_growth_kib is not None and report.rss_growth_kib < 8 * 1024


def test_compliance_suite_on_a_discrete_environment(serve: Serve, figures: dict[str, str]) -> None:
    server = serve("examples.faulty:CountingEnvironment")
    report = check_server(server.host, server.port, random_frames=50, action=lambda: 0)
    figures["compliance (Discrete actions)"] = report.summary()
    assert report.passed, "\n".join(report.failures)


@pytest.mark.parametrize(
    "target",
    ["examples.cartpole:CartPoleEnvironment", "examples.pair:PairEnvironment"],
    ids=["box", "dict"],
)
def test_compliance_suite_on_a_multi_instance_server(
    serve: Serve, figures: dict[str, str], target: str
) -> None:
    """The steps probes too: refused before every instance was reset, or with a short mask."""
    server = serve(target, args=["--instances", "3"])
    report = check_server(server.host, server.port, random_frames=50)
    figures[f"compliance ({target.split(':')[1]} x 3 instances)"] = report.summary()
    assert report.passed, "\n".join(report.failures)


def test_a_token_guards_the_server(serve: Serve, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("RLENV_TOKEN", raising=False)
    server = serve(args=["--token", "s3cret"])
    with pytest.raises(RemoteError) as error:
        Client(server.host, server.port)
    assert error.value.code == ErrorCode.UNAUTHORIZED and "token" in error.value.message
    with pytest.raises(RemoteError) as error:
        Client(server.host, server.port, token="guess")
    assert error.value.code == ErrorCode.UNAUTHORIZED and error.value.message == "wrong token"
    with Client(server.host, server.port, token="s3cret") as client:
        client.reset(seed=0)
    monkeypatch.setenv("RLENV_TOKEN", "s3cret")
    with Client(server.host, server.port) as client:
        client.reset(seed=0)


def test_frames_stay_small_until_authenticated(serve: Serve) -> None:
    server = serve(args=["--token", "s3cret"])
    with socket.create_connection((server.host, server.port), timeout=5) as raw:
        assert read_frame(raw)["hello"]["token_required"] is True
        raw.sendall(struct.pack(">I", 100_000) + b"\x00" * 10)
        reply = read_frame(raw)
        assert reply["error"]["code"] == ErrorCode.BAD_FRAME and reply["error"]["fatal"]
        assert "exceeds the limit of 65536" in reply["error"]["message"]


def test_binding_beyond_loopback_needs_a_token() -> None:
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "rlenv",
            "serve",
            "examples.cartpole:CartPoleEnvironment",
            "--host",
            "0.0.0.0",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        env={k: v for k, v in os.environ.items() if k != "RLENV_TOKEN"},
    )
    assert result.returncode == 2
    assert "refusing to listen on 0.0.0.0" in result.stderr and "--token" in result.stderr


def test_a_server_on_all_interfaces_with_a_token(
    serve: Serve, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("RLENV_TOKEN", raising=False)
    loopback_only = serve()
    with pytest.raises(ConnectionLost):  # 127.0.0.2 does not reach a server on 127.0.0.1 ...
        Client("127.0.0.2", loopback_only.port, timeout=5)
    server = serve(host="0.0.0.0", args=["--token", "t0ken"])
    assert server.host == "0.0.0.0"
    for address in ("127.0.0.1", "127.0.0.2"):  # ... but one on every interface
        with pytest.raises(RemoteError) as missing:
            Client(address, server.port, timeout=5)
        assert missing.value.code == ErrorCode.UNAUTHORIZED and "token" in missing.value.message
        with pytest.raises(RemoteError) as wrong:
            Client(address, server.port, token="t0ke", timeout=5)
        assert wrong.value.code == ErrorCode.UNAUTHORIZED and wrong.value.message == "wrong token"
        with Client(address, server.port, token="t0ken", timeout=5) as client:
            client.reset(seed=0)
            _, reward, *_ = client.step(np.zeros(1, np.float32))
            assert reward == 4.0


def test_an_idle_client_is_dropped_with_a_reason(serve: Serve) -> None:
    server = serve(args=["--idle-timeout", "2.0"])  # a loaded machine may be slow to send
    with socket.create_connection((server.host, server.port), timeout=30) as raw:
        read_frame(raw)  # the hello
        raw.sendall(frame(pack({"id": 1})))  # its first request: the idle timeout counts next
        assert read_frame(raw)["id"] == 1
        reply = read_frame(raw)  # blocks until the server gives up on us
        assert reply["error"]["code"] == ErrorCode.TIMEOUT and reply["error"]["fatal"]
        assert "no request for 2.0 s" in reply["error"]["message"]
    with Client(server.host, server.port) as client:  # and the next client is served
        client.reset(seed=0)


def test_deadlines_follow_the_injected_clock() -> None:
    """In process, with a manual clock: no sleeping, exact deadlines."""
    from examples.cartpole import CartPoleAgent

    clock = ManualClock()
    hello = Hello("T", CartPoleAgent.action_space, CartPoleAgent.observation_space)
    endpoint = Endpoint(hello, Limits(frame_deadline=2.0, idle_timeout=5.0), clock=clock)
    host, port = endpoint.start_server()
    try:
        dripping = socket.create_connection((host, port), timeout=5)
        idle = socket.create_connection((host, port), timeout=5)
        assert endpoint.receive(0) is None  # accepts both, sends the hellos
        for sock in (dripping, idle):  # their first requests: the idle timeout counts next
            read_frame(sock)
            sock.sendall(frame(pack({"id": 1})))
            got = endpoint.receive(0)
            assert got is not None
            endpoint.reply(got[0], Response(1))
            read_frame(sock)
        dripping.sendall(b"\x00\x00\x00")
        assert endpoint.receive(0) is None
        clock.advance(1.9)
        assert endpoint.receive(0) is None and endpoint.connections == 2
        clock.advance(0.2)
        assert endpoint.receive(0) is None and endpoint.connections == 1  # the drip is gone
        assert read_frame(dripping)["error"]["code"] == ErrorCode.TIMEOUT
        clock.advance(3.0)  # 5.1 s since the idle client's connection
        assert endpoint.receive(0) is None and endpoint.connections == 0
        assert "no request for 5.0 s" in read_frame(idle)["error"]["message"]
    finally:
        endpoint.close()


def test_silent_connections_make_room_for_a_client_with_the_token(serve: Serve) -> None:
    server = serve(args=["--token", "t0ken", "--max-connections", "2"])
    silent = [socket.create_connection((server.host, server.port), timeout=10) for _ in range(2)]
    try:
        for sock in silent:
            read_frame(sock)  # the hello; then nothing
        with (
            Client(server.host, server.port, token="t0ken", timeout=10) as first,
            Client(server.host, server.port, token="t0ken", timeout=10) as second,
        ):
            first.reset(seed=0)  # each got in at once, in the place of the oldest silent one
            second.observe()
            for sock in silent:
                error = read_frame(sock)["error"]
                assert (error["code"], error["fatal"]) == (ErrorCode.BUSY, True)
                assert (
                    "full (2 clients) and this connection had sent no request: a newer one "
                    "took its place" == error["message"][len("this server is ") :]
                )
            with pytest.raises(RemoteError) as full:  # clients with the token keep their place
                Client(server.host, server.port, token="t0ken", timeout=10)
            assert full.value.code == ErrorCode.BUSY and "2 clients connected" in full.value.message
            first.step(np.zeros(1, np.float32))
    finally:
        for sock in silent:
            sock.close()


def test_a_connection_without_its_first_request_is_dropped_soon() -> None:
    """The first request (with the token) is due within first_request_timeout, not the idle
    timeout; an injected clock, no sleeping."""
    from examples.cartpole import CartPoleAgent

    clock = ManualClock()
    hello = Hello("T", CartPoleAgent.action_space, CartPoleAgent.observation_space)
    endpoint = Endpoint(
        hello, Limits(first_request_timeout=2.0, idle_timeout=100.0), token="t0ken", clock=clock
    )
    host, port = endpoint.start_server()
    try:
        silent = socket.create_connection((host, port), timeout=5)
        admitted = socket.create_connection((host, port), timeout=5)
        assert endpoint.receive(0) is None
        assert endpoint.limits.to_wire()["first_request_timeout"] == 2.0
        assert read_frame(silent)["hello"]["limits"]["first_request_timeout"] == 2.0
        read_frame(admitted)
        admitted.sendall(frame(pack({"id": 1, "token": "t0ken"})))
        got = endpoint.receive(0)
        assert got is not None and got[1].id == 1
        endpoint.reply(got[0], Response(1))
        clock.advance(1.9)
        assert endpoint.receive(0) is None and endpoint.connections == 2
        clock.advance(0.2)
        assert endpoint.receive(0) is None and endpoint.connections == 1  # the silent one left
        error = read_frame(silent)["error"]
        assert (error["code"], error["fatal"]) == (ErrorCode.TIMEOUT, True)
        assert error["message"] == "no request with the right token within 2.0 s of connecting"
        assert read_frame(admitted)["id"] == 1
    finally:
        endpoint.close()


def test_wrong_tokens_slow_the_guesser_never_the_token_holder(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Past FREE_FAILURES wrong tokens, each wrong token's refusal is held (1 s, 2 s ...) out of
    any slot; the right token from the same address is let in at once; an address compares no
    token while MAX_HELD of its refusals are held; every wrong token is logged with the
    address, never the token. An injected clock, no sleeping."""
    from examples.cartpole import CartPoleAgent

    clock = ManualClock()
    hello = Hello("T", CartPoleAgent.action_space, CartPoleAgent.observation_space)
    endpoint = Endpoint(hello, Limits(max_connections=2), token="t0ken", clock=clock)
    host, port = endpoint.start_server()
    opened: list[socket.socket] = []

    def send(token: str) -> socket.socket:
        """Connect, read the hello, send ``token`` in the first request (id 1)."""
        sock = socket.create_connection((host, port), timeout=5)
        opened.append(sock)
        assert endpoint.receive(0) is None  # accepted: its hello
        assert "hello" in read_frame(sock)
        sock.sendall(frame(pack({"id": 1, "token": token})))
        return sock

    def served(sock: socket.socket) -> bool:
        got = endpoint.receive(0)
        if got is None:
            return False
        endpoint.reply(got[0], Response(1))
        assert read_frame(sock)["id"] == 1 and "error" not in read_frame_or_none(sock)
        return True

    def read_frame_or_none(sock: socket.socket) -> dict[str, Any]:
        sock.setblocking(False)
        try:
            return read_frame(sock)
        except BlockingIOError:
            return {}
        finally:
            sock.setblocking(True)

    def answered(sock: socket.socket) -> bool:
        return select.select([sock], [], [], 0)[0] != []

    caplog.set_level(logging.WARNING, logger="rlenv.serving._penalties")
    try:
        for _ in range(FREE_FAILURES):  # a person mistyping: answered at once
            sock = send("guess")
            assert endpoint.receive(0) is None
            assert read_frame(sock)["error"]["message"] == "wrong token"
        held = [send("guess")]  # its refusal waits 1 s, in no slot
        assert endpoint.receive(0) is None and not answered(held[0])
        assert endpoint.connections == 0
        assert served(send("t0ken"))  # the right token, from the same address: at once
        for _ in range(MAX_HELD - 1):  # 2 s, 4 s, 8 s
            held.append(send("guess"))
            assert endpoint.receive(0) is None
        waiting = send("t0ken")  # MAX_HELD held: compared once one goes out
        assert endpoint.receive(0) is None and not answered(waiting)
        clock.advance(1.0)
        assert served(waiting)  # the first held refusal went out: the token is compared
        error = read_frame(held[0])["error"]
        assert (error["code"], error["fatal"], error["message"]) == (
            ErrorCode.UNAUTHORIZED,
            True,
            "wrong token",
        )
        assert not any(answered(sock) for sock in held[1:])
        clock.advance(MAX_PENALTY)
        assert endpoint.receive(0) is None
        assert all(read_frame(sock)["error"]["message"] == "wrong token" for sock in held[1:])
        lines = [record.getMessage() for record in caplog.records]
        assert lines[:FREE_FAILURES] == [
            f"wrong token from 127.0.0.1 ({n} in a row)" for n in range(1, FREE_FAILURES + 1)
        ]
        assert lines[FREE_FAILURES:] == [
            f"wrong token from 127.0.0.1 ({FREE_FAILURES + n} in a row): answered in "
            f"{2 ** (n - 1)} s"
            for n in range(1, MAX_HELD + 1)
        ]
        assert not any("guess" in line or "t0ken" in line for line in lines)
    finally:
        for sock in opened:
            sock.close()
        endpoint.close()


def test_a_frame_that_would_expand_is_refused_and_the_server_keeps_its_memory(
    serve: Serve,
) -> None:
    server = serve()
    empties = 4 << 20  # 4 MiB of empty arrays: some 300 MB of Python lists, if decoded
    crafted = (
        b"\x82\xa2id\x02\xa5reset\x81\xa7options\x81\xa1a\xdd"
        + struct.pack(">I", empties)
        + b"\x90" * empties
    )
    with socket.create_connection((server.host, server.port), timeout=10) as raw:
        read_frame(raw)
        raw.sendall(frame(pack({"id": 1})))  # the first request: larger frames are allowed next
        assert read_frame(raw)["id"] == 1
        before = peak_rss_kib(server.pid)
        raw.sendall(frame(crafted))
        error = read_frame(raw)["error"]
        assert (error["code"], error["fatal"]) == (ErrorCode.BAD_FRAME, False)
        assert (
            error["message"] == "frame holds more than 1048576 msgpack objects, the limit "
            "of a frame"
        )
        growth = peak_rss_kib(server.pid) - before
        assert growth < 32 * 1024, f"the server's peak memory grew {growth} KiB"
        raw.sendall(frame(pack({"id": 3, "reset": {"seed": 0}})))
        assert read_frame(raw)["id"] == 3  # the same connection goes on
    with Client(server.host, server.port, timeout=10) as client:
        client.reset(seed=0)


def test_non_finite_observations_are_environment_errors(serve: Serve) -> None:
    with Client(*_address(serve("examples.faulty:CountingEnvironment")), timeout=10) as client:
        client.reset(seed=0)
        with pytest.raises(RemoteError) as error:
            client.step(1)
        assert error.value.code == ErrorCode.ENVIRONMENT_ERROR
        assert "observation of /root/Counting/Agent is not finite at [0]" in error.value.message
        observation, _ = client.reset(seed=0)
        assert observation.tolist() == [0.0]


def test_kills_and_stops_at_random_points_lose_and_duplicate_nothing(
    figures: dict[str, str],
) -> None:
    """A fault harness: the server is killed or stopped at random moments around steps; every
    transition the client sees is accounted for by the tick counter in the observation."""
    rng = random.Random(7)
    faults = 8
    env = RemoteEnv("examples.faulty:CountingEnvironment", max_restarts=faults, timeout=5.0)
    transitions = lost = duplicated = survived = 0
    try:
        observation, _ = env.reset(seed=0)
        for fault in range(faults):
            server = env.server
            assert server is not None
            signum = signal.SIGKILL if fault % 2 == 0 else signal.SIGSTOP
            timer = threading.Timer(rng.uniform(0.0, 0.01), _signal_group, (server.pid, signum))
            timer.start()
            restarted = False
            for _ in range(200):
                after, reward, terminated, truncated, info = env.step(0)
                transitions += 1
                if "server_restarted" in info:
                    assert truncated and not terminated and reward == 0.0
                    duplicated += int(after.tobytes() != observation.tobytes())
                    restarted = True
                    break
                expected = observation[0] + info["frames"]
                lost += int(after[0] > expected)
                duplicated += int(after[0] < expected)
                observation = after
            timer.join()
            if server.is_alive():  # the fault came after the last step we took
                _signal_group(server.pid, signal.SIGCONT)
                continue
            assert restarted or not server.is_alive()
            survived += int(restarted)
            observation, _ = env.reset(seed=0)
    finally:
        env.close()
    figures["fault harness"] = (
        f"{faults} faults (SIGKILL/SIGSTOP), {survived} server losses "
        f"survived, {transitions} transitions checked, {lost} lost, "
        f"{duplicated} duplicated"
    )
    assert lost == 0 and duplicated == 0
    assert survived >= faults // 2


def test_the_client_closes_rather_than_pair_a_late_answer(serve: Serve) -> None:
    server = serve("examples.faulty:CountingEnvironment")
    client = Client(server.host, server.port, timeout=3.0)  # the hello and reset's margin too
    client.reset(seed=0)
    os.killpg(server.pid, signal.SIGSTOP)
    try:
        with pytest.raises(Exception, match="did not answer within 3.0s"):
            client.step(0)
    finally:
        os.killpg(server.pid, signal.SIGCONT)
    with pytest.raises(ConnectionLost, match="closed"):
        client.step(0)  # the late answer is never read


def _signal_group(pid: int, signum: int) -> None:
    try:
        os.killpg(pid, signum)
    except ProcessLookupError:
        pass


def _address(server: object) -> tuple[str, int]:
    return server.host, server.port  # type: ignore[attr-defined]


def test_random_bytes_never_crash_the_protocol() -> None:
    hypothesis = pytest.importorskip("hypothesis")
    from hypothesis import strategies as st

    from rlenv.protocol import CONNECTION_CLOSED, NEED_DATA, Connection, Request, Role
    from rlenv.protocol.errors import RemoteProtocolError

    @hypothesis.settings(max_examples=300, deadline=None)
    @hypothesis.given(st.lists(st.binary(max_size=64), max_size=8))
    def feed(chunks: list[bytes]) -> None:
        connection = Connection(Role.SERVER, max_frame_size=1024)
        for chunk in chunks:
            connection.receive_data(chunk)
            for _ in range(16):
                try:
                    message = connection.next_message()
                except RemoteProtocolError as error:
                    if error.fatal:
                        return
                    continue
                if message is NEED_DATA:
                    break
                if message is CONNECTION_CLOSED:
                    return
                assert isinstance(message, Request)

    feed()


def test_random_requests_get_one_answer_each_and_the_environment_stays_sane() -> None:
    hypothesis = pytest.importorskip("hypothesis")
    from hypothesis import strategies as st

    from rlenv_client import LocalClient

    values = st.recursive(
        st.none()
        | st.booleans()
        | st.integers(-3, 10)
        | st.floats(allow_nan=True)
        | st.text(max_size=4),
        lambda inner: (
            st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3)
        ),
        max_leaves=6,
    )
    calls = st.lists(
        st.tuples(st.sampled_from(["reset", "step", "configure", "observe"]), values), max_size=12
    )

    @hypothesis.settings(max_examples=150, deadline=None)
    @hypothesis.given(calls)
    def run(sequence: list[tuple[str, object]]) -> None:
        with LocalClient("examples.cartpole:CartPoleEnvironment") as client:
            for name, value in sequence:
                try:
                    if name == "reset":
                        client.reset(seed=value if isinstance(value, int) and value >= 0 else None)
                    elif name == "step" and value is None:
                        with pytest.raises(TypeError, match="call poll"):
                            client.step(value)
                        client.poll()
                    elif name == "step":
                        client.step(value)
                    elif name == "configure":
                        settings = value if isinstance(value, dict) else {"repeat_action": value}
                        try:
                            client.configure(**settings)
                        except TypeError:  # agent= or world= that is not a map: refused here
                            assert any(
                                not isinstance(settings.get(part, {}), dict)
                                for part in ("agent", "world")
                            )
                    else:
                        client.observe()
                except RemoteError as error:
                    assert error.code in set(ErrorCode) and not error.fatal
            observation, _ = client.reset(seed=1)  # always recoverable
            assert observation in client.observation_space
            _, _, _, _, info = client.step(np.zeros(1, np.float32))
            assert info["frames"] >= 1

    run()


def test_an_answer_that_cannot_travel_is_an_environment_error(serve: Serve) -> None:
    """The client learns why instead of waiting; the server and the connection go on."""
    with Client(*_address(serve("examples.faulty:UnsendableEnvironment")), timeout=10) as client:
        client.reset(seed=0)
        with pytest.raises(RemoteError, match="the answer could not be sent") as error:
            client.step(1)
        assert error.value.code == ErrorCode.ENVIRONMENT_ERROR and "set" in error.value.message
        observation, *_ = client.step(0)
        assert observation.tolist() == [2]


def test_a_refused_request_takes_no_control(serve: Serve) -> None:
    """Whole or in a batch's slot: another client may still take control afterwards."""
    server = serve()
    with (
        Client(server.host, server.port, timeout=10) as first,
        Client(server.host, server.port, timeout=10) as second,
    ):
        with pytest.raises(RemoteError, match="reset.seed"):
            first.reset(seed=-1)
        first.send_batch([first.reset_request(seed=-1)])
        (refused,) = first.receive_batch()
        assert isinstance(refused, ErrorReply) and refused.code == ErrorCode.BAD_REQUEST
        second.reset(seed=1)  # not busy: the refusals took nothing
        with pytest.raises(RemoteError) as busy:
            first.reset(seed=1)
        assert busy.value.code == ErrorCode.BUSY


def test_requests_pipelined_behind_a_slow_one_are_all_answered(serve: Serve) -> None:
    """Frames that came in one read wait in the connection's buffer, not in the socket: they
    are served even when the first takes longer than the housekeeping interval."""
    server = serve("examples.faulty:CountingEnvironment")
    with socket.create_connection(_address(server), timeout=10) as sock:
        read_frame(sock)  # the hello
        for attempt in range(5):
            sock.sendall(frame(pack({"id": 3 * attempt + 1, "reset": {"seed": 0}})))
            assert read_frame(sock)["id"] == 3 * attempt + 1
            slow = pack(
                {
                    "id": 3 * attempt + 2,
                    "action": 0,
                    "repeat_action": 10_000,
                    "observation": {"agent": {}},
                }
            )  # the most ticks one action may run
            quick = pack({"id": 3 * attempt + 3, "observation": {"agent": {}}})
            sock.sendall(frame(slow) + frame(quick))  # one write: they arrive together
            assert read_frame(sock)["frames"] == 10_000
            assert read_frame(sock)["id"] == 3 * attempt + 3


@pytest.mark.parametrize("shared_memory", [None, False], ids=["lane", "socket"])
def test_answer_arrived_says_whether_receiving_would_wait(
    serve: Serve, shared_memory: bool | None
) -> None:
    """A hint a vector uses to await its slowest server first: false while the server works
    (here: forever, its tick hangs), true once the answer is there to take."""
    server = serve("examples.faulty:SlowEnvironment")
    with Client(server.host, server.port, shared_memory=shared_memory, timeout=60) as client:
        assert client.shared_memory is (shared_memory is None)
        client.reset(seed=0)
        client.send_step(0)
        wait_until(client.answer_arrived, "the answer to a quick step never arrived")
        assert client.receive_step()[4]["frames"] == 1
        client.send_step(1)  # the tick sleeps for an hour
        assert not client.answer_arrived()
