"""``rlenv godot-rl`` against a small godot-rl trainer written here (no godot-rl installed).

The trainer is what godot-rl's ``GodotEnv`` is on the wire: it listens on a loopback port and
speaks 4-byte little-endian lengths, then JSON. The bridge runs as ``rlenv godot-rl`` (or its
launcher) in a subprocess, with its own ``rlenv serve`` behind it.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

import rlenv_client  # noqa: F401  (registers rlenv/CartPole-v1)
from rlenv_tools._godot_game import godot_arguments
from rlenv_tools._godot_wire import GodotWireError, agent_wire

ROOT = Path(__file__).resolve().parent.parent
_DEADLINE = 60.0  # seconds: generous, for a busy machine


class FakeTrainer:
    """godot-rl's side of the wire: listens, accepts one game, sends and reads frames."""

    def __init__(self) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.listener.settimeout(_DEADLINE)
        self.port = self.listener.getsockname()[1]
        self.connection: socket.socket | None = None

    def accept(self) -> None:
        self.connection, _ = self.listener.accept()
        self.connection.settimeout(_DEADLINE)

    def send(self, message: dict[str, Any]) -> None:
        assert self.connection is not None
        body = json.dumps(message).encode()
        self.connection.sendall(len(body).to_bytes(4, "little") + body)

    def receive(self) -> dict[str, Any]:
        assert self.connection is not None
        length = int.from_bytes(self._exactly(4), "little")
        return json.loads(self._exactly(length))

    def ask(self, message: dict[str, Any]) -> dict[str, Any]:
        self.send(message)
        return self.receive()

    def start(self) -> dict[str, Any]:
        """Accept the game, shake hands as godot-rl 0.8 does, and return its env_info."""
        self.accept()
        self.send({"type": "handshake", "major_version": "0", "minor_version": "7"})
        return self.ask({"type": "env_info"})

    def close(self) -> None:
        if self.connection is not None:
            self.connection.close()
        self.listener.close()

    def _exactly(self, size: int) -> bytes:
        assert self.connection is not None
        data = b""
        while len(data) < size:
            chunk = self.connection.recv(size - len(data))
            assert chunk, "the game hung up"
            data += chunk
        return data


@pytest.fixture
def trainer() -> Iterator[FakeTrainer]:
    fake = FakeTrainer()
    yield fake
    fake.close()


def _environment() -> dict[str, str]:
    paths = [str(ROOT), str(ROOT / "client"), str(ROOT / "tools")]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}


class Game:
    """A game process (``rlenv godot-rl`` or a launcher), ended after the test."""

    def __init__(self, command: Sequence[str]) -> None:
        self.process = subprocess.Popen(
            command, env=_environment(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )

    def finish(self) -> tuple[int, str]:
        """Its exit status and standard error, once it exits (within the deadline)."""
        _, stderr = self.process.communicate(timeout=_DEADLINE)
        return self.process.returncode, stderr

    def end(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
        self.process.communicate()


@pytest.fixture
def games() -> Iterator[list[Game]]:
    started: list[Game] = []
    yield started
    for game in started:
        game.end()


def _godot_rl(games: list[Game], *args: str) -> Game:
    game = Game([sys.executable, "-m", "rlenv", "godot-rl", *args])
    games.append(game)
    return game


def _cartpole(seed: int) -> gym.Env:
    env = gym.make("rlenv/CartPole-v1", in_process=True)
    env.reset(seed=seed)
    return env


def test_cartpole_plays_godot_rls_messages_seeded_with_true_bounds(
    trainer: FakeTrainer, games: list[Game]
) -> None:
    game = _godot_rl(
        games,
        "rlenv/CartPole-v1",
        "--port",
        str(trainer.port),
        "--instances",
        "2",
        "--env-seed",
        "3",
    )
    info = trainer.start()
    assert info["type"] == "env_info" and info["n_agents"] == 2
    assert info["agent_policy_names"] == ["shared_policy", "shared_policy"]
    assert info["action_space"] == [{"action": {"action_type": "discrete", "size": 2}}] * 2
    box = info["observation_space"][0]["obs"]
    native = gym.make("CartPole-v1").observation_space
    assert box["space"] == "box" and box["size"] == [4]
    assert np.allclose(box["low"], native.low) and np.allclose(box["high"], native.high)

    reset = trainer.ask({"type": "reset"})
    assert reset["type"] == "reset" and reset["info"] == [{}, {}]
    # --env-seed 3 with 2 instances: instance i's first episode is seeded 3 * 2 + i
    references = [_cartpole(6), _cartpole(7)]
    for observation, reference in zip(reset["obs"], references, strict=True):
        assert np.allclose(observation["obs"], reference.unwrapped.client.observe()["agent"])

    steps = 0
    ended: list[int] = []
    while not ended:
        answer = trainer.ask({"type": "action", "action": [{"action": 1}, {"action": 1}]})
        steps += 1
        expected = [reference.step(1) for reference in references]
        assert answer["type"] == "step" and answer["reward"] == [1.0, 1.0]
        for index, done in enumerate(answer["done"]):
            observation, _, terminated, _, _ = expected[index]
            assert done == terminated
            if done:
                ended.append(index)
                final = answer["info"][index]
                assert np.allclose(final["terminal_observation"]["obs"], observation)
                assert final["TimeLimit.truncated"] is False
                # the instance started its next episode: a pole near upright again
                assert abs(answer["obs"][index]["obs"][2]) < 0.06 < abs(observation[2])
            else:
                assert answer["info"][index] == {}
                assert np.allclose(answer["obs"][index]["obs"], observation)
    assert 5 < steps < 40
    trainer.send({"type": "close"})
    assert game.finish()[0] == 0


def test_a_time_limit_truncates_and_says_so(trainer: FakeTrainer, games: list[Game]) -> None:
    game = _godot_rl(
        games, "rlenv/CartPole-v1", "--port", str(trainer.port), "--max-episode-steps", "3"
    )
    trainer.start()
    trainer.ask({"type": "reset"})
    answers = [
        trainer.ask({"type": "action", "action": [{"action": step % 2}]}) for step in range(3)
    ]
    assert [answer["done"] for answer in answers] == [[False], [False], [True]]
    assert answers[2]["info"][0]["TimeLimit.truncated"] is True
    assert answers[2]["info"][0]["terminal_observation"]["obs"] != answers[2]["obs"][0]["obs"]
    assert trainer.ask({"type": "call", "method": "get_info"}) == {
        "type": "call",
        "returns": [None],
    }
    trainer.close()  # hung up without close: the game ends too, quietly
    assert game.finish()[0] == 0


def test_several_agents_are_several_ai_controllers(trainer: FakeTrainer, games: list[Game]) -> None:
    game = _godot_rl(
        games,
        "rlenv/Pair-v0",
        "--port",
        str(trainer.port),
        "--instances",
        "2",
        "--max-episode-steps",
        "50",
    )
    info = trainer.start()
    assert info["n_agents"] == 4
    assert info["action_space"][0] == {"action": {"action_type": "continuous", "size": 2}}
    reset = trainer.ask({"type": "reset"})
    assert len(reset["obs"]) == 4
    rng = np.random.default_rng(0)
    done_controllers: set[int] = set()
    for _ in range(120):
        actions = [{"action": rng.uniform(-1, 1, 2).tolist()} for _ in range(4)]
        answer = trainer.ask({"type": "action", "action": actions})
        assert len(answer["obs"]) == len(answer["reward"]) == len(answer["done"]) == 4
        for index, (done, final) in enumerate(zip(answer["done"], answer["info"], strict=True)):
            if done:
                done_controllers.add(index)
                assert set(final) == {"terminal_observation", "TimeLimit.truncated"}
                assert set(final["terminal_observation"]) == {"obs"}
    assert done_controllers == {0, 1, 2, 3}  # each episode ends by step 50 at the latest
    trainer.send({"type": "close"})
    assert game.finish()[0] == 0


def test_a_bad_message_ends_the_game_with_a_clear_error(
    trainer: FakeTrainer, games: list[Game]
) -> None:
    game = _godot_rl(games, "rlenv/CartPole-v1", "--port", str(trainer.port))
    trainer.start()
    trainer.send({"type": "action", "action": [{"action": 0}, {"action": 1}]})
    status, stderr = game.finish()
    assert status == 2
    assert "needs a list of 1 action maps (one per AIController)" in stderr


def test_the_launcher_takes_godot_rls_flags(
    trainer: FakeTrainer, games: list[Game], tmp_path: Path
) -> None:
    launcher = tmp_path / "CartPole.x86_64"
    written = _godot_rl(games, "rlenv/CartPole-v1", "--launcher", str(launcher), "--instances", "2")
    assert written.finish()[0] == 0
    # what godot-rl's GodotEnv._launch_env gives an exported game
    game = Game(
        [
            str(launcher),
            f"--port={trainer.port}",
            "--env_seed=0",
            "--disable-render-loop",
            "--headless",
            "--fixed-fps",
            "60",
            "--action_repeat=1",
            "--speedup=8",
            "--repeat_action=1",
        ]
    )
    games.append(game)
    assert trainer.start()["n_agents"] == 2
    reset = trainer.ask({"type": "reset"})
    assert np.allclose(reset["obs"][1]["obs"], _cartpole(1).unwrapped.client.observe()["agent"])
    trainer.send({"type": "close"})
    assert game.finish()[0] == 0


def test_the_launcher_refuses_an_unknown_setting_naming_it(
    trainer: FakeTrainer, games: list[Game], tmp_path: Path
) -> None:
    launcher = tmp_path / "CartPole.x86_64"
    assert _godot_rl(games, "rlenv/CartPole-v1", "--launcher", str(launcher)).finish()[0] == 0
    game = Game([str(launcher), f"--port={trainer.port}", "--no_such_setting=3"])
    games.append(game)
    status, stderr = game.finish()
    assert status == 2 and "no_such_setting" in stderr


def test_godot_arguments_are_read_as_godots_sync_reads_them() -> None:
    assert godot_arguments(["--port=11009", "--headless", "--fixed-fps", "60", "--k=a=b"]) == {
        "port": "11009",
        "headless": "",
        "fixed-fps": "60",
        "k": "a=b",
    }
    with pytest.raises(ValueError, match="no --KEY=VALUE flag"):
        godot_arguments(["11009"])


def test_boxes_are_rescaled_images_are_hex_and_other_spaces_refused() -> None:
    wire = agent_wire(
        spaces.Dict(
            {
                "camera": spaces.Box(0, 255, (2, 2, 3), np.uint8),
                "speed": spaces.Box(-5.0, 5.0, (1,), np.float32),
            }
        ),
        spaces.Dict(
            {"push": spaces.Box(-4.0, 2.0, (2,), np.float32), "jump": spaces.Discrete(3, start=1)}
        ),
    )
    assert wire.observation_space == {
        "camera_2d": {"space": "box", "size": [2, 2, 3]},
        "speed": {"space": "box", "size": [1], "low": [-5.0], "high": [5.0]},
    }
    assert wire.action_space == {
        "push": {"action_type": "continuous", "size": 2},
        "jump": {"action_type": "discrete", "size": 3},
    }
    image = np.arange(12, dtype=np.uint8).reshape(2, 2, 3)
    observed = wire.observe({"camera": image, "speed": np.array([1.5], np.float32)})
    assert bytes.fromhex(observed["camera_2d"]) == image.tobytes()
    assert observed["speed"] == [1.5]
    action = wire.act({"push": [-1.0, 1.0], "jump": 2})
    assert np.array_equal(action["push"], [-4.0, 2.0]) and action["jump"] == 3
    assert np.array_equal(wire.act({"push": [0.0, 7.0], "jump": 0})["push"], [-1.0, 2.0])
    with pytest.raises(GodotWireError, match="an action without \\['jump'\\]"):
        wire.act({"push": [0.0, 0.0]})
    with pytest.raises(GodotWireError, match="has 3 numbers; its size is 2"):
        wire.act({"push": [0.0, 0.0, 0.0], "jump": 0})
    with pytest.raises(GodotWireError, match="carries only Box and Discrete"):
        agent_wire(spaces.MultiBinary(3), spaces.Discrete(2))
    with pytest.raises(GodotWireError, match="decodes as an image"):
        agent_wire(spaces.Dict({"pos2d": spaces.Box(-1, 1, (2,))}), spaces.Discrete(2))


def test_images_travel_as_hex_under_a_2d_key(trainer: FakeTrainer, games: list[Game]) -> None:
    game = _godot_rl(games, "rlenv/Pixels-v0", "--port", str(trainer.port), "--env-seed", "2")
    info = trainer.start()
    space = gym.make("rlenv/Pixels-v0", in_process=True).observation_space
    assert info["observation_space"] == [{"obs_2d": {"space": "box", "size": list(space.shape)}}]
    reset = trainer.ask({"type": "reset"})
    image = np.frombuffer(bytes.fromhex(reset["obs"][0]["obs_2d"]), np.uint8).reshape(space.shape)
    reference = gym.make("rlenv/Pixels-v0", in_process=True)
    assert np.array_equal(image, reference.reset(seed=2)[0])
    trainer.send({"type": "close"})
    assert game.finish()[0] == 0
