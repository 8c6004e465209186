"""The HTTP gateway's error statuses and safety rules, through real ``rlenv http`` subprocesses.

Every status of the issue: 400, 404, 409, 422, 503 with Retry-After, 504 (an environment that
hangs, also inside a pymunk callback, beside sessions that go on), 502 (an environment whose
server dies, and a relayed server); each as an RFC 9457 problem, and each followed by a
request that is served. Then Host, Origin, the token, body limits, idle sessions, garbage on
the socket.
"""

from __future__ import annotations

import http.client
import os
import resource
import select
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import pytest
from conftest import Serve, wait_until
from http_gateway import Gateway, assert_problem

from rlenv.serving._penalties import FREE_FAILURES

CARTPOLE = "examples.cartpole:CartPoleEnvironment"


@pytest.fixture(scope="module")
def gateway() -> Iterator[Gateway]:
    started = Gateway(CARTPOLE, "--max-body", "4096")
    yield started
    started.close()


def test_bad_bodies_are_400(gateway: Gateway) -> None:
    session = gateway.session()
    step = f"/v1/envs/{session}/step"
    assert (
        "not JSON"
        in assert_problem(gateway.request("POST", step, raw=b'{"action": '), 400, "bad_request")[
            "detail"
        ]
    )
    assert_problem(gateway.request("POST", step, raw=b'{"action": [NaN]}'), 400, "bad_request")
    assert_problem(gateway.request("POST", step), 400, "bad_request")  # no body
    assert_problem(gateway.request("POST", step, [0.5]), 400, "bad_request")
    unknown = gateway.request("POST", step, {"action": [0.5], "repeat": 2})
    assert "'repeat'" in assert_problem(unknown, 400, "bad_request")["detail"]
    assert_problem(gateway.request("POST", step, {"repeat_action": 2}), 400, "bad_request")
    gateway.post(f"/v1/envs/{session}/reset")
    assert_problem(
        gateway.request("POST", step, {"action": [0.5], "repeat_action": 0}), 400, "bad_request"
    )
    assert_problem(
        gateway.request("POST", f"/v1/envs/{session}/reset", {"seed": -1}), 400, "bad_request"
    )
    assert_problem(
        gateway.request("POST", f"/v1/envs/{session}/reset", {"seed": True}), 400, "bad_request"
    )
    unknown_id = gateway.request("POST", "/v1/envs", {"env_id": "os:system"})
    assert "rlenv/CartPole-v0" in assert_problem(unknown_id, 400, "bad_request")["detail"]
    assert gateway.post(step, {"action": [0.5]})["info"]["frames"] == 4  # served after all that


def test_a_repeat_action_beyond_the_limit_is_400_at_once_and_the_session_steps_on(
    gateway: Gateway,
) -> None:
    """Before, 2**40 ticks held the session's server until the gateway gave up (504)."""
    session = gateway.session()
    gateway.post(f"/v1/envs/{session}/reset", {"seed": 1})
    step = f"/v1/envs/{session}/step"
    for repeat in (10_001, 2**40):
        refused = gateway.request("POST", step, {"action": [0.5], "repeat_action": repeat})
        assert "must be at most 10000" in assert_problem(refused, 400, "bad_request")["detail"]
    assert gateway.post(step, {"action": [0.5], "repeat_action": 10_000})["info"]["frames"] >= 1


def test_unknown_sessions_and_routes_are_404_and_methods_405(gateway: Gateway) -> None:
    for method, path in (
        ("GET", "/v1/envs/nope"),
        ("POST", "/v1/envs/nope/step"),
        ("POST", "/v1/envs/nope/reset"),
        ("GET", "/v1/envs/nope/render"),
        ("GET", "/v1/envs/nope/action_space"),
        ("POST", "/v1/envs/nope/action_space/sample"),
    ):
        assert_problem(gateway.request(method, path, {"action": [0.0]}), 404, "unknown_session")
    assert_problem(gateway.request("GET", "/no/such/route"), 404, "not_found")
    wrong = gateway.request("PUT", "/v1/envs")
    assert_problem(wrong, 405, "method_not_allowed")
    assert set(wrong.headers["allow"].replace(" ", "").split(",")) >= {"GET", "POST"}
    assert "access-control-allow-origin" not in wrong.headers  # never CORS
    assert_problem(gateway.request("OPTIONS", "/v1/envs"), 405, "method_not_allowed")


def test_steps_before_a_reset_and_after_the_end_are_409(gateway: Gateway) -> None:
    session = gateway.session()
    early = gateway.request("POST", f"/v1/envs/{session}/step", {"action": [0.0]})
    assert "reset" in assert_problem(early, 409, "reset_required")["detail"]
    gateway.post(f"/v1/envs/{session}/reset", {"seed": 0})
    for _ in range(500):
        if gateway.post(f"/v1/envs/{session}/step", {"action": [1.0]})["terminated"]:
            break
    assert gateway.get(f"/v1/envs/{session}")["status"] == "ended"
    late = gateway.request("POST", f"/v1/envs/{session}/step", {"action": [0.0]})
    assert "terminated" in assert_problem(late, 409, "reset_required")["detail"]
    gateway.post(f"/v1/envs/{session}/reset")
    assert gateway.get(f"/v1/envs/{session}")["status"] == "running"


def test_actions_outside_the_space_are_422(gateway: Gateway) -> None:
    session = gateway.session()
    gateway.post(f"/v1/envs/{session}/reset", {"seed": 0})
    for action, words in (
        ([2.0], "outside the bounds"),
        ([0.1, 0.2], "shape"),
        ("left", "array"),
        ([None], ""),
    ):
        reply = gateway.request("POST", f"/v1/envs/{session}/step", {"action": action})
        assert words in assert_problem(reply, 422, "invalid_action")["detail"]
    assert gateway.get(f"/v1/envs/{session}")["step"] == 0  # a refused action changed nothing
    gateway.post(f"/v1/envs/{session}/step", {"action": [0.0]})


def test_the_session_limit_is_503_with_retry_after() -> None:
    limited = Gateway(CARTPOLE, "--max-sessions", "2", "--idle-timeout", "120")
    try:
        first, _ = limited.session(), limited.session()
        full = limited.request("POST", "/v1/envs", {})
        assert_problem(full, 503, "session_limit")
        assert 1 <= int(full.headers["retry-after"]) <= 120
        assert limited.request("DELETE", f"/v1/envs/{first}").status == 204
        limited.session()
    finally:
        limited.close()


def test_one_client_holds_at_most_its_share_of_the_sessions() -> None:
    limited = Gateway(
        CARTPOLE, "--max-sessions", "4", "--max-sessions-per-client", "2", "--idle-timeout", "120"
    )
    try:
        first, _ = limited.session(), limited.session()
        greedy = limited.request("POST", "/v1/envs", {})
        assert (
            "2 sessions per client, and 127.0.0.1 has as many"
            in assert_problem(greedy, 503, "session_limit")["detail"]
        )
        assert 1 <= int(greedy.headers["retry-after"]) <= 120
        other = http.client.HTTPConnection(
            "127.0.0.1", limited.port, timeout=60, source_address=("127.0.0.2", 0)
        )
        try:  # another client still finds room
            other.request("POST", "/v1/envs", "{}")
            assert other.getresponse().status == 201
        finally:
            other.close()
        assert limited.get("/v1")["limits"]["max_sessions_per_client"] == 2
        assert limited.request("DELETE", f"/v1/envs/{first}").status == 204
        limited.session()
    finally:
        limited.close()


def test_a_creation_abandoned_mid_request_frees_its_slot() -> None:
    limited = Gateway(CARTPOLE, "--max-sessions", "1", "--idle-timeout", "600")
    try:
        body = b"{}"
        with socket.create_connection((limited.host, limited.port), timeout=30) as abandoned:
            abandoned.sendall(
                f"POST /v1/envs HTTP/1.1\r\nHost: {limited.host}:{limited.port}"
                f"\r\nContent-Length: {len(body)}\r\n\r\n".encode()
                + body
            )

        # it left before its answer: the session is deleted as soon as it is made, not reaped
        # 600 s later; meanwhile the slot may be taken (503) or free
        def created() -> bool:
            reply = limited.request("POST", "/v1/envs", {})
            assert reply.status in (201, 503), reply
            return reply.status == 201

        wait_until(created, "the abandoned creation kept the only slot", seconds=60)
        assert len(limited.get("/v1/envs")["envs"]) == 1
        assert "its client left before it was told of it" in limited.stderr()
    finally:
        limited.close()


def test_idle_sessions_are_reaped() -> None:
    reaping = Gateway(CARTPOLE, "--idle-timeout", "0.5")
    try:
        session = reaping.session()
        wait_until(
            lambda: not reaping.get("/v1/envs")["envs"], "the idle session stayed", seconds=20
        )
        assert_problem(reaping.request("GET", f"/v1/envs/{session}"), 404, "unknown_session")
    finally:
        reaping.close()


def test_an_environment_that_hangs_is_504_and_the_others_go_on() -> None:
    slow = Gateway("examples.faulty:SlowEnvironment", "--timeout", "3")  # the resets' too
    try:
        hung, fine = slow.session(), slow.session()
        for session in (hung, fine):
            slow.post(f"/v1/envs/{session}/reset", {"seed": 0})
        started = time.monotonic()
        timed_out = slow.request("POST", f"/v1/envs/{hung}/step", {"action": 1})
        assert_problem(timed_out, 504, "timeout")
        assert time.monotonic() - started < 30
        described = slow.get(f"/v1/envs/{hung}")
        assert described["status"] == "timed_out" and described["problem"]["status"] == 504
        assert_problem(
            slow.request("POST", f"/v1/envs/{hung}/step", {"action": 0}), 504, "timeout"
        )  # the session says so until it is deleted
        assert slow.post(f"/v1/envs/{fine}/step", {"action": 0})["observation"] == [1]
        assert slow.request("DELETE", f"/v1/envs/{hung}").status == 204
    finally:
        slow.close()


def test_an_isolated_environment_that_hangs_is_504() -> None:
    slow = Gateway("examples.faulty:SlowEnvironment", "--isolate", "--timeout", "3")  # accepted
    try:
        hung, fine = slow.session(), slow.session()
        for session in (hung, fine):
            slow.post(f"/v1/envs/{session}/reset", {"seed": 0})
        assert_problem(slow.request("POST", f"/v1/envs/{hung}/step", {"action": 1}), 504, "timeout")
        assert slow.get(f"/v1/envs/{hung}")["status"] == "timed_out"
        assert slow.post(f"/v1/envs/{fine}/step", {"action": 0})["observation"] == [1]
        assert slow.get("/v1")["hosting"] == "isolated"
    finally:
        slow.close()


def test_an_environment_stuck_in_a_pymunk_callback_is_504_in_time() -> None:
    stuck = Gateway("examples.faulty:StuckEnvironment", "--timeout", "0.5")
    try:
        looping, sleeping, fine = stuck.session(), stuck.session(), stuck.session()
        for session in (looping, sleeping, fine):
            stuck.post(f"/v1/envs/{session}/reset", {"seed": 0})
        for session, action in ((looping, 1), (sleeping, 2)):
            started = time.monotonic()
            answer = stuck.request("POST", f"/v1/envs/{session}/step", {"action": action})
            assert_problem(answer, 504, "timeout")
            assert time.monotonic() - started < 2.5  # the deadline, not the callback, decides
            assert stuck.get(f"/v1/envs/{session}")["status"] == "timed_out"
        assert stuck.post(f"/v1/envs/{fine}/step", {"action": 0})["observation"] == [1]
    finally:
        assert stuck.close() < 5  # SIGTERM ends it, and the stuck servers with it


def test_a_slow_session_never_stalls_the_others() -> None:
    gateway = Gateway("examples.faulty:StuckEnvironment", "--timeout", "2")
    try:
        slow, fast = gateway.session(), gateway.session()
        for session in (slow, fast):
            gateway.post(f"/v1/envs/{session}/reset", {"seed": 0})
        body = b'{"action": 2}'  # sleeps 5 s in a collision callback: 504 after 2 s
        pending = socket.create_connection((gateway.host, gateway.port), timeout=30)
        try:
            pending.sendall(
                f"POST /v1/envs/{slow}/step HTTP/1.1\r\nHost: {gateway.host}:"
                f"{gateway.port}\r\nContent-Length: {len(body)}\r\n"
                "Connection: close\r\n\r\n".encode()
                + body
            )
            started = time.monotonic()
            for tick in range(1, 21):
                step = gateway.post(f"/v1/envs/{fast}/step", {"action": 0})
                assert step["observation"] == [tick]
            assert time.monotonic() - started < 1.5  # not 2 s behind the slow one
            assert not select.select([pending], [], [], 0)[0]  # the slow one still runs
            assert _read_all(pending).startswith(b"HTTP/1.1 504")
        finally:
            pending.close()
        assert gateway.post(f"/v1/envs/{fast}/step", {"action": 0})["observation"] == [21]
    finally:
        gateway.close()


def test_an_environment_whose_server_dies_is_502_and_the_others_go_on() -> None:
    dying = Gateway("examples.faulty:DyingEnvironment", "--isolate", "--timeout", "10")
    try:
        lost, fine = dying.session(), dying.session()
        for session in (lost, fine):
            dying.post(f"/v1/envs/{session}/reset", {"seed": 0})
        assert_problem(
            dying.request("POST", f"/v1/envs/{lost}/step", {"action": 1}), 502, "environment_lost"
        )
        described = dying.get(f"/v1/envs/{lost}")
        assert described["status"] == "lost" and described["problem"]["status"] == 502
        assert_problem(dying.request("POST", f"/v1/envs/{lost}/reset"), 502, "environment_lost")
        assert dying.post(f"/v1/envs/{fine}/step", {"action": 0})["observation"] == [1]
        assert {s["status"] for s in dying.get("/v1/envs")["envs"]} == {"lost", "running"}
    finally:
        dying.close()


def test_an_environment_that_calls_exit_ends_its_session_not_the_gateway() -> None:
    hosting = Gateway("examples.faulty:DyingEnvironment")
    try:
        exiting, fine = hosting.session(), hosting.session()
        for session in (exiting, fine):
            hosting.post(f"/v1/envs/{session}/reset")
        exited = hosting.request("POST", f"/v1/envs/{exiting}/step", {"action": 2})
        assert "closed the connection" in assert_problem(exited, 502, "environment_lost")["detail"]
        assert hosting.get(f"/v1/envs/{exiting}")["status"] == "lost"
        assert hosting.post(f"/v1/envs/{fine}/step", {"action": 0})["observation"] == [1]
    finally:
        hosting.close()


def test_a_relayed_server_that_dies_is_502(serve: Serve) -> None:
    server = serve()
    relay = Gateway(server.address)
    try:
        session = relay.session()
        assert relay.post(f"/v1/envs/{session}/reset", {"seed": 3})["observation"]
        assert relay.post(f"/v1/envs/{session}/step", {"action": [0.0]})["info"]["frames"] == 4
        second = relay.session()  # the server's one environment has one controller
        assert_problem(relay.request("POST", f"/v1/envs/{second}/reset"), 409, "busy")
        server.close()
        assert_problem(
            relay.request("POST", f"/v1/envs/{session}/step", {"action": [0.0]}),
            502,
            "environment_lost",
        )
        assert relay.get(f"/v1/envs/{session}")["status"] == "lost"
        assert relay.get("/v1")["target"] == server.address
    finally:
        relay.close()


def test_an_environment_that_raises_is_500_and_recovers() -> None:
    faulty = Gateway("examples.faulty:FaultyEnvironment")
    try:
        session = faulty.session()
        faulty.post(f"/v1/envs/{session}/reset")
        raised = faulty.request("POST", f"/v1/envs/{session}/step", {"action": 1})
        assert "tripped over action 1" in assert_problem(raised, 500, "environment_error")["detail"]
        faulty.post(f"/v1/envs/{session}/reset")
        assert faulty.post(f"/v1/envs/{session}/step", {"action": 0})["info"]["frames"] == 3
    finally:
        faulty.close()


def test_foreign_hosts_and_origins_are_403(gateway: Gateway) -> None:
    port = gateway.port
    for headers in (
        {"Host": "attacker.example"},
        {"Host": f"attacker.example:{port}"},
        {"Host": f"127.0.0.1.attacker.example:{port}"},
        {"Host": "127.0.0.1:1"},
        {"Origin": "http://attacker.example"},
        {"Origin": f"http://127.0.0.1:{port + 1}"},
    ):
        refused = gateway.request("GET", "/v1/envs", headers=headers)
        assert "refused" in assert_problem(refused, 403, "forbidden")["detail"]
    for host in (f"localhost:{port}", f"127.0.0.1:{port}", f"[::1]:{port}"):
        assert gateway.request("GET", "/v1", headers={"Host": host}).status == 200
    assert (
        gateway.request("GET", "/v1", headers={"Origin": f"http://localhost:{port}"}).status == 200
    )
    with pytest.raises(Exception, match="403"):
        from websockets.sync.client import connect

        connect(
            f"ws://{gateway.host}:{port}/v1/envs/{gateway.session()}/ws",
            origin="http://attacker.example",
        ).close()  # type: ignore[arg-type]


def test_requests_a_page_of_another_origin_made_are_403() -> None:
    bevy = Gateway(CARTPOLE)
    try:
        for site in ("cross-site", "same-site"):  # what an <img src> sends: no Origin
            for path in (
                "/step?payload=%5B%7B%22action%22%3A%22%5B0.0%5D%22%7D%5D",
                "/reset",
                "/state",
                "/v1/envs",
            ):
                refused = bevy.request("GET", path, headers={"Sec-Fetch-Site": site})
                assert "Sec-Fetch-Site" in assert_problem(refused, 403, "forbidden")["detail"]
        assert bevy.get("/v1/envs")["envs"] == []  # nothing was created, nor stepped
        for site in ("same-origin", "none"):  # the gateway's own pages; a typed URL
            assert bevy.request("GET", "/state", headers={"Sec-Fetch-Site": site}).status == 200
    finally:
        bevy.close()


def test_bodies_are_limited(gateway: Gateway) -> None:
    session = gateway.session()
    large = gateway.request("POST", f"/v1/envs/{session}/step", raw=b" " * 5000)
    assert_problem(large, 413, "payload_too_large")
    connection = socket.create_connection((gateway.host, gateway.port))
    try:  # a chunked body that grows past the limit
        connection.sendall(
            f"POST /v1/envs/{session}/step HTTP/1.1\r\nHost: {gateway.host}:"
            f"{gateway.port}\r\nTransfer-Encoding: chunked\r\n\r\n".encode()
        )
        for _ in range(3):
            connection.sendall(b"800\r\n" + b" " * 2048 + b"\r\n")
        connection.sendall(b"0\r\n\r\n")
        answer = _read_all(connection)
        assert answer.startswith(b"HTTP/1.1 413") and b"payload_too_large" in answer
    finally:
        connection.close()
    gateway.post(f"/v1/envs/{session}/reset")


def test_garbage_on_the_socket_never_stops_it(gateway: Gateway) -> None:
    for garbage in (
        b"GARBAGE\r\n\r\n",
        b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03",
        b"GET / HTTP/1.1\r\nHost: " + b"x" * 100_000 + b"\r\n\r\n",
        b"POST /v1/envs HTTP/1.1\r\nContent-Length: 10\r\n\r\n{",
    ):
        connection = socket.create_connection((gateway.host, gateway.port), timeout=30)
        try:
            connection.sendall(garbage)
            connection.shutdown(socket.SHUT_WR)
            _read_all(connection)
        finally:
            connection.close()
    assert gateway.get("/v1")["versions"] == ["v1"]


def test_unfinished_request_heads_are_closed_in_time() -> None:
    gateway = Gateway(CARTPOLE, "--head-timeout", "0.5")
    try:
        for start in (b"", b"GET /v1 HTTP/1.1\r\nHost: x"):  # nothing, or half a head
            connection = socket.create_connection((gateway.host, gateway.port), timeout=30)
            try:
                connection.sendall(start)
                started = time.monotonic()
                assert _read_all(connection) == b""  # closed, without an answer
                assert time.monotonic() - started < 3
            finally:
                connection.close()
        assert gateway.get("/v1")["limits"]["head_timeout"] == 0.5
    finally:
        gateway.close()


def test_unfinished_heads_never_keep_real_requests_out() -> None:
    gateway = Gateway(CARTPOLE, "--max-connections", "16")
    resource.prlimit(gateway.process.pid, resource.RLIMIT_NOFILE, (64, 64))
    loris: list[socket.socket] = []
    try:
        for _ in range(80):  # more than the gateway can open files for
            connection = socket.create_connection((gateway.host, gateway.port), timeout=30)
            connection.sendall(b"GET /v1 HTTP/1.1\r\n")
            loris.append(connection)
        started = time.monotonic()
        assert gateway.request("GET", "/v1", timeout=5).status == 200
        assert gateway.post(f"/v1/envs/{gateway.session()}/reset")["observation"]
        assert time.monotonic() - started < 5
    finally:
        for connection in loris:
            connection.close()
        gateway.close()


def _read_all(connection: socket.socket) -> bytes:
    connection.settimeout(30)
    data = b""
    while chunk := connection.recv(65536):
        data += chunk
    return data


def test_binding_beyond_loopback_needs_a_token() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "rlenv", "http", CARTPOLE, "--host", "0.0.0.0", "--port", "0"],
        capture_output=True,
        text=True,
        timeout=60,
        env={k: v for k, v in os.environ.items() if k != "RLENV_TOKEN"},
    )
    assert result.returncode == 2
    assert "refusing to listen on 0.0.0.0" in result.stderr and "RLENV_TOKEN" in result.stderr


def test_a_token_is_required_when_set() -> None:
    guarded = Gateway(CARTPOLE, "--host", "0.0.0.0", env={"RLENV_TOKEN": "s3cret"})
    try:
        assert guarded.url.startswith("http://0.0.0.0:")
        port = guarded.port
        guarded.host = "127.0.0.1"
        missing = guarded.request("GET", "/v1/envs", headers={"Host": f"127.0.0.1:{port}"})
        assert_problem(missing, 401, "unauthorized")
        assert missing.headers["www-authenticate"].startswith("Bearer")
        wrong = guarded.request("GET", "/v1/envs", headers={"Authorization": "Bearer nope"})
        assert assert_problem(wrong, 401, "unauthorized")["detail"] == "wrong token"
        good = {"Authorization": "Bearer s3cret", "Host": f"some.name:{port}"}
        assert guarded.request("GET", "/v1", headers=good).json()["token_required"] is True
        assert "s3cret" not in guarded.request("GET", "/openapi.json", headers=good).body.decode()
        foreign = guarded.request("GET", "/v1", headers={**good, "Origin": "http://evil.test"})
        assert_problem(foreign, 403, "forbidden")
    finally:
        guarded.close()


def test_wrong_tokens_slow_the_guesser_never_the_token_holder() -> None:
    """Past FREE_FAILURES, each wrong token's 401 is held (1 s, 2 s ...); the token holder on the
    same address is served every time meanwhile, and its successes do not renew the guesser's
    free tries: a bound on the guesses answered, whatever the load."""
    guarded = Gateway(CARTPOLE, "--host", "0.0.0.0", env={"RLENV_TOKEN": "s3cret"})
    try:
        guarded.host = "127.0.0.1"
        wrong, good = {"Authorization": "Bearer nope"}, {"Authorization": "Bearer s3cret"}
        for _ in range(FREE_FAILURES):
            assert (
                assert_problem(guarded.request("GET", "/v1", headers=wrong), 401, "unauthorized")[
                    "detail"
                ]
                == "wrong token"
            )
        session = guarded.request("POST", "/v1/envs", {}, headers=good).json()["id"]
        answered = []  # the guesses' answers, from four guessers at once
        stop = threading.Event()

        def guess() -> None:
            while not stop.is_set():
                started = time.monotonic()
                reply = guarded.request("GET", "/v1", headers=wrong)
                answered.append((reply.status, time.monotonic() - started))

        guessers = [threading.Thread(target=guess) for _ in range(4)]
        for thread in guessers:
            thread.start()
        started = time.monotonic()
        try:
            statuses, ended = [], True
            for _ in range(20):
                if ended:
                    guarded.request("POST", f"/v1/envs/{session}/reset", {}, headers=good)
                step = guarded.request(
                    "POST", f"/v1/envs/{session}/step", {"action": [0.0]}, headers=good
                )
                statuses.append(step.status)
                ended = step.status == 200 and (
                    step.json()["terminated"] or step.json()["truncated"]
                )
            assert statuses == [200] * 20  # never refused for the guessers' failures
            wait_until(lambda: time.monotonic() - started >= 3.0, "no time passed")
        finally:
            stop.set()
            for thread in guessers:
                thread.join(30)
        elapsed = time.monotonic() - started
        assert all(status == 401 for status, _ in answered)
        assert all(took >= 1.0 for _, took in answered), answered  # each one held
        # Held 1, 2, 4, 8 s ...: four guessers get at most one answer each per second held
        assert len(answered) <= 4 * (elapsed + 1), (len(answered), elapsed)
        other = http.client.HTTPConnection(
            "127.0.0.1", guarded.port, timeout=30, source_address=("127.0.0.2", 0)
        )
        try:  # another address is not affected
            other.request("GET", "/v1", headers=wrong)
            assert other.getresponse().status == 401
        finally:
            other.close()
        log = guarded.stderr()
        assert "wrong token from 127.0.0.1 (1 in a row)" in log
        assert f"wrong token from 127.0.0.1 ({FREE_FAILURES + 1} in a row): answered in 1 s" in log
        assert "wrong token from 127.0.0.2 (1 in a row)" in log
        assert "nope" not in log and "s3cret" not in log
    finally:
        guarded.close()


def test_an_unknown_target_is_refused_at_start() -> None:
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "rlenv",
            "http",
            "examples.cartpole:NoSuchEnvironment",
            "--port",
            "0",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2 and "NoSuchEnvironment" in result.stderr
