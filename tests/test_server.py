"""End to end: a client and real servers in subprocesses, over loopback TCP."""

from __future__ import annotations

import os
import signal
import socket
import struct
from typing import Any

import numpy as np
import pytest
from conftest import Serve

from examples.cartpole import TARGET, CartPoleAgent, CartPoleEnvironment, controller
from rlenv.protocol import PROTOCOL_VERSION, Connection, Request, Role, pack
from rlenv.protocol.errors import LocalProtocolError
from rlenv.testing import read_frame
from rlenv_client import (
    Client,
    ConnectionLost,
    ErrorCode,
    LocalClient,
    RemoteError,
    RequestTimeout,
    ServerProcess,
)

PUSH = np.array([0.3], dtype=np.float32)
STILL = np.zeros(1, dtype=np.float32)


def test_hello_describes_the_environment(client: Client) -> None:
    assert client.hello.environment == "CartPole"
    assert client.hello.protocol == PROTOCOL_VERSION
    assert client.hello.physics_ticks_per_second == 60
    assert client.hello.repeat_action == 4
    assert client.hello.render_size == (600, 400)  # width, height
    assert client.action_space == CartPoleAgent.action_space
    assert client.observation_space == CartPoleAgent.observation_space
    assert client.hello.limits == {
        "max_frame_size": 64 * 1024 * 1024,
        "max_first_frame_size": 64 * 1024,
        "max_reply_size": 64 * 1024 * 1024,
        "max_frame_objects": 1 << 20,
        "frame_deadline": 10.0,
        "first_request_timeout": 10.0,
        "idle_timeout": 3600.0,
        "write_timeout": 10.0,
        "max_connections": 8,
        "max_repeat_action": 10_000,
        "max_level_nodes": 1024,
        "max_level_depth": 64,
    }


def test_a_huge_repeat_action_is_refused_at_once_and_others_are_served(serve: Serve) -> None:
    """Before, 2**40 ticks kept the server's loop busy: new clients timed out."""
    server = serve()
    with Client(server.host, server.port, timeout=10) as client:
        client.reset(seed=0)
        with pytest.raises(RemoteError) as refused:
            client.step(STILL, repeat_action=2**40)
        assert refused.value.code == ErrorCode.BAD_REQUEST
        assert "at most 10000 ticks" in refused.value.message
        with Client(server.host, server.port, timeout=10) as newcomer:
            assert newcomer.stats()["current"]["length"] == 0  # served: nothing was stepped
        client.step(STILL)


def test_the_hello_announces_the_limits_the_server_was_started_with(serve: Serve) -> None:
    server = serve(
        args=[
            "--max-frame-size",
            "5000",
            "--idle-timeout",
            "0",
            "--max-connections",
            "3",
            "--frame-deadline",
            "2.5",
        ]
    )
    with Client(server.host, server.port) as client:
        limits = client.hello.limits
        assert (
            limits["max_frame_size"],
            limits["idle_timeout"],
            limits["max_connections"],
            limits["frame_deadline"],
        ) == (5000, None, 3, 2.5)
        assert limits["max_first_frame_size"] == 5000  # never more than max_frame_size
    with socket.create_connection((server.host, server.port), timeout=10) as raw:
        read_frame(raw)
        raw.sendall(struct.pack(">I", 5001) + b"\x00")  # a first frame over the limit
        error = read_frame(raw)["error"]
        assert (error["code"], error["fatal"]) == (ErrorCode.BAD_FRAME, True)
        assert "exceeds the limit of 5000" in error["message"]
    with Client(server.host, server.port) as client:
        client.reset(seed=0)
        with pytest.raises(LocalProtocolError, match="exceeds the peer's frame limit of 5000"):
            client.reset(options={"blob": b"x" * 5000})  # refused before it is sent
        client.step(PUSH)  # nothing was sent: the connection goes on


def test_reset_returns_an_observation_of_the_space(client: Client) -> None:
    observation, info = client.reset(seed=1)
    assert observation in client.observation_space
    assert info == {"frames": 0}


@pytest.mark.parametrize("repeat", [1, 4, 7])
def test_an_action_runs_exactly_repeat_action_ticks(serve: Serve, repeat: int) -> None:
    """The reported count is the real count: k single ticks reach the very same state."""
    with (
        Client(*_address(serve()), timeout=10) as stepped,
        Client(*_address(serve()), timeout=10) as ticked,
    ):
        stepped.reset(seed=7)
        ticked.reset(seed=7)
        observation, reward, terminated, _, info = stepped.step(PUSH, repeat_action=repeat)
        assert info["frames"] == repeat
        assert reward == float(repeat)  # +1 per tick alive
        assert not terminated
        for _ in range(repeat):
            expected, *_ = ticked.step(PUSH, repeat_action=1)
        assert observation.tobytes() == expected.tobytes()


class _TimedCartPole(CartPoleEnvironment):
    """Records the tree's tick count around ``super()._step``, as an override would."""

    def __init__(self) -> None:
        super().__init__()
        self.ticks_around_steps: list[tuple[int, int]] = []

    def _step(self, action: Any, frames: int | None = None) -> None:
        before = self.get_tree().physics_frames
        super()._step(action, frames)
        self.ticks_around_steps.append((before, self.get_tree().physics_frames))


def test_code_after_super_step_runs_once_the_ticks_have_run() -> None:
    """As in the Godot seed (``yield(._step(action), "completed")``): _step returns when done."""
    environment = _TimedCartPole()
    with LocalClient(environment) as local:
        local.reset(seed=3)
        local.step(PUSH, repeat_action=5)
        local.step(PUSH)
    assert [after - before for before, after in environment.ticks_around_steps] == [5, 4]


def test_repeat_action_defaults_and_configuration(client: Client) -> None:
    client.reset(seed=0)
    assert client.step(STILL)[4]["frames"] == 4
    assert client.step(STILL, repeat_action=2)[4]["frames"] == 2
    assert client.step(STILL)[4]["frames"] == 4  # a per-step count does not stick
    client.configure(repeat_action=7)
    assert client.step(STILL)[4]["frames"] == 7


def test_an_episode_ends_early_when_the_pole_falls(client: Client) -> None:
    client.reset(seed=3)
    frames = 0
    terminated = False
    while not terminated:
        _, reward, terminated, truncated, info = client.step(np.ones(1, np.float32), 7)
        frames += info["frames"]
        assert not truncated
    assert 0 < info["frames"] <= 7
    assert reward == info["frames"] - 1  # the tick the pole fell earns nothing
    with pytest.raises(RemoteError) as error:
        client.step(PUSH)
    assert error.value.code == ErrorCode.RESET_REQUIRED
    assert "ended" in error.value.message
    client.reset()
    client.step(PUSH)


def test_the_controller_keeps_the_pole_up(client: Client) -> None:
    for repeat in (1, 4, 7):
        observation, _ = client.reset(seed=repeat)
        for _ in range(1260 // repeat):  # 21 simulated seconds
            observation, _, terminated, _, _ = client.step(controller(observation), repeat)
            assert not terminated
        assert abs(observation[2]) < 0.05 and abs(observation[0]) < 1.0


def test_wrong_actions_get_precise_errors_and_change_nothing(client: Client) -> None:
    client.reset(seed=5)
    client.step(PUSH)
    before = client.observe()
    bad_actions = {
        "action has shape (2,), expected (1,)": np.zeros(2, np.float32),
        "action has shape (), expected (1,)": 0.5,
        "action[0] is nan, expected a finite number": [float("nan")],
        "action[0] is inf, expected a finite number": [float("inf")],
        "action[0] is 3.0, outside the bounds [-1.0, 1.0]": [3.0],
        "action must be an array or a number, got str": "left",
        "action has dtype bool, expected float32": np.array([True]),
    }
    for message, action in bad_actions.items():
        with pytest.raises(RemoteError) as error:
            client.step(action)
        assert error.value.code == ErrorCode.INVALID_ACTION
        assert error.value.message == message
        assert not error.value.fatal
    with pytest.raises(TypeError, match="dtype <U1 cannot travel on the wire"):
        client.step(np.array(["x"]))  # refused before it leaves this process
    after = client.observe()
    assert after["agent"].tobytes() == before["agent"].tobytes()
    assert client.step(PUSH)[4]["frames"] == 4  # and the client goes on


def test_requests_out_of_order_are_refused(client: Client) -> None:
    for call in (lambda: client.step(PUSH), client.observe):
        with pytest.raises(RemoteError) as error:
            call()
        assert error.value.code == ErrorCode.RESET_REQUIRED
    client.reset()


def test_bad_configuration_is_refused_whole(client: Client) -> None:
    client.reset(seed=0)
    with pytest.raises(RemoteError) as error:
        client.configure(repeat_action=2, agent={"max_force": 5.0, "gravity": 1.0})
    assert error.value.code == ErrorCode.INVALID_CONFIG
    assert "'gravity'" in error.value.message and "max_force" in error.value.message
    assert client.step(PUSH)[4]["frames"] == 4  # repeat_action=2 was not applied
    for bad in ({"repeat_action": 0}, {"repeat_action": 1.5}, {"repeat_action": "4"}):
        with pytest.raises(RemoteError, match="repeat_action"):
            client.configure(**bad)
    with pytest.raises(RemoteError, match="max_force must be a float"):
        client.configure(agent={"max_force": "strong"})
    client.configure(agent={"max_force": 20})  # an int may set a float
    assert client.step(PUSH)[4]["frames"] == 4


def test_observe_reports_agent_and_world(client: Client) -> None:
    observation, _ = client.reset(seed=2)
    seen = client.observe()
    assert seen["agent"].tobytes() == observation.tobytes()
    assert seen["world"]["cart"][0] == pytest.approx(float(observation[0]))
    assert set(seen["world"]) == {"cart", "pole_tip"}


def test_world_data_on_request(server: ServerProcess) -> None:
    with Client(server.host, server.port, world_data=True) as client:
        _, info = client.reset(seed=0)
        assert set(info["world"]) == {"cart", "pole_tip"}
        assert "world" in client.step(PUSH)[4]


def test_observations_are_fresh_writable_arrays(client: Client) -> None:
    first, _ = client.reset(seed=0)
    second, *_ = client.step(PUSH)
    assert first.dtype == np.float32 and first.flags.writeable
    assert not np.shares_memory(first, second)


def test_same_seed_and_actions_are_bit_identical_across_servers(serve: Serve) -> None:
    trajectories = []
    for _ in range(2):
        with Client(*_address(serve()), timeout=10) as client:
            observation, _ = client.reset(seed=1234)
            trajectory = [observation.tobytes()]
            for t in range(100):
                action = np.array([np.sin(t / 7.0)], dtype=np.float32)
                observation, _, terminated, _, _ = client.step(action, repeat_action=1 + t % 5)
                trajectory.append(observation.tobytes())
                if terminated:
                    observation, _ = client.reset()
                    trajectory.append(observation.tobytes())
            trajectories.append(trajectory)
    assert trajectories[0] == trajectories[1]


def test_reset_with_a_seed_does_not_depend_on_history(client: Client) -> None:
    def episode() -> list[bytes]:
        observation, _ = client.reset(seed=99)
        seen = [observation.tobytes()]
        for _ in range(8):
            observation, *_ = client.step(STILL, repeat_action=2)
            seen.append(observation.tobytes())
        return seen

    first = episode()
    client.step(PUSH)  # leave forces and solver state behind
    assert episode() == first
    other, _ = client.reset(seed=100)
    assert other.tobytes() != first[0]


def test_a_second_client_may_observe_but_not_control(server: ServerProcess, client: Client) -> None:
    client.reset(seed=0)
    with Client(server.host, server.port, timeout=5) as second:
        seen = second.observe()  # observing is open to everyone
        assert seen["agent"].tobytes() == client.observe()["agent"].tobytes()
        for control in (
            lambda: second.reset(seed=1),
            lambda: second.step(PUSH),
            lambda: second.configure(repeat_action=2),
        ):
            with pytest.raises(RemoteError) as error:
                control()
            assert error.value.code == ErrorCode.BUSY and not error.value.fatal
            assert "controlled by another client" in error.value.message
        assert client.step(PUSH)[4]["frames"] == 4  # the controller is undisturbed
    # control passes on when the controller leaves
    client.close()
    with Client(server.host, server.port, timeout=5) as third:
        third.reset(seed=2)


def test_connections_beyond_the_cap_are_told_busy(serve: Serve) -> None:
    server = serve(args=["--max-connections", "2"])
    with Client(server.host, server.port) as first, Client(server.host, server.port):
        with pytest.raises(RemoteError) as error:
            Client(server.host, server.port, timeout=5)
        assert error.value.code == ErrorCode.BUSY and error.value.fatal
        assert "2 clients connected" in error.value.message
        first.reset(seed=0)


def test_the_next_client_is_served_after_one_leaves(server: ServerProcess) -> None:
    for seed in range(3):
        with Client(server.host, server.port, timeout=5) as client:
            client.reset(seed=seed)
            client.step(PUSH)


def test_a_dead_server_gives_connection_lost(server: ServerProcess) -> None:
    client = Client(server.host, server.port, timeout=10)
    client.reset(seed=0)
    os.killpg(server.pid, signal.SIGKILL)
    server.process.wait()
    with pytest.raises(ConnectionLost):
        client.step(PUSH)
    assert client.closed
    with pytest.raises(ConnectionLost, match="closed"):
        client.step(PUSH)


def test_a_stopped_server_gives_a_timeout_and_the_connection_closes(
    server: ServerProcess,
) -> None:
    client = Client(server.host, server.port, timeout=3.0)  # the hello and reset's margin too
    client.reset(seed=0)
    os.killpg(server.pid, signal.SIGSTOP)
    try:
        with pytest.raises(RequestTimeout, match="did not answer within 3.0s"):
            client.step(PUSH)
        assert client.closed  # a late answer can never be taken for a later request's
    finally:
        os.killpg(server.pid, signal.SIGCONT)


def test_nothing_listening_gives_connection_lost() -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with pytest.raises(ConnectionLost, match="cannot connect"):
        Client("127.0.0.1", port, timeout=2)


def test_broken_framing_is_answered_and_the_server_keeps_serving(server: ServerProcess) -> None:
    with socket.create_connection((server.host, server.port), timeout=5) as raw:
        read_frame(raw)  # the hello
        raw.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
        reply = read_frame(raw)
        assert reply["error"]["code"] == ErrorCode.BAD_FRAME
        assert "exceeds the limit" in reply["error"]["message"]
        assert reply["error"]["fatal"] is True
        assert raw.recv(1) == b""  # and the server hung up
    with Client(server.host, server.port, timeout=5) as client:
        client.reset(seed=0)
        assert client.step(PUSH)[4]["frames"] == 4


def test_bad_frames_with_intact_framing_keep_the_connection(server: ServerProcess) -> None:
    with socket.create_connection((server.host, server.port), timeout=5) as raw:
        read_frame(raw)
        for body, code, words in [
            (b"\xc1", ErrorCode.BAD_FRAME, "not valid msgpack"),
            (pack({"id": 1}) + b"\x00", ErrorCode.BAD_FRAME, "trailing bytes"),
            (pack([1, 2]), ErrorCode.BAD_FRAME, "must hold a map"),
            (pack({"id": 2, "jump": True}), ErrorCode.BAD_REQUEST, "unknown request key 'jump'"),
            (pack({"id": 3, "reset": {"seed": -1}}), ErrorCode.BAD_REQUEST, "reset.seed"),
        ]:
            raw.sendall(struct.pack(">I", len(body)) + body)
            reply = read_frame(raw)
            assert reply["error"]["code"] == code
            assert words in reply["error"]["message"]
            assert reply["error"]["fatal"] is False
        good = Request(4, {"reset": {"seed": 0}, "observation": {"agent": {}}}).to_wire()
        body = pack(good)
        raw.sendall(struct.pack(">I", len(body)) + body)
        reply = read_frame(raw)
        assert reply["id"] == 4 and "error" not in reply


def test_a_client_that_leaves_mid_episode_loses_nothing_for_the_next(
    server: ServerProcess,
) -> None:
    raw = socket.create_connection((server.host, server.port), timeout=5)
    connection = Connection(Role.CLIENT)
    connection.receive_data(raw.recv(65536))
    connection.next_message()
    raw.sendall(connection.send(Request(1, {"reset": {"seed": 3}, "observation": {"agent": {}}})))
    raw.sendall(connection.send(Request(2, {"action": PUSH, "repeat_action": 7})))
    raw.close()  # gone before the answers
    with LocalClient(TARGET) as reference:  # the same requests, answered
        reference.reset(seed=3)
        left_at = reference.step(PUSH, 7)[0]
        reference.reset(seed=0)
        fresh = reference.step(PUSH)[0]
    with Client(server.host, server.port, timeout=5) as client:
        stats = client.stats()  # before anything else: both requests ran whole
        assert (stats["steps"], stats["ticks"], stats["errors"]) == (1, 7, 0)
        assert stats["current"] == {"return": 7.0, "length": 1, "ticks": 7}
        assert client.observe()["agent"].tobytes() == left_at.tobytes()  # where it left off
        client.reset(seed=0)
        observation, _, _, _, info = client.step(PUSH)
        assert info["frames"] == 4  # its repeat_action was for its request only
        assert observation.tobytes() == fresh.tobytes()  # a new episode like any other


def test_errors_in_user_code_are_reported_and_reset_recovers(serve: Serve) -> None:
    with Client(*_address(serve("examples.faulty:FaultyEnvironment")), timeout=10) as client:
        observation, _ = client.reset()
        assert observation.tolist() == [0]
        observation, reward, _, _, info = client.step(0)
        assert observation.tolist() == [3] and reward == 1.5 and info["frames"] == 3
        with pytest.raises(RemoteError) as error:
            client.step(1)
        assert error.value.code == ErrorCode.ENVIRONMENT_ERROR
        assert "the agent tripped over action 1" in error.value.message
        assert "/root/Faulty/Agent" in error.value.message  # the node at fault
        with pytest.raises(RemoteError) as error:
            client.step(0)
        assert error.value.code == ErrorCode.RESET_REQUIRED
        assert error.value.message == "the episode was stopped by an environment_error; reset first"
        client.reset()
        with pytest.raises(RemoteError, match="no observation for action 2"):
            client.step(2)
        observation, _ = client.reset()
        assert observation.tolist() == [0]
        total = 0
        terminated = False
        while not terminated:
            observation, _, terminated, _, info = client.step(0)
            total += info["frames"]
        assert total == 10 and observation.tolist() == [10]


def test_discrete_actions_are_checked(serve: Serve) -> None:
    with Client(*_address(serve("examples.faulty:FaultyEnvironment")), timeout=10) as client:
        client.reset()
        for action, message in [
            (3, "action is 3, outside [0, 2]"),
            (0.0, "action must be an integer, got float"),
            (True, "action must be an integer, got bool"),
            (
                np.array([1]),
                "action must be an integer (a Discrete value is "
                "one integer, not an array), got an array of shape (1,) and "
                "dtype int64",
            ),
        ]:
            with pytest.raises(RemoteError) as error:
                client.step(action)
            assert error.value.message == message
        client.step(np.int64(2 - 2))


def test_server_output_is_kept_for_errors(serve: Serve) -> None:
    from rlenv_client import ServerStartError

    with pytest.raises(ServerStartError) as error:
        serve("examples.faulty:NoSuchEnvironment")
    assert "has no attribute 'NoSuchEnvironment'" in str(error.value)
    with pytest.raises(ServerStartError, match="expected MODULE:CLASS"):
        serve("envs")


def test_closing_a_server_leaves_no_process(serve: Serve) -> None:
    process = serve()
    process.close()
    assert not process.is_alive()
    with pytest.raises(ProcessLookupError):
        os.killpg(process.pid, 0)


def _address(server: ServerProcess) -> tuple[str, int]:
    return server.host, server.port


def test_a_server_hosts_several_instances_stepped_by_one_batch(serve: Serve) -> None:
    multi, single = serve(args=["--instances", "3"]), serve()
    with Client(multi.host, multi.port) as many, Client(single.host, single.port) as one:
        assert many.hello.instances == 3 and one.hello.instances == 1
        many.send_batch([many.reset_request(seed=s) for s in (10, 11, 12)])
        resets = [many.reset_result(reply) for reply in many.receive_batch()]
        for seed, (observation, _) in zip((10, 11, 12), resets, strict=True):
            assert observation.tobytes() == one.reset(seed=seed)[0].tobytes()  # same episodes
        # one instance's bad action is that instance's error; the others step
        many.send_batch([many.step_request(PUSH), many.step_request(np.zeros(2, np.float32)), None])
        first, second, third = many.receive_batch()
        assert many.step_result(first)[4]["frames"] == 4
        with pytest.raises(RemoteError, match=r"shape \(2,\)"):
            many.step_result(second)
        assert third is None
        # instances are independent trees: instance 2 did not move
        many.send_batch([None, None, Request(0, {"observation": {"agent": {}}})])
        (observation,) = [many.reset_result(r)[0] for r in many.receive_batch() if r is not None]
        assert observation.tobytes() == resets[2][0].tobytes()
        with pytest.raises(RemoteError, match="a batch of 4 requests for 3 instances"):
            many.send_batch([None] * 4)
            many.receive_batch()
        assert many.step(PUSH)[4]["frames"] == 4  # a plain request goes to instance 0
        # so do snapshots and inspections, checked there like any other request
        assert many.snapshot()["events"]
        assert many.tree()[0]["path"] == "/root/CartPole"
        with pytest.raises(RemoteError, match="inspect"):
            many.send_request(Request(0, {"inspect": {"bogus": {}}}))
            many.step_result(many.receive_reply())


def test_steps_step_every_instance_in_columns_as_plain_requests_would(serve: Serve) -> None:
    multi, single = serve(args=["--instances", "3"]), serve()
    seeds = (20, 21, 22)
    actions = np.array([[0.3], [-0.7], [1.0]], dtype=np.float32)
    with Client(multi.host, multi.port) as many, Client(single.host, single.port) as one:
        many.send_batch([many.reset_request(seed=seed) for seed in seeds])
        many.receive_batch()
        many.send_steps(actions, repeat_action=3)
        columns = many.receive_steps()
        assert columns.errors is None and columns.info == ({}, {}, {})
        for index, seed in enumerate(seeds):  # the same as one plain request per instance
            one.reset(seed=seed)
            observation, reward, terminated, truncated, info = one.step(actions[index], 3)
            assert columns.observation[index].tobytes() == observation.tobytes()
            assert (
                columns.reward[index],
                columns.terminated[index],
                columns.truncated[index],
                columns.frames[index],
            ) == (reward, terminated, truncated, info["frames"])
        # reset where the mask says so (the action of that row is ignored), step the others
        many.send_steps(actions, reset=np.array([False, True, False]))
        mixed = many.receive_steps()
        assert mixed.frames.tolist() == [4, 0, 4] and mixed.reward.tolist() == [4.0, 0.0, 4.0]


def test_refused_steps_change_nothing(serve: Serve) -> None:
    multi = serve(args=["--instances", "2"])
    with Client(multi.host, multi.port) as many:
        many.send_steps(np.zeros((2, 1), np.float32))
        with pytest.raises(RemoteError, match="steps: instance 0: no episode has started"):
            many.receive_steps()
        many.send_steps(np.zeros((2, 1), np.float32), reset=np.ones(2, np.bool_))
        before = many.receive_steps().observation
        for bad, words in [
            (np.array([[0.0], [2.0]], np.float32), r"steps.action\[1, 0\] is 2.0, outside"),
            (np.zeros((3, 1), np.float32), r"shape \(3, 1\), expected \(2, 1\)"),
        ]:
            many.send_steps(bad)
            with pytest.raises(RemoteError, match=words) as refused:
                many.receive_steps()
            assert refused.value.code == ErrorCode.INVALID_ACTION
        many.send_steps(np.zeros((2, 1), np.float32), reset=np.ones(3, np.bool_))
        with pytest.raises(RemoteError, match="steps.reset has 3 flags for 2 instances"):
            many.receive_steps()
        many.send_batch([Request(0, {"observation": {"agent": {}}})] * 2)  # nothing moved
        after = np.stack([many.reset_result(reply)[0] for reply in many.receive_batch()])
        assert after.tobytes() == before.tobytes()


def test_a_failing_instance_fails_alone_in_columns(serve: Serve) -> None:
    """Discrete actions (checked row by row); action 1 raises in the faulty agent's tick."""
    multi = serve("examples.faulty:FaultyEnvironment", args=["--instances", "2"])
    with Client(multi.host, multi.port) as many:
        many.send_steps(np.zeros(2, np.int64), reset=np.ones(2, np.bool_))
        many.receive_steps()
        many.send_steps(np.array([0, 1]))
        columns = many.receive_steps()
        assert columns.errors is not None and columns.errors[0] is None
        assert columns.errors[1].code == ErrorCode.ENVIRONMENT_ERROR
        assert "tripped over action 1" in columns.errors[1].message
        assert columns.observation[0].tolist() == [3] and columns.frames[0] == 3
        many.send_steps(np.array([0, 0]))
        with pytest.raises(
            RemoteError, match="steps: instance 1: the episode was stopped by an environment_error"
        ):
            many.receive_steps()
        many.send_steps(np.array([0, 5]), reset=np.array([False, True]))
        with pytest.raises(RemoteError, match=r"steps.action\[1\] is 5, outside \[0, 2\]"):
            many.receive_steps()  # rows of resetting instances are checked too
        many.send_steps(np.array([0, 0]), reset=np.array([False, True]))
        assert many.receive_steps().observation.tolist() == [[6], [0]]


def test_a_non_finite_observation_fails_its_instance_alone_in_columns(serve: Serve) -> None:
    """Float observations are checked once for all instances; a NaN fails only its own."""
    multi = serve("examples.faulty:CountingEnvironment", args=["--instances", "3"])
    with Client(multi.host, multi.port) as many:
        many.send_steps(np.zeros(3, np.int64), reset=np.ones(3, np.bool_))
        many.receive_steps()
        many.send_steps(np.array([0, 1, 0]), repeat_action=2)
        columns = many.receive_steps()
        assert columns.errors is not None and columns.errors[0] is None is columns.errors[2]
        assert columns.errors[1].code == ErrorCode.ENVIRONMENT_ERROR
        assert (
            "the observation of /root/Counting/Agent is not finite at [0]"
            in columns.errors[1].message
        )
        assert columns.observation[[0, 2], 0].tolist() == [2.0, 2.0]
        assert np.isfinite(columns.observation).all()  # the failed row is blank, not NaN
        many.send_steps(np.zeros(3, np.int64))
        with pytest.raises(
            RemoteError, match="steps: instance 1: the episode was stopped by an environment_error"
        ):
            many.receive_steps()


def test_joint_actions_in_columns_are_checked_whole(serve: Serve) -> None:
    """Dict actions (two agents): every agent's rows must be there, one per instance."""
    multi = serve("examples.pair:PairEnvironment", args=["--instances", "2"])
    rows = {name: np.zeros((2, 2), np.float32) for name in ("Blue", "Red")}
    with Client(multi.host, multi.port) as many:
        many.send_steps(rows, reset=np.ones(2, np.bool_))
        assert many.receive_steps().errors is None
        for bad, words in [
            (
                {**rows, "Blue": np.zeros((3, 2), np.float32)},
                r"steps.action\['Blue'\] has shape \(3, 2\), expected \(2, 2\)",
            ),
            ({"Blue": rows["Blue"]}, r"missing keys \['Red'\]"),
            (np.zeros((2, 2), np.float32), r"must be a map with keys \['Blue', 'Red'\]"),
        ]:
            many.send_steps(bad)
            with pytest.raises(RemoteError, match=words):
                many.receive_steps()
        many.send_steps(rows)
        columns = many.receive_steps()
        assert columns.errors is None and set(columns.observation) == {"Blue", "Red"}
        assert all(set(info["agents"]) == {"Blue", "Red"} for info in columns.info)


def test_a_single_instance_server_takes_batches_and_steps_as_a_host_of_one(
    serve: Serve,
) -> None:
    """No request form depends on how many instances a server hosts."""
    with (
        Client(*_address(serve()), timeout=10) as steps,
        Client(*_address(serve()), timeout=10) as plain,
    ):
        steps.send_batch([steps.reset_request(seed=3)])
        (reply,) = steps.receive_batch()
        observation, _ = plain.reset(seed=3)
        assert steps.reset_result(reply)[0].tobytes() == observation.tobytes()
        for _ in range(3):
            steps.send_steps(PUSH[np.newaxis], repeat_action=2)
            columns = steps.receive_steps()
            observation, reward, terminated, _, info = plain.step(PUSH, 2)
            assert columns.observation.shape == (1, 5) and columns.errors is None
            assert columns.observation[0].tobytes() == observation.tobytes()
            assert (columns.reward[0], columns.terminated[0], columns.frames[0]) == (
                reward,
                terminated,
                info["frames"],
            )


def test_batches_are_validated_part_by_part(server: ServerProcess) -> None:
    with socket.create_connection((server.host, server.port), timeout=5) as raw:
        read_frame(raw)
        for body, words in [
            (pack({"id": 1, "batch": []}), "non-empty list"),
            (pack({"id": 2, "batch": [1]}), "batch[0] must be a map"),
            (pack({"id": 3, "batch": [{"jump": 1}]}), "batch[0].'jump'"),
            (pack({"id": 4, "batch": [None], "reset": {}}), "carries nothing else"),
        ]:
            raw.sendall(struct.pack(">I", len(body)) + body)
            reply = read_frame(raw)
            assert reply["error"]["code"] == ErrorCode.BAD_REQUEST
            assert words in reply["error"]["message"], reply


def test_the_token_is_checked_on_every_request_until_one_carries_it(serve: Serve) -> None:
    """Frames that are no request do not count: a client whose first frame carried the token
    but was malformed is asked for it again, not shut out; the first request read decides."""
    server = serve(args=["--token", "s3cret"])

    def call(raw: socket.socket, body: dict[str, Any]) -> dict[str, Any]:
        data = pack(body)
        raw.sendall(struct.pack(">I", len(data)) + data)
        return read_frame(raw)

    with socket.create_connection((server.host, server.port), timeout=10) as raw:
        assert read_frame(raw)["hello"]["token_required"] is True
        for malformed, code in [
            ({"id": "one", "token": "s3cret"}, ErrorCode.BAD_REQUEST),
            ({"id": 1, "token": 7}, ErrorCode.BAD_REQUEST),
        ]:
            reply = call(raw, malformed)
            assert reply["error"]["code"] == code and not reply["error"]["fatal"], reply
        raw.sendall(struct.pack(">I", 1) + b"\xc1")  # not even msgpack
        assert read_frame(raw)["error"]["code"] == ErrorCode.BAD_FRAME
        reply = call(raw, {"id": 2, "token": "s3cret", "reset": {"seed": 0}})
        assert reply["id"] == 2 and reply["frames"] == 0
        assert call(raw, {"id": 3, "action": b"\x00" * 4})["frames"] == 4  # no token needed now
    with socket.create_connection((server.host, server.port), timeout=10) as raw:
        read_frame(raw)
        reply = call(raw, {"id": 1, "reset": {}})  # a request read without the token
        assert reply["error"]["code"] == ErrorCode.UNAUTHORIZED and reply["error"]["fatal"]
        assert raw.recv(1) == b""


@pytest.mark.parametrize("reset_by", ["steps", "batch"])
def test_a_row_that_failed_counts_its_ticks_afresh_after_its_reset(
    serve: Serve, reset_by: str
) -> None:
    """Row 1 raises in the middle of a step; after its reset, it counts ticks and rewards
    exactly like its neighbours, whichever way it was reset."""
    server = serve("examples.faulty:FaultyEnvironment", args=["--instances", "3"])
    with Client(server.host, server.port) as client:
        client.send_steps(np.zeros(3, np.int64), reset=np.ones(3, bool), repeat_action=3)
        client.receive_steps()
        client.send_steps(np.array([0, 1, 0]), repeat_action=3)
        failed = client.receive_steps()
        assert failed.errors is not None and failed.errors[1].code == ErrorCode.ENVIRONMENT_ERROR
        if reset_by == "steps":
            client.send_steps(
                np.zeros(3, np.int64), reset=np.array([False, True, False]), repeat_action=3
            )
            client.receive_steps()
        else:
            client.send_batch([None, Request(0, {"reset": {}})])
            client.receive_batch()
        client.send_steps(np.zeros(3, np.int64), repeat_action=3)
        answer = client.receive_steps()
        assert answer.errors is None
        assert answer.frames.tolist() == [3, 3, 3]
        assert answer.reward.tolist() == [1.5, 1.5, 1.5]
        neighbours = 9 if reset_by == "steps" else 6  # ticks since their reset
        assert answer.observation.ravel().tolist() == [neighbours, 3, neighbours]


def test_a_failed_request_leaves_no_ticks_nor_reward_to_later_answers(serve: Serve) -> None:
    """An action that fails after 3 ticks: its ticks and reward belong to no answer, and its
    episode cannot be snapshotted (restoring it would fail the same way)."""
    server = serve("examples.faulty:FaultyEnvironment")
    with Client(server.host, server.port) as client, Client(server.host, server.port) as observer:
        client.reset(seed=0)
        with pytest.raises(RemoteError) as error:
            client._call(action=2, observation={"agent": {}})  # fails when observed
        assert error.value.code == ErrorCode.ENVIRONMENT_ERROR
        for answer in (
            client._call(action=None),
            client._call(config={}),
            observer._call(inspect={"tree": {}}),
        ):
            assert (answer.frames, answer.reward) == (0, 0.0)
        with pytest.raises(RemoteError) as refused:
            client.snapshot()
        assert refused.value.code == ErrorCode.RESET_REQUIRED
        assert (
            refused.value.message == "the episode was stopped by an environment_error; reset first"
        )
        client.reset(seed=0)
        assert client.step(0)[4]["frames"] == 3
