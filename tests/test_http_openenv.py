"""OpenEnv's routes on ``rlenv http`` (``/openenv``), with plain WebSocket and HTTP clients.

The messages are those of ``openenv-core`` 0.3 (``{"type", "data"}`` on ``WS /openenv/ws``,
``ResetRequest``, ``StepRequest``, ``State`` ...), written out here so that the default suite
needs no openenv-core; ``test_openenv.py`` plays them with OpenEnv's own client (``make
test-openenv``).
"""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Iterator
from typing import Any

import gymnasium as gym
import jsonschema
import pytest
from conftest import Serve
from http_gateway import Gateway, assert_problem, assert_same_observation
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import ClientConnection, connect

import rlenv_client  # noqa: F401  (registers the ids)

CARTPOLE = "rlenv/CartPole-v1"
PAIR = "rlenv/Pair-v0"


@pytest.fixture(scope="module")
def gateway() -> Iterator[Gateway]:
    """``rlenv http rlenv/CartPole-v1 --max-body 4096``, shared by this module's tests."""
    started = Gateway(CARTPOLE, "--max-body", "4096")
    yield started
    started.close()


class Conversation:
    """An OpenEnv WebSocket: one ``{"type", "data"}`` message, one answer."""

    def __init__(self, websocket: ClientConnection) -> None:
        self.websocket = websocket

    def ask(self, kind: str, data: Any = None, **more: Any) -> dict[str, Any]:
        message = {"type": kind, **({} if data is None else {"data": data}), **more}
        return self.send(json.dumps(message))

    def send(self, text: str | bytes) -> dict[str, Any]:
        self.websocket.send(text)
        return json.loads(self.websocket.recv(timeout=30))

    def error(self, kind: str, data: Any = None, **more: Any) -> dict[str, Any]:
        """The error answering this message: its ``data``."""
        answer = self.ask(kind, data, **more)
        assert answer["type"] == "error" and answer.keys() == {"type", "data"}, answer
        assert {"message", "code", "problem"} <= answer["data"].keys(), answer
        return answer["data"]


@contextlib.contextmanager
def openenv_websocket(
    gateway: Gateway, headers: dict[str, str] | None = None
) -> Iterator[Conversation]:
    """``WS /openenv/ws`` of ``gateway``, closed on leaving."""
    url = f"ws://{gateway.host}:{gateway.port}/openenv/ws"
    with connect(url, additional_headers=headers) as websocket:
        yield Conversation(websocket)


def _session_ids(gateway: Gateway) -> set[str]:
    return {session["id"] for session in gateway.get("/v1/envs")["envs"]}


def _wait_until_gone(gateway: Gateway, session_id: str, seconds: float = 30.0) -> None:
    deadline = time.monotonic() + seconds
    while session_id in _session_ids(gateway):
        assert time.monotonic() < deadline, f"session {session_id} still there"
        time.sleep(0.02)


def test_health_schema_and_metadata_describe_the_target(gateway: Gateway) -> None:
    assert gateway.get("/openenv/health") == {"status": "healthy"}
    schema = gateway.get("/openenv/schema")
    assert schema.keys() == {"action", "observation", "state"}
    session = gateway.session()
    spaces = gateway.get(f"/v1/envs/{session}/action_space")["schema"]
    assert schema["action"]["properties"]["action"] == spaces  # the TARGET's own space
    assert schema["action"]["required"] == ["action"]
    observed = gateway.get(f"/v1/envs/{session}/observation_space")["schema"]
    assert schema["observation"]["properties"]["observation"] == observed
    assert {"episode_id", "step_count"} <= schema["state"]["properties"].keys()
    metadata = gateway.get("/openenv/metadata")
    assert metadata["name"] == CARTPOLE and metadata["version"] == gateway.get("/v1")["rlenv"]
    assert {"description", "readme_content", "author", "documentation_url"} <= metadata.keys()
    assert gateway.get("/v1")["capabilities"]["openenv"] == "/openenv"
    paths = gateway.get("/openapi.json")["paths"]
    assert {p for p in paths if p.startswith("/openenv/")} == {
        f"/openenv/{route}"
        for route in ("ws", "reset", "step", "state", "health", "schema", "metadata")
    }


def test_each_websocket_is_a_session_of_its_own_played_as_gymnasium_plays_it(
    gateway: Gateway,
) -> None:
    """Observations bit for bit, both flags in the metadata, ``done`` when either is set."""
    schema = gateway.get("/openenv/schema")
    before = _session_ids(gateway)
    expected_env = gym.make(CARTPOLE)
    try:
        with openenv_websocket(gateway) as conversation:
            reset = conversation.ask("reset", {"seed": 3, "episode_id": "first"})
            (session,) = _session_ids(gateway) - before  # opened with the WebSocket
            assert reset["type"] == "observation" and reset["data"].keys() == {
                "observation",
                "reward",
                "done",
            }
            data = reset["data"]
            assert data["reward"] is None and data["done"] is False
            assert data["observation"]["metadata"] == {
                "terminated": False,
                "truncated": False,
                "info": {"frames": 0},
            }
            jsonschema.validate(data["observation"], schema["observation"])
            expected, _ = expected_env.reset(seed=3)
            assert_same_observation(data["observation"]["observation"], expected)
            steps = 0
            while True:  # a balancing policy, to the time limit
                action = int(expected[2] + 0.5 * expected[3] > 0)
                answer = conversation.ask("step", {"action": action})["data"]
                expected, reward, terminated, truncated, _ = expected_env.step(action)
                steps += 1
                observation = answer["observation"]
                assert_same_observation(observation["observation"], expected)
                assert answer["reward"] == reward
                assert observation["metadata"]["terminated"] == terminated
                assert observation["metadata"]["truncated"] == truncated
                assert answer["done"] == (terminated or truncated)
                if answer["done"]:
                    break
            assert steps == 500 and truncated and not terminated  # gymnasium's TimeLimit
            state = conversation.ask("state")
            assert state["type"] == "state"
            assert state["data"] == {
                "episode_id": "first",
                "step_count": 500,
                "env_id": CARTPOLE,
                "episode": 1,
                "status": "ended",
            }
            ended = conversation.error("step", {"action": 0})
            assert ended["code"] == "EXECUTION_ERROR"
            assert ended["problem"]["code"] == "reset_required"
            again = conversation.ask("reset", {})["data"]  # no seed: the episodes go on
            expected, _ = expected_env.reset()
            assert_same_observation(again["observation"]["observation"], expected)
            state = conversation.ask("state")["data"]
            assert state["episode"] == 2 and state["step_count"] == 0
            assert state["episode_id"] not in (None, "first")
            conversation.websocket.send(json.dumps({"type": "close"}))
            with pytest.raises(ConnectionClosed) as closed:
                conversation.websocket.recv(timeout=30)  # unanswered, as OpenEnv's server
            assert closed.value.rcvd is not None and closed.value.rcvd.code == 1000
        assert session not in _session_ids(gateway)  # deleted before the WebSocket closed
    finally:
        expected_env.close()


def test_refusals_are_openenvs_error_messages_and_the_conversation_goes_on(
    gateway: Gateway,
) -> None:
    with openenv_websocket(gateway) as conversation:
        before_reset = conversation.error("step", {"action": 0})
        assert before_reset["code"] == "EXECUTION_ERROR"
        assert before_reset["problem"]["code"] == "reset_required"
        assert conversation.send("not json")["data"]["code"] == "INVALID_JSON"
        for unknown in ({"type": "jump"}, {"type": "mcp", "data": {}}, [1], {"data": {}}):
            refused = conversation.send(json.dumps(unknown))["data"]
            assert refused["code"] == "UNKNOWN_TYPE" and refused["problem"]["status"] == 400
        conversation.ask("reset", {"seed": 0})
        for data, needle, code in (
            ({"action": 2}, "outside", "invalid_action"),  # Discrete(2)
            ({"action": [1]}, "integer", "invalid_action"),
            ({"action": 1, "bogus": True}, "'bogus'", "bad_request"),
            ({"action": 1, "metadata": [1]}, "metadata", "bad_request"),
            ({"metadata": {}}, "'action'", "bad_request"),
            (1, "JSON object", "bad_request"),
        ):
            refused = conversation.error("step", data)
            assert refused["code"] == "VALIDATION_ERROR", refused
            assert refused["problem"]["code"] == code and needle in refused["message"], refused
        assert "'data'" in conversation.error("step")["message"]
        assert "'bogus'" in conversation.error("reset", {"bogus": 1})["message"]
        assert "'data'" in conversation.error("state", {})["message"]
        assert "episode_id" in conversation.error("reset", {"episode_id": 7})["message"]
        negative = conversation.error("reset", {"seed": -1})
        assert negative["code"] == "VALIDATION_ERROR" and negative["problem"]["status"] == 400
        # it goes on: the episode the last good reset began, in a binary frame too
        step = conversation.send(json.dumps({"type": "step", "data": {"action": 1}}).encode())
        assert step["type"] == "observation" and step["data"]["reward"] == 1.0
        repeated = conversation.ask("step", {"action": 1, "repeat_action": 2, "metadata": {}})
        assert repeated["data"]["observation"]["metadata"]["info"]["frames"] == 2


def test_a_session_deleted_under_its_websocket_says_so(gateway: Gateway) -> None:
    before = _session_ids(gateway)
    with openenv_websocket(gateway) as conversation:
        conversation.ask("reset", {"seed": 1})
        (session,) = _session_ids(gateway) - before
        assert gateway.request("DELETE", f"/v1/envs/{session}").status == 204
        lost = conversation.error("step", {"action": 1})
        assert lost["code"] == "SESSION_ERROR" and lost["problem"]["code"] == "environment_lost"
    assert_problem(gateway.request("GET", f"/v1/envs/{session}"), 404, "unknown_session")


def test_oversized_messages_are_refused_and_the_gateway_serves_on(gateway: Gateway) -> None:
    before = _session_ids(gateway)
    with openenv_websocket(gateway) as conversation:
        conversation.ask("reset", {"seed": 1})
        (session,) = _session_ids(gateway) - before
        conversation.websocket.send(json.dumps({"type": "step", "data": {"action": "x" * 5000}}))
        with pytest.raises(ConnectionClosed) as closed:
            conversation.websocket.recv(timeout=30)
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1009  # too big
    _wait_until_gone(gateway, session)
    large = gateway.request("POST", "/openenv/step", raw=b" " * 5000)
    assert_problem(large, 413, "payload_too_large")
    assert gateway.get("/openenv/health") == {"status": "healthy"}


def test_the_http_routes_drive_one_shared_session(gateway: Gateway) -> None:
    reset = gateway.post("/openenv/reset", {"seed": 3, "episode_id": "shared"})
    assert reset.keys() == {"observation", "reward", "done"} and reset["reward"] is None
    with openenv_websocket(gateway) as conversation:  # the same seed, the same first observation
        assert conversation.ask("reset", {"seed": 3})["data"] == reset
    step = gateway.post("/openenv/step", {"action": {"action": 1}, "request_id": "r1"})
    assert step["reward"] == 1.0 and step["done"] is False
    assert step["observation"]["metadata"]["info"] == {"frames": 1}
    state = gateway.get("/openenv/state")
    assert state["episode_id"] == "shared" and state["step_count"] == 1
    assert gateway.get("/v1/envs/openenv")["step"] == 1  # a session like any other
    for body, code, needle in (
        ({"action": 1}, "bad_request", "JSON object"),  # an Action is an object
        ({"action": {"action": 5}}, "invalid_action", "outside"),
        ({"action": {"action": 1}, "timeout_s": 3}, "bad_request", "'timeout_s'"),
        ({}, "bad_request", "'action'"),
    ):
        refused = gateway.request("POST", "/openenv/step", body)
        assert needle in assert_problem(refused, refused.status, code)["detail"]
    assert_problem(gateway.request("POST", "/openenv/step"), 400, "bad_request")  # no body
    assert_problem(gateway.request("POST", "/openenv/reset", {"bogus": 1}), 400, "bad_request")
    assert gateway.post("/openenv/reset")["done"] is False  # an empty body is ResetRequest()
    assert gateway.request("DELETE", "/v1/envs/openenv").status == 204
    fresh = gateway.get("/openenv/state")  # created afresh
    assert fresh["episode_id"] is None and fresh["step_count"] == 0


def test_several_agents_travel_keyed_by_agent() -> None:
    """rlenv/Pair-v0: actions and observations keyed by agent, each agent's outcome in info."""
    pair = Gateway(PAIR)
    expected_env = gym.make(PAIR)
    try:
        expected_env.action_space.seed(5)
        with openenv_websocket(pair) as conversation:
            data = conversation.ask("reset", {"seed": 5})["data"]
            expected, _ = expected_env.reset(seed=5)
            assert_same_observation(data["observation"]["observation"], expected)
            for _ in range(400):
                action = {
                    name: a.tolist() for name, a in expected_env.action_space.sample().items()
                }
                data = conversation.ask("step", {"action": action})["data"]
                expected, reward, terminated, truncated, info = expected_env.step(action)
                assert_same_observation(data["observation"]["observation"], expected)
                metadata = data["observation"]["metadata"]
                assert data["reward"] == reward and data["done"] == (terminated or truncated)
                assert (metadata["terminated"], metadata["truncated"]) == (terminated, truncated)
                assert metadata["info"]["agents"] == info["agents"]
                if data["done"]:
                    break
            assert data["done"]
    finally:
        expected_env.close()
        pair.close()


def test_websockets_count_against_their_clients_sessions() -> None:
    limited = Gateway(CARTPOLE, "--max-sessions-per-client", "1", "--idle-timeout", "120")
    try:
        with openenv_websocket(limited) as first:
            first.ask("reset", {"seed": 0})
            (session,) = _session_ids(limited)
            with openenv_websocket(limited) as second:
                try:
                    refused = json.loads(second.websocket.recv(timeout=60))
                except ConnectionClosed as closed_first:
                    # websockets 13.0's threading client (make test-lowest) may drop the message
                    # that arrives just before the close: the close still says why.
                    assert closed_first.rcvd is not None and closed_first.rcvd.code == 1013
                    assert "sessions per client" in closed_first.rcvd.reason
                else:
                    assert refused["type"] == "error"
                    assert refused["data"]["code"] == "CAPACITY_REACHED"
                    assert refused["data"]["problem"]["code"] == "session_limit"
                    with pytest.raises(ConnectionClosed) as closed:
                        second.websocket.recv(timeout=30)
                    assert closed.value.rcvd is not None and closed.value.rcvd.code == 1013
            assert first.ask("step", {"action": 1})["type"] == "observation"  # unaffected
        _wait_until_gone(limited, session)
        with openenv_websocket(limited) as third:  # the first's slot is free again
            assert third.ask("reset", {})["type"] == "observation"
    finally:
        limited.close()


def test_the_gateways_deadline_holds_and_the_other_websockets_go_on() -> None:
    slow = Gateway("examples.faulty:SlowEnvironment", "--timeout", "3")  # action 1 hangs
    try:
        with openenv_websocket(slow) as hung, openenv_websocket(slow) as fine:
            for conversation in (hung, fine):
                assert conversation.ask("reset", {"seed": 0})["type"] == "observation"
            started = time.monotonic()
            timed_out = hung.error("step", {"action": 1})
            assert time.monotonic() - started < 30
            assert timed_out["code"] == "SESSION_ERROR"
            assert timed_out["problem"]["code"] == "timeout"
            assert hung.error("step", {"action": 0})["problem"]["code"] == "timeout"  # over
            assert hung.ask("state")["data"]["status"] == "timed_out"
            step = fine.ask("step", {"action": 0})["data"]
            assert step["observation"]["observation"] == [1]
    finally:
        slow.close()


def test_a_session_that_cannot_be_made_is_a_factory_error(serve: Serve) -> None:
    server = serve()
    relay = Gateway(server.address)  # described at its start, then its server is gone
    try:
        server.close()
        with openenv_websocket(relay) as conversation:
            refused = json.loads(conversation.websocket.recv(timeout=60))["data"]
            assert refused["code"] == "FACTORY_ERROR"
            assert refused["problem"]["code"] == "environment_lost"
            with pytest.raises(ConnectionClosed) as closed:
                conversation.websocket.recv(timeout=30)
            assert closed.value.rcvd is not None and closed.value.rcvd.code == 1011
        assert relay.get("/v1/envs") == {"envs": []}
        assert relay.get("/openenv/health") == {"status": "healthy"}
    finally:
        relay.close()


def test_without_a_target_the_routes_say_so_and_the_token_guards_them() -> None:
    bare = Gateway("--host", "0.0.0.0", env={"RLENV_TOKEN": "s3cret"})
    try:
        bare.host = "127.0.0.1"
        token = {"Authorization": "Bearer s3cret"}
        with pytest.raises(InvalidStatus) as refused, openenv_websocket(bare):
            pass
        assert refused.value.response.status_code == 401
        with pytest.raises(InvalidStatus) as refused, openenv_websocket(bare, token):
            pass
        assert refused.value.response.status_code == 404
        assert b"TARGET" in refused.value.response.body
        for method, route in (("POST", "reset"), ("GET", "state"), ("GET", "schema")):
            answer = bare.request(method, f"/openenv/{route}", headers=token)
            assert "TARGET" in assert_problem(answer, 404, "not_found")["detail"]
        assert bare.request("GET", "/openenv/health", headers=token).json()["status"] == "healthy"
        assert_problem(bare.request("GET", "/openenv/health"), 401, "unauthorized")
    finally:
        bare.close()
