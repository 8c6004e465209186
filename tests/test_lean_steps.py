"""The lean path of ``steps`` answers exactly as the general path does, failures included.

Two hosts of the same environment get the same ``steps`` requests: one serves them on the lean
path (``Host.lean``), the other, with it switched off, through each instance's hooks and
answer, stacked by ``Columns``. Every answer must be the same: observations byte for byte,
rewards, flags, ticks, infos, and which rows failed and why.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pytest

from examples.cartpole import CartPoleEnvironment
from examples.faulty import (
    CountingEnvironment,
    CountingWorld,
    FaultyEnvironment,
    TickAgent,
    WrongShapeEnvironment,
)
from rlenv import RLEnvironment
from rlenv_client import LocalClient

K = 6


class InfoCartPole(CartPoleEnvironment):
    """CartPole whose info says where the cart is (and, once, holds a bin key)."""

    def _get_info(self) -> dict[Any, Any]:
        x = float(self.world.cart.position.x)
        return {"x": x, b"raw": 1} if 0.0123 < x < 0.0124 else {"x": x}


class RespondingCartPole(CartPoleEnvironment):
    """Overrides ``_send_response``: only the general path may serve it."""

    def _send_response(self, observation_request: Mapping[str, Any] | None) -> None:
        super()._send_response(observation_request)


class SharedBufferAgent(TickAgent):
    """Writes its observation into one array that every instance shares, and returns it."""

    buffer = np.zeros(1, np.float64)

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        self.buffer[:] = super().get_data(observation_request)
        return self.buffer


class SharedBufferCounting(RLEnvironment):
    """Counting, its agents sharing one observation array: a row's NaN is gone by the next's."""

    def __init__(self) -> None:
        super().__init__("Counting", repeat_action=50)
        self.add_child(SharedBufferAgent())
        self.add_child(CountingWorld())


def _clients(environment: type) -> tuple[LocalClient, LocalClient]:
    lean, general = (LocalClient(environment, instances=K) for _ in range(2))
    general.host.lean = None
    assert lean.host.lean is not None
    return lean, general


def _answer(client: LocalClient, actions: Any, reset: np.ndarray) -> dict[str, Any]:
    client.send_steps(actions, reset, 2)
    answer = client.receive_steps()
    errors = [
        None if e is None else (e.code, e.message.split("\n")[0])
        for e in answer.errors or [None] * K
    ]
    return {
        "observation": np.asarray(answer.observation).tobytes(),
        "reward": answer.reward.tolist(),
        "terminated": answer.terminated.tolist(),
        "truncated": answer.truncated.tolist(),
        "frames": answer.frames.tolist(),
        "info": list(answer.info),
        "errors": errors,
    }


@pytest.mark.parametrize(
    ("environment", "actions"),
    [
        (CartPoleEnvironment, lambda rng: rng.uniform(-1, 1, (K, 1)).astype(np.float32)),
        (InfoCartPole, lambda rng: rng.uniform(-1, 1, (K, 1)).astype(np.float32)),
        (CountingEnvironment, lambda rng: rng.choice(2, K, p=[0.9, 0.1])),  # 1: NaN observed
        (SharedBufferCounting, lambda rng: rng.choice(2, K, p=[0.8, 0.2])),
        (FaultyEnvironment, lambda rng: rng.choice(3, K, p=[0.8, 0.1, 0.1])),  # 1, 2 raise
        (WrongShapeEnvironment, lambda rng: rng.choice(3, K)),
    ],
    ids=["cartpole", "info", "counting", "shared buffer", "faulty", "wrong shape"],
)
def test_the_lean_path_answers_as_the_general_path(environment: type, actions: Any) -> None:
    lean, general = _clients(environment)
    rng = np.random.default_rng(7)
    for client in (lean, general):
        client.send_batch([client.reset_request(seed=index) for index in range(K)])
        client.receive_batch()
    reset = np.ones(K, np.bool_)  # every episode starts in a steps request too
    failures = 0
    for _ in range(300):
        batch = actions(rng)
        answers = [_answer(client, batch, reset) for client in (lean, general)]
        assert answers[0] == answers[1]
        failed = np.array([error is not None for error in answers[0]["errors"]])
        failures += failed.sum()
        reset = np.array(answers[0]["terminated"]) | np.array(answers[0]["truncated"]) | failed
    assert [i.stats.since(0)["steps"] for i in lean.host.instances] == [
        i.stats.since(0)["steps"] for i in general.host.instances
    ]
    if environment in (
        CountingEnvironment,
        SharedBufferCounting,
        FaultyEnvironment,
        WrongShapeEnvironment,
    ):
        assert failures > 0  # the failing rows were compared too


def test_the_lean_path_serves_only_what_it_can() -> None:
    assert LocalClient(CartPoleEnvironment, instances=2).host.lean is not None
    assert LocalClient(RespondingCartPole, instances=2).host.lean is None
    assert LocalClient("examples.pair:PairEnvironment", instances=2).host.lean is None
    assert LocalClient("examples.faulty:FaultyEnvironment", instances=2).host.lean is not None
