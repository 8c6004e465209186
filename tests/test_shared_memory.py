"""The shared-memory lane: its slots (sans-IO), and real servers stepped through it.

A lane changes how steps travel, never what they say: every test on real servers compares a
client with a lane against one without, or checks the error the socket would have carried.
"""

from __future__ import annotations

import mmap
import os
import signal
import socket
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from conftest import Serve, wait_until
from gymnasium import spaces

from examples.cartpole import TARGET
from rlenv.protocol import Hello, Request, Response, StepsResponse
from rlenv.protocol.errors import ConnectionLost, RemoteError, RequestTimeout
from rlenv.protocol.shared_memory import STEP, STEPS, Layout, Slots, lane_unavailable
from rlenv.transport.lanes import listen_for_lane
from rlenv_client import Client, RemoteVectorEnv

pytestmark = pytest.mark.skipif(
    lane_unavailable(Hello("x", spaces.Box(0, 1, (1,)), spaces.Box(0, 1, (1,)))) is not None,
    reason="no shared-memory lanes on this platform",
)

BOX = spaces.Box(-1.0, 1.0, (3,), np.float32)
ENDLESS = {"world": {"track_limit": 1e9}, "agent": {"angle_limit": 1e9}}
FAULTY = "examples.faulty:{}"


def slots_for(action: spaces.Space, observation: spaces.Space = BOX, instances: int = 4) -> Slots:
    hello = Hello("Test", action, observation, instances=instances)
    layout = Layout.for_hello(hello)
    return Slots(mmap.mmap(-1, layout.size), layout, hello)


# --- the slots, sans-IO -----------------------------------------------------------------------


def test_the_layout_puts_every_region_on_8_bytes_and_in_order() -> None:
    layout = Layout.for_hello(
        Hello(
            "T",
            spaces.Box(0, 1, (3,), np.float32),
            spaces.Box(0, 255, (5, 7), np.uint8),
            instances=3,
        )
    )
    wire = layout.to_wire()
    order = ["actions", "reset", "observation", "reward", "frames", "terminated", "truncated"]
    offsets = [wire[name] for name in order]
    assert offsets == sorted(offsets) and all(offset % 8 == 0 for offset in offsets[:5])
    assert wire["action_size"] == 12 and wire["observation_size"] == 35
    assert wire["reset"] >= wire["actions"] + 3 * 12
    assert wire["reward"] >= wire["observation"] + 3 * 35
    assert wire["size"] % 64 == 0 and wire["size"] >= wire["truncated"] + 3


@pytest.mark.parametrize(
    ("hello", "why"),
    [
        (Hello("T", BOX, spaces.Dict({"a": BOX})), "observation space (Dict) has no fixed-size"),
        (Hello("T", spaces.Tuple([BOX]), BOX), "action space (Tuple) has no fixed-size"),
        (Hello("T", BOX, spaces.Discrete(3)), "observation space (Discrete) has no fixed-size"),
        (Hello("T", BOX, BOX, agents=("a", "b")), "has 2 agents"),
    ],
)
def test_a_lane_says_why_it_cannot_carry_a_server(hello: Hello, why: str) -> None:
    assert why in (lane_unavailable(hello) or "")
    with pytest.raises(ValueError, match=why.replace("(", r"\(").replace(")", r"\)")):
        Layout.for_hello(hello)


@pytest.mark.parametrize(
    "request_",
    [
        Request(
            7, {"action": np.arange(3, dtype=np.float32).tobytes(), "observation": {"agent": {}}}
        ),
        Request(
            8,
            {
                "action": np.ones(3, np.float32).tobytes(),
                "observation": {"agent": {}},
                "repeat_action": 9,
            },
        ),
        Request(
            9,
            {
                "steps": {
                    "action": np.arange(12, dtype=np.float32).tobytes(),
                    "reset": bytes([0, 1, 0, 1]),
                }
            },
        ),
        Request(
            10,
            {
                "steps": {
                    "action": np.zeros(12, np.float32).tobytes(),
                    "reset": bytes(4),
                    "repeat_action": 2,
                }
            },
        ),
    ],
    ids=["step", "step-repeat", "steps", "steps-repeat"],
)
def test_a_request_that_fits_reads_back_as_it_was_written(request_: Request) -> None:
    slots = slots_for(BOX)
    before = slots.request_sequence
    kind = slots.write_request(request_)
    assert kind == (STEPS if "steps" in request_.parts else STEP)
    assert slots.request_sequence == before + 1
    assert slots.read_request() == request_


def test_a_steps_request_without_reset_flags_reads_back_with_none_set() -> None:
    slots = slots_for(BOX)
    action = np.ones(12, np.float32).tobytes()
    assert slots.write_request(Request(3, {"steps": {"action": action}})) == STEPS
    assert slots.read_request() == Request(3, {"steps": {"action": action, "reset": bytes(4)}})


@pytest.mark.parametrize(
    ("reset", "repeat"),
    [(np.array([False, True, False, True]), None), (None, 2)],
    ids=["reset-flags", "repeat"],
)
def test_steps_written_as_columns_read_back_as_the_request_they_stand_for(
    reset: np.ndarray | None, repeat: int | None
) -> None:
    slots = slots_for(BOX)
    action = np.arange(12, dtype=np.float32).reshape(4, 3)
    assert slots.write_steps(5, action, reset, repeat) and slots.request_sequence == 1
    steps = {
        "action": action.tobytes(),
        "reset": bytes(4) if reset is None else reset.astype(np.uint8).tobytes(),
    }
    if repeat is not None:
        steps["repeat_action"] = repeat
    assert slots.read_request() == Request(5, {"steps": steps})


@pytest.mark.parametrize(
    ("action", "reset", "repeat"),
    [
        (np.zeros((4, 3), np.float64), None, None),
        (np.zeros((3, 3), np.float32), None, None),
        (np.zeros(12, np.float32), None, None),
        (np.zeros((4, 3), np.float32).tolist(), None, None),
        (np.zeros((4, 3), np.float32), np.zeros(4, np.uint8), None),
        (np.zeros((4, 3), np.float32), [False] * 4, None),
        (np.zeros((4, 3), np.float32), None, 0),
    ],
    ids=["dtype", "count", "flat", "list", "uint8-flags", "list-flags", "repeat-0"],
)
def test_columns_that_do_not_fit_are_left_to_write_request(
    action: object, reset: object, repeat: int | None
) -> None:
    slots = slots_for(BOX)
    assert not slots.write_steps(5, action, reset, repeat)
    assert slots.request_sequence == 0  # nothing written


@pytest.mark.parametrize(
    ("space", "action", "repeat"),
    [
        (BOX, np.array([0.5, -0.25, 1.0], np.float32), None),
        (BOX, np.array([0.5, -0.25, 1.0], np.float32), 3),
        (spaces.Discrete(5, start=-2), -2, None),
        (spaces.Discrete(5, start=-2), np.int64(2), 4),
        (spaces.Discrete(3, dtype=np.int8), np.int8(1), None),
    ],
    ids=["box", "box-repeat", "discrete-int", "discrete-numpy", "discrete-int8"],
)
def test_a_step_written_in_place_is_the_request_write_request_writes(
    space: spaces.Space, action: object, repeat: int | None
) -> None:
    in_place, by_request = slots_for(space), slots_for(space)
    assert in_place.write_step(7, action, repeat)
    parts = {
        "action": int(action) if isinstance(space, spaces.Discrete) else action.tobytes(),
        "observation": {"agent": {}},
    }
    if repeat is not None:
        parts["repeat_action"] = repeat
    assert by_request.write_request(Request(7, parts)) == STEP
    assert bytes(in_place._buffer) == bytes(by_request._buffer)  # the same block, to the byte
    assert in_place.read_request() == Request(7, parts)


@pytest.mark.parametrize(
    ("space", "action", "repeat"),
    [
        (BOX, np.zeros(3, np.float64), None),
        (BOX, np.zeros((1, 3), np.float32), None),
        (BOX, [0.0, 0.0, 0.0], None),
        (BOX, np.zeros(3, np.float32), 0),
        (BOX, None, None),
        (spaces.Discrete(3), 3, None),
        (spaces.Discrete(3), True, None),
        (spaces.Discrete(3), 1.0, None),
    ],
    ids=["dtype", "shape", "list", "repeat-0", "none", "out-of-range", "bool", "float"],
)
def test_a_step_that_does_not_fit_is_left_to_write_request(
    space: spaces.Space, action: object, repeat: int | None
) -> None:
    slots = slots_for(space)
    assert not slots.write_step(7, action, repeat)
    assert slots.request_sequence == 0 and not any(bytes(slots._buffer))


def test_a_discrete_action_travels_as_its_dtype() -> None:
    slots = slots_for(spaces.Discrete(5, start=-2))
    request = Request(4, {"action": -2, "observation": {"agent": {}}})
    assert slots.write_request(request) == STEP
    assert slots.read_request() == request
    batch = np.array([2, -1, 0, 1], np.int64).tobytes()
    assert slots.write_request(Request(5, {"steps": {"action": batch}})) == STEPS
    assert slots.read_request().parts["steps"]["action"] == batch


@pytest.mark.parametrize(
    "request_",
    [
        Request(
            1,
            {"action": np.zeros(3, np.float32).tobytes(), "observation": {"agent": {}}},
            token="secret",
        ),
        Request(
            1,
            {
                "action": np.zeros(3, np.float32).tobytes(),
                "observation": {"agent": {}, "world": {}},
            },
        ),
        Request(1, {"action": np.zeros(3, np.float32).tobytes()}),
        Request(1, {"action": np.zeros(2, np.float32).tobytes(), "observation": {"agent": {}}}),
        Request(1, {"action": [0.0, 0.0, 0.0], "observation": {"agent": {}}}),
        Request(
            1,
            {
                "action": np.zeros(3, np.float32).tobytes(),
                "observation": {"agent": {}},
                "repeat_action": 0,
            },
        ),
        Request(
            1,
            {
                "action": np.zeros(3, np.float32).tobytes(),
                "observation": {"agent": {}},
                "reset": {},
            },
        ),
        Request(1, {"steps": {"action": np.zeros(12, np.float32).tobytes(), "reset": [True] * 4}}),
        Request(1, {"steps": {"action": np.zeros(12, np.float32).tobytes(), "extra": 1}}),
        Request(1, {"steps": {"action": np.zeros(12, np.float32).tobytes(), "repeat_action": 1.5}}),
        Request(1, {"steps": {"action": np.zeros(9, np.float32).tobytes()}}),
        Request(1, {"reset": {"seed": 0}, "observation": {"agent": {}}}),
    ],
    ids=[
        "token",
        "world",
        "no-observation",
        "short-action",
        "list-action",
        "repeat-0",
        "with-reset",
        "reset-list",
        "steps-extra-key",
        "steps-repeat-float",
        "steps-short",
        "reset",
    ],
)
def test_anything_else_stays_for_the_socket(request_: Request) -> None:
    slots = slots_for(BOX)
    before = slots.request_sequence
    assert slots.write_request(request_) == 0
    assert slots.request_sequence == before


def test_an_out_of_range_discrete_action_stays_for_the_socket() -> None:
    slots = slots_for(spaces.Discrete(3))
    assert slots.write_request(Request(1, {"action": 3, "observation": {"agent": {}}})) == 0
    assert slots.write_request(Request(1, {"action": True, "observation": {"agent": {}}})) == 0


def test_answers_that_fit_read_back_as_they_were_written() -> None:
    slots = slots_for(BOX)
    observation = np.array([0.5, -1.0, 2.0], np.float32).tobytes()
    response = Response(11, {"agent": observation}, 2.5, True, False, {}, 3)
    assert slots.write_answer(response, STEP) and slots.answer_sequence == 1
    assert slots.read_answer(STEP) == response
    column = np.arange(12, dtype=np.float32).tobytes()
    steps = StepsResponse(
        12,
        column,
        np.array([1.0, 2.0, 0.0, -1.0]),
        np.array([True, False, False, True]),
        np.array([False, True, False, False]),
        np.array([4, 4, 1, 2]),
        ({},) * 4,
    )
    assert slots.write_answer(steps, STEPS) and slots.answer_sequence == 2
    back = slots.read_answer(STEPS)
    assert back.id == 12 and back.observation == column and back.info == steps.info
    assert back.errors is None
    for name in ("reward", "terminated", "truncated", "frames"):
        assert np.array_equal(getattr(back, name), getattr(steps, name))
        assert getattr(back, name).dtype == getattr(steps, name).dtype or name == "frames"


def test_a_steps_answer_read_without_copy_is_read_only_views_of_the_slots() -> None:
    slots = slots_for(BOX)
    for answer_id in (1, 2):  # the views show the answer written last
        column = np.arange(12, dtype=np.float32) * answer_id
        steps = StepsResponse(
            answer_id,
            column.tobytes(),
            np.array([1.0, 2.0, 0.0, -1.0]) * answer_id,
            np.array([True, False, False, answer_id == 2]),
            np.array([False, True, False, False]),
            np.array([4, 4, 1, answer_id]),
            ({},) * 4,
        )
        assert slots.write_answer(steps, STEPS)
        if answer_id == 1:
            views = slots.read_answer(STEPS, copy=False)
            copies = slots.read_answer(STEPS)
        assert np.array_equal(views.observation, column.reshape(4, 3))
        for name in ("reward", "terminated", "truncated", "frames"):
            assert np.array_equal(getattr(views, name), getattr(steps, name))
            assert getattr(views, name).dtype == getattr(copies, name).dtype
    assert views.id == 1 and views.info == steps.info and views.errors is None
    assert copies.observation == (np.arange(12, dtype=np.float32)).tobytes()  # its own copy
    for array in (views.observation, views.reward, views.terminated, views.truncated, views.frames):
        assert not array.flags.writeable


@pytest.mark.parametrize(
    ("reply", "kind"),
    [
        (Response(1, {"agent": bytes(12)}, info={"late": True}), STEP),
        (Response(1, {"agent": bytes(12), "world": {}}), STEP),
        (Response(1, {"agent": bytes(8)}), STEP),
        (Response(1, None), STEP),
        (
            StepsResponse(
                1,
                bytes(48),
                np.zeros(4),
                np.zeros(4, bool),
                np.zeros(4, bool),
                np.zeros(4, np.int64),
                ({}, {"x": 1}, {}, {}),
            ),
            STEPS,
        ),
        (
            StepsResponse(
                1,
                bytes(48),
                np.zeros(4),
                np.zeros(4, bool),
                np.zeros(4, bool),
                np.zeros(4, np.int64),
                ({},) * 4,
                (None, None, None, None),
            ),
            STEPS,
        ),
        (Response(1, {"agent": bytes(12)}), STEPS),
    ],
    ids=["info", "world", "short", "no-observation", "steps-info", "steps-errors", "kind"],
)
def test_answers_that_do_not_fit_leave_the_slots_alone(reply: object, kind: int) -> None:
    slots = slots_for(BOX)
    assert not slots.write_answer(reply, kind)  # type: ignore[arg-type]
    assert slots.answer_sequence == 0


# --- real servers -----------------------------------------------------------------------------


def episodes(client: Client, seed: int, actions: list[float]) -> list[tuple]:
    """Resets and steps, each result as plain values (episodes end and start again)."""
    client.configure(world={"track_limit": 0.5})
    results: list[tuple] = []
    observation, _ = client.reset(seed=seed)
    results.append(("reset", observation.tobytes()))
    for action in actions:
        observation, reward, terminated, truncated, info = client.step(
            np.array([action], np.float32), repeat_action=3
        )
        results.append((observation.tobytes(), reward, terminated, truncated, info))
        if terminated or truncated:
            observation, _ = client.reset()
            results.append(("reset", observation.tobytes()))
    return results


def test_steps_through_a_lane_are_those_through_the_socket(serve: Serve) -> None:
    actions = list(np.random.default_rng(3).uniform(-1, 1, 120))
    server = serve()
    with Client(server.host, server.port, shared_memory=True) as lane:
        assert lane.shared_memory
        through_lane = episodes(lane, 5, actions)
    with Client(server.host, server.port, shared_memory=False) as plain:
        assert not plain.shared_memory
        through_socket = episodes(plain, 5, actions)
    assert through_lane == through_socket
    assert sum(1 for result in through_lane if result[0] == "reset") > 2  # episodes ended


def steps_of(client: Client, seed: int, rounds: int, copy: bool = True) -> list[tuple]:
    count = client.hello.instances
    client.send_batch([client.reset_request(seed + i) for i in range(count)])
    client.receive_batch()
    rng = np.random.default_rng(seed)
    resetting = np.zeros(count, bool)
    results = []
    for _ in range(rounds):
        client.send_steps(rng.uniform(-1, 1, (count, 1)).astype(np.float32), resetting, 2)
        answer = client.receive_steps(copy=copy)
        results.append(
            (
                answer.observation.tobytes(),
                answer.reward.tolist(),
                answer.terminated.tolist(),
                answer.truncated.tolist(),
                answer.frames.tolist(),
                answer.info,
            )
        )
        resetting = answer.terminated | answer.truncated
    return results


def test_steps_of_many_instances_through_a_lane_are_those_through_the_socket(serve: Serve) -> None:
    server = serve(args=["--instances", "5"])
    with Client(server.host, server.port, shared_memory=True) as lane:
        through_lane = steps_of(lane, 11, 150)
        in_place = steps_of(lane, 11, 150, copy=False)  # the slots' views, read at once
    with Client(server.host, server.port, shared_memory=False) as plain:
        through_socket = steps_of(plain, 11, 150)
    assert through_lane == in_place == through_socket
    assert any(any(row[2]) for row in through_lane)  # some episodes ended and reset


def test_a_discrete_environment_steps_through_a_lane(serve: Serve) -> None:
    server = serve("examples.classic_cartpole:ClassicCartPoleEnvironment")
    results = []
    for shared_memory in (True, False):
        with Client(server.host, server.port, shared_memory=shared_memory) as client:
            assert client.shared_memory is shared_memory
            client.reset(seed=1)
            results.append([client.step(i % 2)[:4] for i in range(20)])
    assert str(results[0]) == str(results[1])


def test_discrete_steps_of_many_instances_go_through_the_slots_as_through_the_socket(
    serve: Serve,
) -> None:
    """K Discrete actions (int64, as gymnasium batches them) are written into the slots as
    they are; the episodes are those stepped on the socket."""
    server = serve(
        "examples.classic_cartpole:ClassicCartPoleEnvironment", args=["--instances", "3"]
    )
    results = []
    for shared_memory in (True, False):
        with Client(server.host, server.port, shared_memory=shared_memory) as client:
            client.send_batch([client.reset_request(seed) for seed in range(3)])
            client.receive_batch()
            resetting, seen = np.zeros(3, bool), []
            for step in range(60):
                client.send_steps(np.array([step % 2, 1, 0], np.int64), resetting)
                answer = client.receive_steps(copy=False)
                seen.append(
                    (
                        answer.observation.tobytes(),
                        answer.reward.tolist(),
                        answer.terminated.tolist(),
                        answer.frames.tolist(),
                    )
                )
                resetting = answer.terminated | answer.truncated
            results.append(seen)
    assert results[0] == results[1]
    assert any(any(row[2]) for row in results[0])  # some episodes ended and reset


def test_views_of_an_answer_outlive_their_client(serve: Serve) -> None:
    """Closing a client whose answer's views are still held neither fails nor unmaps them."""
    server = serve()
    with Client(server.host, server.port, shared_memory=True) as client:
        client.send_batch([client.reset_request(0)])
        client.receive_batch()
        client.send_steps(np.zeros((1, 1), np.float32))
        answer = client.receive_steps(copy=False)
        kept = answer.observation.copy()
    assert client.closed
    assert np.array_equal(answer.observation, kept) and answer.frames.tolist() == [4]


def faulty_session(client: Client) -> list[object]:
    """A refusal, a failure and steps, as results or errors (code and message)."""
    outcomes: list[object] = []
    for call in (
        lambda: client.step(0),
        lambda: client.reset(seed=0),
        lambda: client.step(7),
        lambda: client.step(2),
        lambda: client.reset(seed=0),
        lambda: client.step(0),
        lambda: client.step(1),
        lambda: client.reset(seed=0),
        lambda: client.step(0),
    ):
        try:
            outcomes.append(str(call()))
        except RemoteError as error:
            outcomes.append((error.code, str(error)))
    return outcomes


def test_refusals_and_failures_come_as_they_would_on_the_socket(serve: Serve) -> None:
    server, other = (
        serve(FAULTY.format("FaultyEnvironment")),
        serve(FAULTY.format("FaultyEnvironment")),
    )
    with Client(server.host, server.port, shared_memory=True) as client:
        through_lane = faulty_session(client)
        assert client.shared_memory  # the lane stays
    with Client(other.host, other.port, shared_memory=False) as client:
        assert faulty_session(client) == through_lane
    codes = [outcome[0] for outcome in through_lane if isinstance(outcome, tuple)]
    assert codes == ["reset_required", "invalid_action", "environment_error", "environment_error"]


def test_an_answer_with_an_info_comes_on_the_socket(serve: Serve) -> None:
    server = serve(FAULTY.format("UnsendableEnvironment"))
    with Client(server.host, server.port, shared_memory=True) as client:
        client.reset(seed=0)
        frames = client.step(0)[-1]["frames"]  # through the slots
        with pytest.raises(RemoteError, match="environment_error.*could not be sent"):
            client.step(1)
        client.reset(seed=0)
        assert client.step(0)[0].tolist() == [frames]


def test_a_server_that_dies_mid_step_is_lost_at_once(serve: Serve) -> None:
    server = serve(FAULTY.format("DyingEnvironment"))
    with Client(server.host, server.port, shared_memory=True, timeout=60) as client:
        client.reset(seed=0)
        with pytest.raises(ConnectionLost, match="closed the connection"):
            client.step(1)  # its process ends inside the tick
        assert client.closed


def test_a_hung_server_times_out_on_the_lane(serve: Serve) -> None:
    server = serve(FAULTY.format("SlowEnvironment"))
    with Client(server.host, server.port, shared_memory=True, timeout=3.0) as client:
        client.reset(seed=0)  # under the same timeout: a margin for a loaded machine
        with pytest.raises(RequestTimeout, match="did not answer within 3.0s"):
            client.step(1)
        assert client.closed


_KILLED_CLIENT = textwrap.dedent("""
    import sys
    import numpy as np
    from rlenv_client import Client
    client = Client("127.0.0.1", int(sys.argv[1]), shared_memory=True)
    client.reset(seed=0)
    client.step(np.zeros(1, np.float32))
    print("stepping", flush=True)
    while True:
        client.step(np.zeros(1, np.float32))
        client.reset(seed=0)
""")


def test_a_client_killed_mid_lane_leaves_the_server_serving(serve: Serve) -> None:
    server = serve()
    process = subprocess.Popen(
        [sys.executable, "-c", _KILLED_CLIENT, str(server.port)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert process.stdout is not None
        assert process.stdout.readline() == "stepping\n"
        process.send_signal(signal.SIGKILL)
        process.wait(10)
    finally:
        process.kill()
        process.wait()
        if process.stdout is not None:
            process.stdout.close()
    with Client(server.host, server.port, shared_memory=True) as client:
        wait_until(lambda: _takes_control(client), "the dead client's control was never freed")
        assert client.step(np.zeros(1, np.float32))[-1]["frames"] == 4


def _takes_control(client: Client) -> bool:
    try:
        client.reset(seed=0)
    except RemoteError as error:
        assert error.code == "busy"
        return False
    return True


def test_an_interrupted_wait_drops_its_answer_and_keeps_order(serve: Serve) -> None:
    server = serve()
    with Client(server.host, server.port, shared_memory=True) as client:
        client.configure(**ENDLESS)
        client.reset(seed=0)
        client.send_step(np.ones(1, np.float32))  # its caller gives up on it (as on Ctrl-C)
        observation, *_ = client.reset(seed=0)  # waits for the step's answer first, drops it
        second = client.step(np.zeros(1, np.float32))
    with Client(server.host, server.port, shared_memory=False) as plain:
        assert np.array_equal(plain.reset(seed=0)[0], observation)
        assert np.array_equal(plain.step(np.zeros(1, np.float32))[0], second[0])


def test_rlenv_shared_memory_0_keeps_steps_on_the_socket(
    serve: Serve, monkeypatch: pytest.MonkeyPatch
) -> None:
    server = serve()
    monkeypatch.setenv("RLENV_SHARED_MEMORY", "0")
    with Client(server.host, server.port) as client:
        assert not client.shared_memory
    with Client(server.host, server.port, shared_memory=True) as client:
        assert client.shared_memory  # asked for explicitly


def test_a_vector_steps_through_lanes_and_survives_a_lost_server() -> None:
    with RemoteVectorEnv(4, TARGET, instances_per_server=2) as envs:
        assert all(client.shared_memory for client in envs.clients)  # type: ignore[attr-defined]
        envs.reset(seed=0)
        envs.step(np.zeros((4, 1), np.float32))
        envs.servers[0].process.send_signal(signal.SIGKILL)
        envs.servers[0].process.wait(10)
        _, _, _, truncated, infos = envs.step(np.zeros((4, 1), np.float32))
        assert truncated[:2].all() and "server_restarted" in infos
        assert all(client.shared_memory for client in envs.clients)  # type: ignore[attr-defined]
        envs.step(np.zeros((4, 1), np.float32))


# --- what the server refuses ------------------------------------------------------------------


def ask(port: int, parts: dict) -> object:
    with Client("127.0.0.1", port, shared_memory=False) as client:
        client.send_request(Request(0, parts))
        return client.receive_reply()


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ({"address": "/run/docker.sock", "key": bytes(16)}, "must be 'rlenv-lane-'"),
        ({"address": "rlenv-lane-" + "0" * 32, "key": b"short"}, "must be 16 bytes"),
        ({"address": "rlenv-lane-" + "0" * 32, "key": bytes(16)}, "cannot be reached"),
        ([], "must be a map"),
    ],
)
def test_the_server_refuses_a_lane_it_cannot_open(
    serve: Serve, value: object, message: str
) -> None:
    server = serve()
    reply = ask(server.port, {"shared_memory": value})
    assert reply.code == "bad_request" and message in reply.message  # type: ignore[attr-defined]


def test_a_lane_goes_alone_in_a_request(serve: Serve) -> None:
    server = serve()
    listener, name, key = listen_for_lane()
    with listener:
        reply = ask(server.port, {"shared_memory": {"address": name, "key": key}, "reset": {}})
    assert reply.code == "bad_request"  # type: ignore[attr-defined]
    assert "goes alone" in reply.message  # type: ignore[attr-defined]


def _other_address() -> str | None:
    """An address of this machine that is not loopback, if it has one."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        probe.connect(("192.0.2.1", 9))  # no packet is sent
        address = probe.getsockname()[0]
    except OSError:
        return None
    finally:
        probe.close()
    return None if address.startswith("127.") else address


def test_a_client_from_another_address_gets_no_lane(serve: Serve) -> None:
    address = _other_address()
    if address is None:
        pytest.skip("this machine has no address but loopback")
    server = serve(host=address, args=["--token", "t"])
    with Client(address, server.port, token="t") as client:
        assert not client.shared_memory  # the client does not even ask
        listener, name, key = listen_for_lane()
        with listener:
            client.send_request(Request(0, {"shared_memory": {"address": name, "key": key}}))
            reply = client.receive_reply()
    assert reply.code == "bad_request"  # type: ignore[attr-defined]
    assert f"this one is at {address}" in reply.message  # type: ignore[attr-defined]
    with pytest.raises(ValueError, match="not on this machine"):
        Client(address, server.port, token="t", shared_memory=True)


def test_no_file_is_left_in_dev_shm(serve: Serve) -> None:
    before = set(os.listdir("/dev/shm"))
    server = serve()
    with Client(server.host, server.port, shared_memory=True) as client:
        client.reset(seed=0)
        client.step(np.zeros(1, np.float32))
        assert set(os.listdir("/dev/shm")) == before


def test_slots_of_an_unknown_kind_are_refused_on_the_socket(serve: Serve) -> None:
    server = serve()
    with Client(server.host, server.port, shared_memory=True) as client:
        client.reset(seed=0)
        assert client._lane is not None
        lane = client._lane.lane  # what a client of another language could write by mistake
        header = memoryview(lane.memory)[:32].cast("q")
        header[1], header[2] = 99, 7  # id 99, kind 7
        header[0] += 1
        client._connection.note_request(99)
        lane.ring()
        reply = client._receive()
        del header
        assert reply.code == "bad_request" and "kind 7" in reply.message  # type: ignore[union-attr]
        assert client.step(np.zeros(1, np.float32))[-1]["frames"] == 4  # the lane goes on


_LANE_WITHOUT_DESCRIPTORS = textwrap.dedent("""
    import errno, os, resource
    from rlenv.serving._host import Host
    from rlenv.transport.lanes import KEY_SIZE, open_lane
    hello = Host("examples.cartpole:CartPoleEnvironment").hello
    resource.setrlimit(resource.RLIMIT_NOFILE, (64, 64))
    held = []
    try:
        while True:
            held.append(os.open(os.devnull, os.O_RDONLY))
    except OSError:
        os.close(held.pop())  # one descriptor free: the block takes it, the doorbell finds none
    try:
        open_lane("rlenv-lane-" + "0" * 32, bytes(KEY_SIZE), hello, None)
    except OSError as error:
        print(errno.errorcode[error.errno])
    try:
        os.close(os.open(os.devnull, os.O_RDONLY))
        print("free")
    except OSError:
        print("leaked")
""")


def test_a_lane_that_cannot_open_leaves_no_descriptor_behind() -> None:
    result = subprocess.run(
        [sys.executable, "-c", _LANE_WITHOUT_DESCRIPTORS],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    assert result.stdout.split() == ["EMFILE", "free"]
