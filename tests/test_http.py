"""The HTTP gateway's routes, through a real ``rlenv http`` subprocess on port 0.

Sessions, spaces, frames, snapshots, bevy_rl's routes, the WebSocket, the event stream and
the OpenAPI document; the error statuses and the safety rules are in ``test_http_faults.py``.
"""

from __future__ import annotations

import base64
import http.client
import json
import re
import socket
import urllib.parse
from collections.abc import Iterator

import numpy as np
import pytest
from http_gateway import Gateway, assert_problem, decode_png
from openapi_spec_validator import validate
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from rlenv_client import LocalClient
from rlenv_tools._bench import ENDLESS
from rlenv_tools.http.json_spaces import space_from_json

CARTPOLE = "examples.cartpole:CartPoleEnvironment"


@pytest.fixture(scope="module")
def gateway() -> Iterator[Gateway]:
    """``rlenv http CARTPOLE --port 0``, shared by this module's tests (fresh sessions each)."""
    started = Gateway(CARTPOLE)
    yield started
    started.close()


def test_two_sessions_reset_with_one_seed_observe_the_same_and_are_isolated(
    gateway: Gateway,
) -> None:
    first, second = gateway.session(), gateway.session(CARTPOLE)
    one = gateway.post(f"/v1/envs/{first}/reset", {"seed": 3})
    other = gateway.post(f"/v1/envs/{second}/reset", {"seed": 3})
    assert one == other and len(one["observation"]) == 5
    with LocalClient(CARTPOLE) as local:  # the same episode as any other way of running it
        observation, _ = local.reset(seed=3)
        assert one["observation"] == observation.tolist()
    pushed = [gateway.post(f"/v1/envs/{first}/step", {"action": [0.2]}) for _ in range(3)]
    assert pushed[0]["observation"] != one["observation"]
    # the second session did not move: its first step is the first's first step
    assert gateway.post(f"/v1/envs/{second}/step", {"action": [0.2]}) == pushed[0]
    listed = {s["id"]: s for s in gateway.get("/v1/envs")["envs"]}
    assert listed[first]["step"] == 3 and listed[second]["step"] == 1
    assert listed[first]["status"] == listed[second]["status"] == "running"
    described = gateway.get(f"/v1/envs/{first}")
    assert described["episode"] == 1 and described["step"] == 3
    assert described["env_id"] == CARTPOLE and described["agents"] == ["Agent"]


def test_seed_zero_is_a_seed(gateway: Gateway) -> None:
    session = gateway.session()
    zero = [gateway.post(f"/v1/envs/{session}/reset", {"seed": 0}) for _ in range(2)]
    unseeded = gateway.post(f"/v1/envs/{session}/reset")
    assert zero[0] == zero[1] and unseeded != zero[0]


def test_a_step_runs_repeat_action_frames(gateway: Gateway) -> None:
    session = gateway.session()
    gateway.post(f"/v1/envs/{session}/reset", {"seed": 1})
    step = gateway.post(f"/v1/envs/{session}/step", {"action": [0.0], "repeat_action": 4})
    assert step["info"]["frames"] == 4 and step["reward"] == 4.0
    assert step["terminated"] is False and step["truncated"] is False
    default = gateway.post(f"/v1/envs/{session}/step", {"action": [0.0]})
    assert default["info"]["frames"] == 4  # CartPole's repeat_action


def test_kwargs_configure_the_session(gateway: Gateway) -> None:
    session = gateway.session(repeat_action=7)
    gateway.post(f"/v1/envs/{session}/reset", {"seed": 1})
    assert gateway.post(f"/v1/envs/{session}/step", {"action": [0.0]})["info"]["frames"] == 7
    refused = gateway.request("POST", "/v1/envs", {"kwargs": {"no_such_setting": 1}})
    assert "no_such_setting" in assert_problem(refused, 422, "invalid_config")["detail"]


def test_render_is_a_png_or_raw_bytes(gateway: Gateway) -> None:
    session = gateway.session()
    gateway.post(f"/v1/envs/{session}/reset", {"seed": 2})
    png = gateway.request("GET", f"/v1/envs/{session}/render")
    assert png.status == 200 and png.content_type == "image/png"
    pixels = decode_png(png.body)
    assert pixels.shape == (400, 600, 3) and pixels.std() > 0  # something is drawn
    raw = gateway.request(
        "GET", f"/v1/envs/{session}/render", headers={"Accept": "application/octet-stream"}
    )
    assert raw.content_type == "application/octet-stream"
    assert raw.headers["x-shape"] == "400,600,3" and raw.headers["x-dtype"] == "uint8"
    assert np.array_equal(np.frombuffer(raw.body, np.uint8).reshape(400, 600, 3), pixels)
    small = decode_png(gateway.request("GET", f"/v1/envs/{session}/render?width=60&height=40").body)
    assert small.shape == (40, 60, 3)
    assert_problem(gateway.request("GET", f"/v1/envs/{session}/render?width=0"), 400, "bad_request")


def test_spaces_come_with_their_json_schema(gateway: Gateway) -> None:
    import jsonschema

    created = gateway.request("POST", "/v1/envs", {"env_id": CARTPOLE})
    assert created.status == 201 and created.headers["location"].endswith(created.json()["id"])
    body = created.json()
    session = body["id"]
    action = gateway.get(f"/v1/envs/{session}/action_space")
    observation = gateway.get(f"/v1/envs/{session}/observation_space")
    assert (
        action["space"]
        == body["action_space"]
        == {"type": "Box", "shape": [1], "low": -1.0, "high": 1.0, "dtype": "float32"}
    )
    assert observation["space"] == body["observation_space"]
    action_space = space_from_json(action["space"])
    for _ in range(5):
        sample = gateway.post(f"/v1/envs/{session}/action_space/sample")["action"]
        assert action_space.contains(np.asarray(sample, np.float32))
        jsonschema.validate(sample, action["schema"])
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate([2.0], action["schema"])
    contains = f"/v1/envs/{session}/action_space/contains"
    assert gateway.post(contains, {"action": [0.5]}) == {"member": True}
    refused = gateway.post(contains, {"action": [2.0]})
    assert refused["member"] is False and "outside the bounds" in refused["reason"]
    jsonschema.validate(
        gateway.post(f"/v1/envs/{session}/reset")["observation"], observation["schema"]
    )


def test_several_agents_and_images(gateway: Gateway) -> None:
    import jsonschema

    pair = gateway.session("rlenv/Pair-v0")
    space = gateway.get(f"/v1/envs/{pair}/action_space")["space"]
    assert space["type"] == "Dict" and set(space["spaces"]) == {"Red", "Blue"}
    first = gateway.post(f"/v1/envs/{pair}/reset", {"seed": 0})["observation"]
    assert set(first) == {"Red", "Blue"} and len(first["Red"]) == 8
    step = gateway.post(
        f"/v1/envs/{pair}/step", {"action": {"Red": [1.0, 0.0], "Blue": [0.0, -1.0]}}
    )
    assert set(step["info"]["agents"]) == {"Red", "Blue"}
    assert_problem(
        gateway.request("POST", f"/v1/envs/{pair}/step", {"action": {"Red": [1.0, 0.0]}}),
        422,
        "invalid_action",
    )

    pixels = gateway.session("rlenv/Pixels-v0")
    schema = gateway.get(f"/v1/envs/{pixels}/observation_space")["schema"]
    assert schema["contentMediaType"] == "image/png"
    image = gateway.post(f"/v1/envs/{pixels}/reset", {"seed": 0})["observation"]
    jsonschema.validate(image, schema)
    screen = decode_png(base64.b64decode(image))
    with LocalClient("examples.pixels:PixelsEnvironment") as local:
        assert np.array_equal(screen, local.reset(seed=0)[0])


def test_a_registered_id_keeps_its_time_limit(gateway: Gateway) -> None:
    session = gateway.session("rlenv/CartPole-v0", **ENDLESS)
    assert gateway.get(f"/v1/envs/{session}")["max_episode_steps"] == 500
    gateway.post(f"/v1/envs/{session}/reset", {"seed": 0})
    steps = [gateway.post(f"/v1/envs/{session}/step", {"action": [0.0]}) for _ in range(500)]
    assert [s["truncated"] for s in steps] == [False] * 499 + [True]
    assert gateway.get(f"/v1/envs/{session}")["status"] == "ended"
    late = gateway.request("POST", f"/v1/envs/{session}/step", {"action": [0.0]})
    assert "time limit of 500 steps" in assert_problem(late, 409, "reset_required")["detail"]


def test_the_time_limit_truncates_every_agent_still_playing(gateway: Gateway) -> None:
    """Red catches its apple early, Blue stands still: at the limit, Blue is truncated too."""
    from examples.pair import chase

    session = gateway.session("rlenv/Pair-v0")
    observation = gateway.post(f"/v1/envs/{session}/reset", {"seed": 3})["observation"]
    for _ in range(300):
        red = chase(np.array(observation["Red"], np.float32)).tolist()
        step = gateway.post(
            f"/v1/envs/{session}/step", {"action": {"Red": red, "Blue": [0.0, 0.0]}}
        )
        observation = step["observation"]
        if step["terminated"] or step["truncated"]:
            break
    assert (step["terminated"], step["truncated"]) == (False, True)
    agents = step["info"]["agents"]
    assert (agents["Red"]["terminated"], agents["Red"]["truncated"]) == (True, False)
    assert (agents["Blue"]["terminated"], agents["Blue"]["truncated"]) == (False, True)


def test_snapshots_restore_in_another_session(gateway: Gateway) -> None:
    source, copy = gateway.session(), gateway.session()
    gateway.post(f"/v1/envs/{source}/reset", {"seed": 5})
    for action in ([0.5], [-0.25], [1.0]):
        gateway.post(f"/v1/envs/{source}/step", {"action": action})
    snapshot = gateway.get(f"/v1/envs/{source}/snapshot")["snapshot"]
    restored = gateway.post(f"/v1/envs/{copy}/restore", {"snapshot": snapshot})
    assert gateway.get(f"/v1/envs/{copy}")["step"] == 3
    after = [gateway.post(f"/v1/envs/{s}/step", {"action": [0.3]}) for s in (source, copy)]
    assert after[0] == after[1] and restored["observation"] != after[0]["observation"]
    broken = gateway.request("POST", f"/v1/envs/{copy}/restore", {"snapshot": {"version": 1}})
    assert_problem(broken, 400, "bad_request")


def test_delete_closes_a_session(gateway: Gateway) -> None:
    session = gateway.session()
    deleted = gateway.request("DELETE", f"/v1/envs/{session}")
    assert deleted.status == 204 and deleted.body == b""
    assert session not in {s["id"] for s in gateway.get("/v1/envs")["envs"]}
    assert_problem(gateway.request("GET", f"/v1/envs/{session}"), 404, "unknown_session")
    assert_problem(gateway.request("DELETE", f"/v1/envs/{session}"), 404, "unknown_session")


def test_versions_and_capabilities(gateway: Gateway) -> None:
    about = gateway.get("/v1")
    assert about["versions"] == ["v1"] and about["target"] == CARTPOLE
    assert about["env_ids"][0] == CARTPOLE and "rlenv/CartPole-v0" in about["env_ids"]
    assert about["capabilities"]["websocket"] and about["capabilities"]["bevy_rl"]
    assert about["hosting"] == "isolated" and about["token_required"] is False


def test_openapi_is_generated_from_the_routes(gateway: Gateway) -> None:
    reply = gateway.request("GET", "/openapi.json")
    assert reply.status == 200 and reply.content_type == "application/json"
    document = reply.json()
    validate(document)  # against the OpenAPI 3.1 schema
    assert document["openapi"] == "3.1.0"
    paths = document["paths"]
    expected = {
        "/v1/envs": {"get", "post"},
        "/v1/envs/{id}": {"get", "delete"},
        "/v1/envs/{id}/reset": {"post"},
        "/v1/envs/{id}/step": {"post"},
        "/v1/envs/{id}/render": {"get"},
        "/v1/envs/{id}/action_space": {"get"},
        "/v1/envs/{id}/observation_space": {"get"},
        "/v1/envs/{id}/action_space/sample": {"post"},
        "/v1/envs/{id}/action_space/contains": {"post"},
        "/v1/envs/{id}/snapshot": {"get"},
        "/v1/envs/{id}/restore": {"post"},
        "/v1/envs/{id}/ws": {"get"},
        "/v1/envs/{id}/events": {"get"},
        "/v1": {"get"},
        "/state": {"get"},
        "/visual_observations": {"get"},
        "/reset": {"get", "post"},
        "/step": {"get"},
        "/openenv/ws": {"get"},
        "/openenv/reset": {"post"},
        "/openenv/step": {"post"},
        "/openenv/state": {"get"},
        "/openenv/health": {"get"},
        "/openenv/schema": {"get"},
        "/openenv/metadata": {"get"},
        "/openapi.json": {"get"},
    }
    assert {path: set(item) for path, item in paths.items()} == expected
    step = paths["/v1/envs/{id}/step"]["post"]
    assert {"200", "400", "404", "409", "422", "502", "504"} <= set(step["responses"])
    problem = step["responses"]["422"]["content"]["application/problem+json"]["schema"]
    assert problem == {"$ref": "#/components/schemas/Problem"}
    schemas = document["components"]["schemas"]
    action_schema = gateway.get(f"/v1/envs/{gateway.session()}/action_space")["schema"]
    assert schemas["Action"] == action_schema  # the TARGET's space, not a hand-written copy


def test_bevy_rl_routes_in_bevy_rl_formats(gateway: Gateway) -> None:
    state = gateway.request("GET", "/state")  # creates and resets the "bevy" session
    assert state.status == 200 and len(state.json()) == 5
    assert gateway.get("/v1/envs/bevy")["status"] == "running"
    frame = gateway.request("GET", "/visual_observations")
    assert frame.content_type == "image/png" and decode_png(frame.body).shape == (400, 600, 3)
    for method in ("POST", "GET"):
        reset = gateway.request(method, "/reset")
        assert reset.status == 200 and reset.json() == [{"reward": 0.0, "is_terminated": False}]
    payload = urllib.parse.quote(json.dumps([{"action": json.dumps([0.5])}]))
    step = gateway.request("GET", f"/step?payload={payload}")
    assert step.status == 200 and step.content_type == "application/json"
    assert step.json() == [{"reward": 4.0, "is_terminated": False}]
    assert gateway.get("/state") != state.json()
    seeded = gateway.request("POST", "/reset?seed=3")
    assert (
        seeded.status == 200
        and gateway.get("/state")
        == gateway.post(f"/v1/envs/{gateway.session()}/reset", {"seed": 3})["observation"]
    )
    for bad in ("nope", urllib.parse.quote("[]"), urllib.parse.quote('[{"action": "[0.5"}]')):
        assert_problem(gateway.request("GET", f"/step?payload={bad}"), 400, "bad_request")
    assert_problem(gateway.request("GET", "/step"), 400, "bad_request")
    for beyond in ("10001", "1099511627776", "9" * 40):  # the hello's limits.max_repeat_action
        refused = gateway.request("GET", f"/step?payload={payload}&repeat_action={beyond}")
        assert "at most 10000" in assert_problem(refused, 400, "bad_request")["detail"]
    outside = urllib.parse.quote(json.dumps([{"action": "[7.0]"}]))
    assert_problem(gateway.request("GET", f"/step?payload={outside}"), 422, "invalid_action")
    for _ in range(500):  # pushed one way, the pole falls
        if (done := gateway.get(f"/step?payload={payload}"))[0]["is_terminated"]:
            break
    assert done[0]["is_terminated"]
    assert_problem(gateway.request("GET", f"/step?payload={payload}"), 409, "reset_required")


def test_bevy_rl_routes_with_several_agents() -> None:
    pair = Gateway("examples.pair:PairEnvironment")
    try:
        assert set(pair.get("/state")) == {"Red", "Blue"}
        payload = urllib.parse.quote(
            json.dumps([{"action": "[1.0, 0.0]"}, {"action": "[0.0, 1.0]"}])
        )
        states = pair.get(f"/step?payload={payload}")
        assert len(states) == 2 and all(set(s) == {"reward", "is_terminated"} for s in states)
        one = urllib.parse.quote(json.dumps([{"action": "[1.0, 0.0]"}]))
        assert_problem(pair.request("GET", f"/step?payload={one}"), 400, "bad_request")
    finally:
        pair.close()


def test_bevy_rl_routes_need_a_target() -> None:
    bare = Gateway()
    try:
        assert_problem(bare.request("GET", "/state"), 404, "not_found")
        assert bare.get("/v1")["target"] is None
        assert_problem(bare.request("POST", "/v1/envs", {}), 400, "bad_request")
        assert bare.session("rlenv/CartPole-v0")
    finally:
        bare.close()


def test_the_websocket_carries_typed_messages(gateway: Gateway) -> None:
    session = gateway.session()
    with connect(f"ws://{gateway.host}:{gateway.port}/v1/envs/{session}/ws") as websocket:
        websocket.send(json.dumps({"type": "reset", "seed": 3}))
        reset = json.loads(websocket.recv(timeout=10))
        assert reset["type"] == "reset" and len(reset["observation"]) == 5
        websocket.send(json.dumps({"type": "step", "action": [0.5], "repeat_action": 2}))
        step = json.loads(websocket.recv(timeout=10))
        assert step["type"] == "step" and step["info"]["frames"] == 2
        for bad, status in (
            ("not json", 400),
            (json.dumps({"type": "jump"}), 400),
            (json.dumps({"type": "step", "action": [float("nan")]}), 400),
            (json.dumps({"type": "step", "action": [9.0]}), 422),
        ):
            websocket.send(bad)
            error = json.loads(websocket.recv(timeout=10))
            assert error["type"] == "error" and error["problem"]["status"] == status
        websocket.send(json.dumps({"type": "step", "action": [0.5]}))  # it goes on
        assert json.loads(websocket.recv(timeout=10))["type"] == "step"
        websocket.send(json.dumps({"type": "step", "action": [0.5]}).encode())  # binary
        assert json.loads(websocket.recv(timeout=10))["info"]["frames"] == 4
        websocket.send(json.dumps({"type": "close"}))
        assert json.loads(websocket.recv(timeout=10)) == {"type": "close"}
    assert gateway.get(f"/v1/envs/{session}")["step"] == 3  # the session stays
    with pytest.raises(InvalidStatus) as refused:
        connect(f"ws://{gateway.host}:{gateway.port}/v1/envs/nope/ws").close()
    assert refused.value.response.status_code == 404


def test_watchers_follow_a_session_as_server_sent_events(gateway: Gateway) -> None:
    session = gateway.session()
    stream = http.client.HTTPConnection(gateway.host, gateway.port, timeout=30)
    stream.request("GET", f"/v1/envs/{session}/events")
    answer = stream.getresponse()
    assert answer.status == 200
    assert answer.getheader("content-type").startswith("text/event-stream")
    assert answer.readline().startswith(b": ")  # the first comment: the stream is open
    answer.readline()
    gateway.post(f"/v1/envs/{session}/reset", {"seed": 1})
    gateway.post(f"/v1/envs/{session}/step", {"action": [0.0]})
    gateway.post(f"/v1/envs/{session}/step", {"action": [0.0]})
    events = [_event(answer) for _ in range(3)]
    assert [(e["id"], e["event"]) for e in events] == [("0", "reset"), ("1", "step"), ("2", "step")]
    data = json.loads(events[2]["data"])
    assert data["episode"] == 1 and data["step"] == 2 and data["info"]["frames"] == 4
    assert gateway.request("DELETE", f"/v1/envs/{session}").status == 204
    assert answer.read() == b""  # the stream ends with the session
    stream.close()
    assert_problem(gateway.request("GET", "/v1/envs/nope/events"), 404, "unknown_session")


def _event(answer: http.client.HTTPResponse) -> dict[str, str]:
    fields = {}
    while (line := answer.readline().decode().rstrip("\n")) or not fields:
        if line and not line.startswith(":"):
            name, _, value = line.partition(": ")
            fields[name] = value
    return fields


def test_sigterm_ends_it_with_streams_open() -> None:
    started = Gateway(CARTPOLE)
    session = started.session()
    stream = http.client.HTTPConnection(started.host, started.port, timeout=30)
    stream.request("GET", f"/v1/envs/{session}/events")
    stream.getresponse()
    with connect(f"ws://{started.host}:{started.port}/v1/envs/{session}/ws") as websocket:
        websocket.send(json.dumps({"type": "reset"}))
        websocket.recv(timeout=10)
        try:
            assert started.close() < 10  # raises past 10 s
            assert started.process.returncode is not None
        finally:
            stream.close()


def test_an_answer_leaves_in_one_write(gateway: Gateway) -> None:
    """Head and body in one segment: the first read of a kept-alive connection has it all."""
    session = gateway.session(**ENDLESS)
    gateway.post(f"/v1/envs/{session}/reset")
    body = json.dumps({"action": [0.0]}).encode()
    request = (
        f"POST /v1/envs/{session}/step HTTP/1.1\r\nHost: {gateway.host}:{gateway.port}"
        f"\r\nContent-Length: {len(body)}\r\n\r\n"
    ).encode() + body
    with socket.create_connection((gateway.host, gateway.port), timeout=30) as connection:
        connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        for _ in range(30):
            connection.sendall(request)
            answer = connection.recv(65536)
            head, _, rest = answer.partition(b"\r\n\r\n")
            length = int(re.search(rb"content-length: (\d+)", head.lower()).group(1))
            assert head.startswith(b"HTTP/1.1 200") and len(rest) == length, answer


def test_the_command_says_where_it_listens() -> None:
    started = Gateway(CARTPOLE)
    try:
        assert re.fullmatch(r"http://127\.0\.0\.1:\d+", started.url)
    finally:
        started.close()
