"""``rlenv dm-env-rpc``: dm_env_rpc's own compliance tests, and episodes through its adaptor.

The server runs as users run it (``python -m rlenv dm-env-rpc TARGET --port 0``, a subprocess
whose worlds are ``rlenv serve`` subprocesses); the agents' side is the dm_env_rpc wheel's
(``create_secure_channel_and_connect``, ``DmEnvAdaptor``, ``compliance``), unchanged.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
import pytest

import rlenv_client  # noqa: F401  (registers the ids)
from rlenv_client.client import Client
from rlenv_client.launcher import ServerProcess, end_process

pytest.importorskip("dm_env_rpc")
pytest.importorskip("grpc")

from dm_env_rpc.v1 import (  # noqa: E402
    compliance,
    connection,
    dm_env_adaptor,
    dm_env_rpc_pb2,
    error,
    tensor_spec_utils,
    tensor_utils,
)

pytestmark = pytest.mark.dm_env_rpc

States = dm_env_rpc_pb2.EnvironmentStateType


class Served:
    """``rlenv dm-env-rpc TARGET --port 0`` in a subprocess; :meth:`close` ends it."""

    def __init__(self, target: str, *args: str) -> None:
        self._stderr = tempfile.TemporaryFile()
        self.process = subprocess.Popen(
            [sys.executable, "-m", "rlenv", "dm-env-rpc", target, "--port", "0", *args],
            stdout=subprocess.PIPE,
            stderr=self._stderr,
            text=True,
        )
        line = self.process.stdout.readline()  # type: ignore[union-attr]
        if not line.startswith("listening on "):
            self.close()
            raise RuntimeError(f"rlenv dm-env-rpc did not start ({line!r}): {self.stderr()}")
        self.address = line.strip().removeprefix("listening on ")

    def connect(self) -> connection.Connection:
        return connection.create_secure_channel_and_connect(self.address, timeout=30)

    def stderr(self) -> str:
        self._stderr.seek(0)
        return self._stderr.read().decode(errors="replace")

    def close(self) -> None:
        end_process(self.process, 10.0)
        self._stderr.close()


SERVED: dict[str, Served] = {}
TARGETS = ("rlenv/CartPole-v1", "rlenv/Reacher-v0")


def setup_module() -> None:
    for target in TARGETS:
        SERVED[target] = Served(target)


def teardown_module() -> None:
    while SERVED:
        SERVED.popitem()[1].close()


# --- dm_env_rpc's compliance tests, on each target -------------------------------------------


class _OnTarget:
    """A compliance test case's connection to :data:`SERVED`'s server and a world there."""

    __test__ = False  # the classes _suites makes are the tests
    target: ClassVar[str]
    joins: ClassVar[bool] = False  # whether each test starts joined (Step's do)

    @classmethod
    def setUpClass(cls) -> None:
        super().setUpClass()  # type: ignore[misc]
        cls._connection = SERVED[cls.target].connect()
        cls._world = cls._connection.send(dm_env_rpc_pb2.CreateWorldRequest()).world_name

    @classmethod
    def tearDownClass(cls) -> None:
        cls._connection.send(dm_env_rpc_pb2.LeaveWorldRequest())
        cls._connection.send(dm_env_rpc_pb2.DestroyWorldRequest(world_name=cls._world))
        cls._connection.close()
        super().tearDownClass()  # type: ignore[misc]

    def setUp(self) -> None:
        super().setUp()  # type: ignore[misc]
        if self.joins:
            self._specs = self._join()

    def tearDown(self) -> None:
        self._connection.send(dm_env_rpc_pb2.LeaveWorldRequest())
        super().tearDown()  # type: ignore[misc]

    @property
    def connection(self) -> connection.Connection:
        return self._connection

    @property
    def world_name(self) -> str:
        return self._world

    @property
    def specs(self) -> Any:
        return self._specs

    def _join(self) -> Any:
        request = dm_env_rpc_pb2.JoinWorldRequest(world_name=self._world)
        return self._connection.send(request).specs


class _CreateDestroy(compliance.CreateDestroyWorld):
    __test__ = False  # the classes _suites makes are the tests
    target: ClassVar[str]

    @classmethod
    def setUpClass(cls) -> None:
        super().setUpClass()
        cls._connection = SERVED[cls.target].connect()

    @classmethod
    def tearDownClass(cls) -> None:
        cls._connection.close()
        super().tearDownClass()

    @property
    def connection(self) -> connection.Connection:
        return self._connection

    @property
    def required_world_settings(self) -> dict[str, Any]:
        return {}

    @property
    def invalid_world_settings(self) -> dict[str, Any]:
        return {
            "seed": tensor_utils.pack_tensor("seven"),
            "no_such_setting": tensor_utils.pack_tensor(1),
        }

    @property
    def has_multiple_world_support(self) -> bool:
        return True


class _JoinLeave(_OnTarget, compliance.JoinLeaveWorld):
    @property
    def invalid_join_settings(self) -> dict[str, Any]:
        return {"no_such_setting": tensor_utils.pack_tensor(1)}


class _Reset(_OnTarget, compliance.Reset):
    def join_world(self) -> Any:
        return self._join()


class _ResetWorld(_OnTarget, compliance.ResetWorld):
    pass


class _Step(_OnTarget, compliance.Step):
    joins = True

    def join_world(self) -> Any:
        return self._join()


def _suites() -> dict[str, type]:
    """Every compliance case on every target, as classes pytest collects."""
    classes = {}
    for target in TARGETS:
        prefix = "Test" + target.removeprefix("rlenv/").split("-")[0]
        for case in (_CreateDestroy, _JoinLeave, _Reset, _ResetWorld, _Step):
            name = prefix + case.__name__.removeprefix("_")
            classes[name] = type(name, (case,), {"target": target, "__test__": True})
    return classes


globals().update(_suites())


# --- episodes as the adaptor plays them --------------------------------------------------------


def _joined(target: str, **settings: Any) -> tuple[Any, connection.Connection, str]:
    link = SERVED[target].connect()
    env, world = dm_env_adaptor.create_and_join_world(
        link, create_world_settings=settings, join_world_settings={}
    )
    return env, link, world


def _leave(link: connection.Connection, world: str) -> None:
    link.send(dm_env_rpc_pb2.LeaveWorldRequest())
    link.send(dm_env_rpc_pb2.DestroyWorldRequest(world_name=world))
    link.close()


def test_an_episode_is_gymnasiums_bit_for_bit_and_ends_terminated() -> None:
    env, link, world = _joined("rlenv/CartPole-v1", seed=7)
    reference = gym.make("rlenv/CartPole-v1")
    try:
        first = env.reset()
        expected, _ = reference.reset(seed=7)
        assert first.first()
        np.testing.assert_array_equal(first.observation["observation"], expected)
        assert first.observation["observation"].dtype == expected.dtype
        rng = np.random.default_rng(0)
        while True:
            action = int(rng.integers(2))
            step = env.step({"action": action})
            expected, reward, terminated, truncated, _ = reference.step(action)
            np.testing.assert_array_equal(step.observation["observation"], expected)
            assert step.reward == reward
            if terminated or truncated:
                break
            assert step.mid() and step.discount == 1.0
        assert terminated and step.last() and step.discount == 0.0  # TERMINATED
        # The next step starts the next episode, continuing the seed's sequence as gymnasium.
        again = env.step({"action": 0})
        expected, _ = reference.reset()
        assert again.first()
        np.testing.assert_array_equal(again.observation["observation"], expected)
    finally:
        reference.close()
        _leave(link, world)


def test_the_time_limit_interrupts_with_discount_one_and_reset_takes_a_seed() -> None:
    env, link, world = _joined("rlenv/Reacher-v0")
    reference = gym.make("rlenv/Reacher-v0")
    seed = {"seed": tensor_utils.pack_tensor(3)}
    try:
        link.send(dm_env_rpc_pb2.ResetRequest(settings=seed))
        first = link.send(dm_env_rpc_pb2.StepRequest(requested_observations=[1]))
        expected, _ = reference.reset(seed=3)
        observation = tensor_utils.unpack_tensor(first.observations[1])
        np.testing.assert_array_equal(observation, expected)
        action = {1: tensor_utils.pack_tensor(np.zeros(2, np.float32))}
        discount = _uid(env, "discount")
        states = [
            link.send(dm_env_rpc_pb2.StepRequest(actions=action, requested_observations=[discount]))
            for _ in range(200)  # Reacher-v0's time limit
        ]
        assert {response.state for response in states[:-1]} == {States.RUNNING}
        assert states[-1].state == States.INTERRUPTED  # truncated: bootstrap from it
        assert tensor_utils.unpack_tensor(states[-1].observations[discount]) == 1.0
        link.send(dm_env_rpc_pb2.ResetRequest(settings=seed))  # the same seed, the same start
        again = link.send(dm_env_rpc_pb2.StepRequest(requested_observations=[1]))
        assert again.state == States.RUNNING
        assert again.observations[1] == first.observations[1]
    finally:
        reference.close()
        _leave(link, world)


def test_refusals_name_what_is_wrong_and_the_world_goes_on() -> None:
    env, link, world = _joined("rlenv/CartPole-v1")
    try:
        env.reset()
        with pytest.raises(error.DmEnvRpcError, match="out of its bounds"):
            link.send(dm_env_rpc_pb2.StepRequest(actions={1: tensor_utils.pack_tensor(2)}))
        with pytest.raises(error.DmEnvRpcError, match="float64, its spec says int64"):
            link.send(dm_env_rpc_pb2.StepRequest(actions={1: tensor_utils.pack_tensor(1.0)}))
        with pytest.raises(error.DmEnvRpcError, match="no observation has uid 99"):
            link.send(dm_env_rpc_pb2.StepRequest(requested_observations=[99]))
        with pytest.raises(error.DmEnvRpcError, match="seed must be a non-negative integer"):
            link.send(dm_env_rpc_pb2.ResetRequest(settings={"seed": tensor_utils.pack_tensor(-1)}))
        with pytest.raises(error.DmEnvRpcError, match=r"no world .*nowhere"):
            link.send(dm_env_rpc_pb2.ResetWorldRequest(world_name="nowhere"))
        huge = tensor_utils.pack_tensor(np.array([0], np.float32))
        huge.shape[:] = [100_000, 100_000]  # one element, broadcast: refused before unpacking
        with pytest.raises(error.DmEnvRpcError, match="has shape"):
            link.send(dm_env_rpc_pb2.StepRequest(actions={1: huge}))
        seed = tensor_utils.pack_tensor(np.array([1], np.int64))
        seed.shape[:] = [100_000, 100_000]
        with pytest.raises(error.DmEnvRpcError, match="must be a scalar"):
            link.send(dm_env_rpc_pb2.ResetRequest(settings={"seed": seed}))
        with pytest.raises(error.DmEnvRpcError, match="is joined"):
            link.send(dm_env_rpc_pb2.DestroyWorldRequest(world_name=world))
        assert env.step({"action": 1}).mid()  # still serving
    finally:
        _leave(link, world)


def test_one_connection_at_a_time_joins_a_world() -> None:
    env, link, world = _joined("rlenv/CartPole-v1")
    other = SERVED["rlenv/CartPole-v1"].connect()
    try:
        with pytest.raises(error.DmEnvRpcError, match="joined by another connection"):
            other.send(dm_env_rpc_pb2.JoinWorldRequest(world_name=world))
        link.send(dm_env_rpc_pb2.LeaveWorldRequest())
        other.send(dm_env_rpc_pb2.JoinWorldRequest(world_name=world))
        other.send(dm_env_rpc_pb2.LeaveWorldRequest())
    finally:
        other.close()
        _leave(link, world)


def test_several_agents_act_and_are_rewarded_each() -> None:
    served = Served("rlenv/Pair-v0")
    reference = gym.make("rlenv/Pair-v0")
    try:
        link = served.connect()
        env, world = dm_env_adaptor.create_and_join_world(
            link, create_world_settings={"seed": 5}, join_world_settings={}, nested_tensors=False
        )
        names = {spec.name for spec in env.action_spec().values()}
        assert names == {"Red", "Blue"}
        assert {"Red", "Blue", "rewards.Red", "rewards.Blue"} <= set(env.observation_spec())
        first = env.reset()
        expected, _ = reference.reset(seed=5)
        for agent in ("Red", "Blue"):
            np.testing.assert_array_equal(first.observation[agent], expected[agent])
        action = {"Red": np.full(2, 0.5, np.float32), "Blue": np.full(2, -0.5, np.float32)}
        step = env.step(action)
        expected, reward, _, _, info = reference.step(action)
        assert step.reward == reward
        for agent in ("Red", "Blue"):
            np.testing.assert_array_equal(step.observation[agent], expected[agent])
            assert step.observation[f"rewards.{agent}"] == info["agents"][agent]["reward"]
        # An agent a step leaves out repeats its last action.
        step = env.step({"Red": np.zeros(2, np.float32)})
        action["Red"] = np.zeros(2, np.float32)
        expected, *_ = reference.step(action)
        np.testing.assert_array_equal(step.observation["Blue"], expected["Blue"])
        _leave(link, world)
    finally:
        reference.close()
        served.close()


def test_a_running_server_is_a_target_too() -> None:
    with ServerProcess("examples.classic_cartpole:ClassicCartPoleEnvironment") as server:
        served = Served(f"{server.host}:{server.port}")
        try:
            link = served.connect()
            env, world = dm_env_adaptor.create_and_join_world(
                link, create_world_settings={"seed": 2}, join_world_settings={}
            )
            first = env.reset()
            assert first.first() and env.step({"action": 1}).mid()
            _leave(link, world)  # its connection closed: another client may control the server
            with Client(server.host, server.port) as reference:
                expected, _ = reference.reset(seed=2)
            np.testing.assert_array_equal(first.observation["observation"], expected)
        finally:
            served.close()


def test_a_target_that_cannot_load_stops_the_command_with_its_reason() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "rlenv", "dm-env-rpc", "no_such_module:Thing", "--port", "0"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2
    assert result.stderr.startswith("rlenv dm-env-rpc: ") and "no_such_module" in result.stderr


def _uid(env: Any, name: str) -> int:
    return next(
        uid for uid, spec in env._dm_env_rpc_specs.observations.items() if spec.name == name
    )


def test_every_kind_of_space_is_a_tensor_a_leaf_and_actions_fold_back() -> None:
    from gymnasium import spaces

    from rlenv_tools._dm_env_rpc_specs import ActionRefused, Specs

    action_space = spaces.Dict(
        {
            "move": spaces.Box(-1.0, 2.0, (2,), np.float32),
            "pick": spaces.Tuple((spaces.Discrete(3, start=-1), spaces.MultiBinary(4))),
            "gear": spaces.MultiDiscrete([2, 5]),
        }
    )
    observation_space = spaces.Box(0, 255, (4, 4, 3), np.uint8)
    specs = Specs(action_space, observation_space, ["Agent"])
    names = {leaf.name: leaf for leaf in specs.actions}
    assert set(names) == {"action.move", "action.pick.0", "action.pick.1", "action.gear"}
    pick = tensor_spec_utils.bounds(names["action.pick.0"].spec)
    assert (pick.min, pick.max) == (-1, 1)
    assert tensor_spec_utils.bounds(names["action.gear"].spec).max.tolist() == [1, 4]
    assert names["action.pick.1"].dtype == np.int8
    sent = {
        names["action.move"].uid: tensor_utils.pack_tensor(np.array([0.5, 2.0], np.float32)),
        names["action.pick.0"].uid: tensor_utils.pack_tensor(np.int64(-1)),
    }
    last: dict[int, Any] = {}
    action = specs.action(sent, last)
    assert action_space.contains(action)
    assert action["pick"][0] == -1 and action["pick"][1].tolist() == [0, 0, 0, 0]
    np.testing.assert_array_equal(action["move"], [0.5, 2.0])
    again = specs.action({}, last)  # nothing sent: the last actions repeat
    np.testing.assert_array_equal(again["move"], [0.5, 2.0])
    with pytest.raises(ActionRefused, match="out of its bounds"):
        specs.action({names["action.gear"].uid: tensor_utils.pack_tensor(np.array([0, 5]))}, last)
    image = specs.observations[0]
    assert image.name == "observation" and image.dtype == np.uint8
    frame = observation_space.sample()
    tensors = specs.observation_tensors([image.uid], frame, {})
    np.testing.assert_array_equal(tensor_utils.unpack_tensor(tensors[image.uid]), frame)
    with pytest.raises(ValueError, match="cannot carry a Text space"):
        Specs(spaces.Text(5), observation_space, ["Agent"])
