"""An instance whose code raised is rebuilt at the next reset; reset options are checked.

``examples.faulty:BrittleEnvironment``'s world removes its physics in ``reset`` and then, with
``options={"fail": True}``, raises: no reset of the same objects can cure that.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from conftest import Serve

from examples.faulty import BrittleAgent, BrittleEnvironment, BrittleWorld
from rlenv import RLEnvironment
from rlenv.protocol.errors import ErrorCode, RemoteError, RequestError
from rlenv_client import BaseClient, Client, LocalClient

TARGET = "examples.faulty:BrittleEnvironment"
ACTIONS = [1, 0, 1, 1, 0]


def _episode(client: BaseClient, seed: int) -> tuple[list[np.ndarray], dict[str, Any]]:
    observation, info = client.reset(seed=seed)
    observations = [observation]
    for action in ACTIONS:
        observations.append(client.step(action)[0])
    return observations, info


def _break(client: BaseClient) -> None:
    client.reset(seed=3)
    client.step(1)
    with pytest.raises(RemoteError) as error:
        client.reset(options={"fail": True})
    assert error.value.code == ErrorCode.ENVIRONMENT_ERROR


def test_a_served_instance_is_rebuilt_after_a_failed_reset(serve: Serve) -> None:
    broken, fresh = serve(TARGET), serve(TARGET)
    with (
        Client(broken.host, broken.port, timeout=10) as client,
        Client(fresh.host, fresh.port, timeout=10) as reference,
    ):
        client.configure(repeat_action=3)
        reference.configure(repeat_action=3)
        _break(client)
        observations, info = _episode(client, seed=7)
        expected, reference_info = _episode(reference, seed=7)
        assert info["rebuilt"] == "ValueError: this level is refused (asked with options['fail'])"
        assert "rebuilt" not in reference_info
        assert all(np.array_equal(a, b) for a, b in zip(observations, expected, strict=True))
        assert client.step(0)[4]["frames"] == 3  # the configuration carried over
        _, info = client.reset(seed=7)
        assert "rebuilt" not in info  # once


def test_an_in_process_instance_is_rebuilt_and_its_client_sees_the_new_environment() -> None:
    with LocalClient(BrittleEnvironment) as client, LocalClient(BrittleEnvironment) as reference:
        before = client.environment
        _break(client)
        observations, info = _episode(client, seed=11)
        assert "rebuilt" in info and client.environment is not before
        assert client.environment.is_inside_tree() and not before.is_inside_tree()
        expected, _ = _episode(reference, seed=11)
        assert all(np.array_equal(a, b) for a, b in zip(observations, expected, strict=True))


def test_a_reset_without_a_seed_after_the_rebuild_continues_the_generator() -> None:
    with LocalClient(BrittleEnvironment) as client, LocalClient(BrittleEnvironment) as reference:
        client.reset(seed=5)
        with pytest.raises(RemoteError):
            client.reset(options={"fail": True})
        reference.reset(seed=5)  # the failed reset drew nothing from the generator
        assert np.array_equal(client.reset()[0], reference.reset()[0])


def test_in_steps_one_instance_is_rebuilt_and_its_neighbours_go_on(serve: Serve) -> None:
    server, fresh = (serve(TARGET, args=("--instances", "3")) for _ in range(2))
    with (
        Client(server.host, server.port, timeout=10) as client,
        Client(fresh.host, fresh.port, timeout=10) as reference,
    ):
        _one_rebuilt_in_steps(client, reference)


class _RespondingEnvironment(BrittleEnvironment):
    """Answers through its own ``_send_response``: steps take the general path."""

    def _send_response(self, observation_request: Any) -> None:
        super()._send_response(observation_request)


def test_in_steps_on_the_general_path_one_instance_is_rebuilt() -> None:
    with (
        LocalClient(_RespondingEnvironment, instances=3) as client,
        LocalClient(_RespondingEnvironment, instances=3) as reference,
    ):
        assert client.host is not None and client.host.lean is None
        _one_rebuilt_in_steps(client, reference)


def _one_rebuilt_in_steps(client: BaseClient, reference: BaseClient) -> None:
    """Instance 1 of ``client`` fails and is rebuilt in a steps request; 0 and 2 go on."""
    for each in (client, reference):
        each.send_batch([each.reset_request(seed=seed) for seed in (1, 2, 3)])
        each.receive_batch()
    client.send_batch([None, client.reset_request(options={"fail": True}), None])
    assert client.receive_batch()[1].code == ErrorCode.ENVIRONMENT_ERROR
    reference.send_batch([None, reference.reset_request(seed=2), None])  # 1 starts again
    reference.receive_batch()
    client.send_steps(np.array([1, 0, 1]), reset=np.array([False, True, False]))
    answer = client.receive_steps()
    reference.send_steps(np.array([1, 0, 1]), reset=np.array([False, True, False]))
    expected = reference.receive_steps()
    assert answer.errors is None
    assert answer.info[1]["rebuilt"].startswith("ValueError")
    assert "rebuilt" not in answer.info[0] and "rebuilt" not in answer.info[2]
    for row in (0, 2):  # the neighbours stepped as if nothing happened
        assert np.array_equal(answer.observation[row], expected.observation[row])
    for _ in range(3):
        client.send_steps(np.array([0, 1, 1]))
        reference.send_steps(np.array([0, 1, 1]))
        assert np.array_equal(
            client.receive_steps().observation[[0, 2]],
            reference.receive_steps().observation[[0, 2]],
        )


class _KeptEnvironment(BrittleEnvironment):
    """Opts out: the same objects stay, broken."""

    rebuild_after_error = False


def test_an_environment_may_opt_out_of_being_rebuilt() -> None:
    with LocalClient(_KeptEnvironment) as client:
        before = client.environment
        _break(client)
        with pytest.raises(RemoteError, match="Physics"):
            client.reset()
        assert client.environment is before


def test_unknown_reset_options_are_refused_naming_the_known_ones(serve: Serve) -> None:
    server = serve("examples.plinko:PlinkoEnvironment")
    with Client(server.host, server.port, timeout=10) as client:
        with pytest.raises(RemoteError) as error:
            client.reset(seed=1, options={"levle": 1})
        assert error.value.code == ErrorCode.BAD_REQUEST
        assert error.value.message == (
            "reset.options: PlinkoEnvironment has no reset option 'levle'; it accepts level"
        )
        client.reset(seed=1)  # still serving
        level = client.get_property("World", "level")
        client.reset(seed=2, options={"level": level})


def test_declared_options_are_checked_in_process_and_undeclared_ones_stay_free() -> None:
    with LocalClient("examples.classic_cartpole:ClassicCartPoleEnvironment") as client:
        with pytest.raises(RemoteError, match="has no reset option 'lwo'; it accepts low, high"):
            client.reset(options={"lwo": -0.1})
        client.reset(options={"low": -0.01, "high": 0.01})
    with LocalClient("examples.cartpole:CartPoleEnvironment") as client:
        client.reset(options={"anything": 1})  # declares none: any options, as before


class _RefusingWorld(BrittleWorld):
    """Brittle's world, refusing ``options["refuse"]`` half way through its reset."""

    def reset(self, options: Any) -> None:
        super().reset({})
        if options.get("refuse"):
            raise RequestError(ErrorCode.BAD_REQUEST, "this reset is refused half way")


class _Refusing(RLEnvironment):
    reset_options = ("refuse",)

    def __init__(self) -> None:
        super().__init__("Refusing", repeat_action=2)
        self.add_child(BrittleAgent())
        self.add_child(_RefusingWorld())


def test_a_reset_the_environment_refuses_starts_no_episode_and_the_next_one_rebuilds() -> None:
    client = LocalClient(_Refusing)
    try:
        client.reset(seed=1)
        client.step(1)
        with pytest.raises(RemoteError, match="refused half way") as refused:
            client.reset(seed=2, options={"refuse": True})
        assert refused.value.code == ErrorCode.BAD_REQUEST
        with pytest.raises(RemoteError, match="the reset was refused") as stepped:
            client.step(1)
        assert stepped.value.code == ErrorCode.RESET_REQUIRED
        _, info = client.reset(seed=2)
        assert "refused half way" in info["rebuilt"]
        assert client.step(1)[0].shape == (4,)
        assert "rebuilt" not in client.reset(seed=2)[1]
    finally:
        client.close()
