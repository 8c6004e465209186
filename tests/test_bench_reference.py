"""The hand-written CartPole server (``examples.handwritten``), the floor of ``rlenv bench``.

It must do rlenv's CartPole's work exactly, or the bench would compare unequal work: the same
seed and actions give bit-identical observations, rewards, terminations and tick counts, over
real sockets (rlenv's server and client against the raw server and a raw client) and in this
process (``LocalClient`` against the ``CartPole`` class).
"""

from __future__ import annotations

import socket
import struct
import subprocess
import sys
from collections.abc import Callable, Iterator
from typing import Any

import msgpack
import numpy as np
import pytest

CARTPOLE = "examples.cartpole:CartPoleEnvironment"
STEPS = 200
REPEAT = 4


class RawClient:
    """``python -m examples.handwritten`` in a subprocess, and a raw msgpack client to it."""

    def __init__(self, instances: int = 1) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-m", "examples.handwritten", str(instances)],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.process.stdout is not None
        line = self.process.stdout.readline()
        assert line.startswith("listening on "), line
        host, _, port = line.removeprefix("listening on ").strip().rpartition(":")
        self.sock = socket.create_connection((host, int(port)), timeout=30)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.ids = 0

    def call(self, **parts: Any) -> dict[str, Any]:
        self.ids += 1
        body = msgpack.packb({"id": self.ids, **parts})
        self.sock.sendall(struct.pack(">I", len(body)) + body)
        data = b""
        while len(data) < 4 or len(data) < 4 + struct.unpack(">I", data[:4])[0]:
            chunk = self.sock.recv(65536)
            assert chunk, "the hand-written server closed the connection"
            data += chunk
        reply = msgpack.unpackb(data[4:])
        assert reply["id"] == self.ids
        reply["observation"] = np.frombuffer(reply["observation"], np.float32).copy()
        return reply

    def close(self) -> None:
        self.sock.close()
        try:
            self.process.wait(10)  # it exits when its client disconnects
        finally:
            self.process.kill()
            self.process.wait()


@pytest.fixture
def raw() -> Iterator[RawClient]:
    client = RawClient()
    try:
        yield client
    finally:
        client.close()
    assert client.process.returncode == 0


def _actions(seed: int) -> np.ndarray:
    """Random pushes: episodes of a few steps, so many end early (between two requests' ticks)."""
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (STEPS, 1)).astype(np.float32)


def test_hand_written_server_answers_a_reset_and_a_step(raw: RawClient) -> None:
    reset = raw.call(reset={"seed": 0})
    assert reset["observation"].shape == (5,) and np.all(np.abs(reset["observation"]) < 0.1)
    assert (reset["reward"], reset["terminated"], reset["frames"]) == (0.0, False, 0)
    step = raw.call(action=np.array([0.5], np.float32).tobytes(), repeat_action=REPEAT)
    assert step["frames"] == REPEAT and step["reward"] == REPEAT
    assert step["terminated"] is False and step["truncated"] is False and step["info"] == {}
    assert step["observation"][3] > reset["observation"][3]  # pushed towards +x


def test_hand_written_server_stops_when_the_pole_falls(raw: RawClient) -> None:
    raw.call(reset={"seed": 1})
    step = raw.call(action=np.array([1.0], np.float32).tobytes(), repeat_action=1000)
    assert step["terminated"] is True and step["frames"] < 1000
    assert step["reward"] == step["frames"] - 1  # +1 per tick alive, not the tick it fell


def test_hand_written_server_takes_the_bench_configuration(raw: RawClient) -> None:
    endless = {"agent": {"angle_limit": 1e9}, "world": {"track_limit": 1e9}}
    raw.call(config=endless, reset={"seed": 1})
    step = raw.call(action=np.array([1.0], np.float32).tobytes(), repeat_action=1000)
    assert (step["terminated"], step["frames"], step["reward"]) == (False, 1000, 1000.0)
    assert abs(step["observation"][0]) > 2.4 and abs(step["observation"][2]) > np.pi / 15


@pytest.mark.parametrize("seed", [0, 5])
def test_same_trajectory_as_rlenv_over_sockets(raw: RawClient, seed: int) -> None:
    from rlenv_client import Client, ServerProcess

    with ServerProcess(CARTPOLE) as server, Client(server.host, server.port) as client:
        ended = _compare(lambda **kwargs: _rlenv_call(client, **kwargs), raw.call, seed)
    assert ended >= 2


def test_same_trajectory_as_rlenv_in_process(seed: int = 3) -> None:
    from examples.handwritten import CartPole
    from rlenv_client import LocalClient

    cartpole = CartPole()
    with LocalClient(CARTPOLE) as local:
        ended = _compare(
            lambda **kwargs: _rlenv_call(local, **kwargs),
            _caller(cartpole),
            seed,
            lambda: _assert_same_state(local, cartpole),
        )
    assert ended >= 2


def test_same_trajectory_as_rlenv_when_endless() -> None:
    """Configured as the bench does: the pole falls over and the episode goes on."""
    from examples.handwritten import CartPole
    from rlenv_client import LocalClient

    endless = {"agent": {"angle_limit": 1e9}, "world": {"track_limit": 1e9}}
    cartpole = CartPole()
    call = _caller(cartpole)
    with LocalClient(CARTPOLE) as local:
        local.configure(**endless)
        expected, _ = local.reset(seed=2)
        got = call(config=endless, reset={"seed": 2})["observation"]
        for action in _actions(2):
            assert got.tobytes() == expected.tobytes()
            _assert_same_state(local, cartpole)
            expected, reward, terminated, _, _ = local.step(action, REPEAT)
            reply = call(action=action.tobytes(), repeat_action=REPEAT)
            got = reply["observation"]
            assert (reply["reward"], reply["terminated"]) == (reward, terminated) == (4.0, False)
        assert abs(got[2]) > np.pi / 2  # the pole fell over, and nothing ended


def _caller(cartpole: Any) -> Callable[..., dict[str, Any]]:
    """Requests to a hand-written ``CartPole`` in this process, answered as its server does."""

    def call(**parts: Any) -> dict[str, Any]:
        reply = cartpole.answer({"id": 0, **parts})
        reply["observation"] = np.frombuffer(reply["observation"], np.float32)
        return reply

    return call


def _assert_same_state(local: Any, cartpole: Any) -> None:
    """The bodies' state in double precision (observations are float32), read by inspection."""
    for node, body in (("Cart", cartpole.cart), ("Pole", cartpole.pole)):
        for name in ("position", "velocity", "angle", "angular_velocity"):
            expected = local.get_property(f"World/Physics/{node}", name)
            got = getattr(body, name)
            assert expected == (list(got) if isinstance(expected, list) else got), (node, name)


def _rlenv_call(
    client: Any,
    *,
    reset: dict[str, Any] | None = None,
    action: bytes | None = None,
    repeat_action: int = REPEAT,
) -> dict[str, Any]:
    """``client.reset`` or ``client.step``, answered like the hand-written server answers."""
    if reset is not None:
        observation, info = client.reset(**reset)
        return {
            "observation": observation,
            "reward": 0.0,
            "terminated": False,
            "truncated": False,
            "frames": 0,
        }
    observation, reward, terminated, truncated, info = client.step(
        np.frombuffer(action, np.float32).copy(), repeat_action
    )
    return {
        "observation": observation,
        "reward": reward,
        "terminated": terminated,
        "truncated": truncated,
        "frames": info["frames"],
    }


def _compare(
    rlenv: Any, hand_written: Any, seed: int, check: Callable[[], None] = lambda: None
) -> int:
    """Drive both with the same seed and actions, resetting when the pole falls; the episodes
    that ended. Resets after the first continue the seeded generator, as gymnasium's do.
    ``check`` runs after every request."""
    ended, ended_now = 0, False
    for number, action in enumerate([None, *_actions(seed)]):
        request = (
            {"reset": {"seed": seed}}
            if number == 0
            else {"reset": {}}
            if ended_now
            else {"action": action.tobytes()}
        )
        expected, got = rlenv(**request), hand_written(**request)
        assert expected["observation"].dtype == got["observation"].dtype == np.float32
        assert expected["observation"].tobytes() == got["observation"].tobytes(), (
            number,
            request,
            expected,
            got,
        )
        for key in ("reward", "terminated", "truncated", "frames"):
            assert expected[key] == got[key], (number, key, expected, got)
        check()
        ended_now = bool(got["terminated"])
        ended += ended_now
    return ended


def test_hand_written_columns_step_each_cartpole_as_alone() -> None:
    """``python -m examples.handwritten 3``: one request steps or resets three CartPoles, each
    exactly as a lone CartPole given its column of the request."""
    from examples.handwritten import CartPole

    alone = [CartPole() for _ in range(3)]
    for seed, cartpole in enumerate(alone):
        cartpole.reset(seed)
    raw = RawClient(3)
    try:
        resets, ended = [False, False, False], 0
        for number, action in enumerate(_actions(4)[:60]):
            actions = np.array([action[0], -action[0], 0.5 * action[0]], np.float32)
            reply = raw.call(action=actions.tobytes(), reset=resets, repeat_action=REPEAT)
            observations = reply["observation"].reshape(3, 5)
            rewards = np.frombuffer(reply["reward"], np.float64)
            frames = np.frombuffer(reply["frames"], np.int64)
            for index, cartpole in enumerate(alone):
                if resets[index]:
                    cartpole.reset()
                    expected = {"reward": 0.0, "terminated": False, "frames": 0}
                else:
                    expected = cartpole.answer(
                        {
                            "id": number,
                            "action": actions[index : index + 1].tobytes(),
                            "repeat_action": REPEAT,
                        }
                    )
                assert observations[index].tobytes() == cartpole.observe(), (number, index)
                assert (rewards[index], bool(reply["terminated"][index]), frames[index]) == (
                    expected["reward"],
                    expected["terminated"],
                    expected["frames"],
                )
            resets = [bool(fell) for fell in reply["terminated"]]
            ended += sum(resets)
        assert ended >= 3  # columns were reset, and stepped again
    finally:
        raw.close()
    assert raw.process.returncode == 0
