"""examples.hunt: prey that appear and are caught, two decision periods, over a real server."""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
import pytest
from api_warnings import warnings_of
from conftest import Serve
from gymnasium.utils.env_checker import check_env

from examples.hunt import HUNTER, PREY, TARGET, Hunter, Prey
from rlenv_client import Client

PREY_DRIVEN = [argument for name in PREY for argument in ("--policy", f"{name}=heuristic")]
_hunter, _prey = Hunter(), Prey(PREY[0], np.zeros(2))


def _heuristic(name: str, observation: np.ndarray) -> np.ndarray:
    return (_hunter if name == HUNTER else _prey).heuristic(observation)


def _episode(client: Client, seed: int) -> dict[str, Any]:
    """One episode, every agent by its heuristic: each agent's answers as (tick, outcome)."""
    observation, _ = client.reset(seed=seed)
    seen: dict[str, list[tuple[int, dict[str, Any]]]] = {name: [] for name in observation}
    starting, tick = list(observation), 0
    while True:
        action = {name: _heuristic(name, value) for name, value in observation.items()}
        observation, _, terminated, truncated, info = client.step(action)
        tick += info["frames"]
        assert list(observation) == list(info["agents"])
        for name, outcome in info["agents"].items():
            seen.setdefault(name, []).append((tick, outcome))
        if terminated or truncated:
            return {"starting": starting, "seen": seen, "ticks": tick}


def test_the_hello_declares_the_hunter_and_eight_prey(serve: Serve) -> None:
    server = serve(TARGET)
    with Client(server.host, server.port, timeout=10) as client:
        hello = client.hello
        assert hello.possible_agents == {HUNTER: "Hunter", **dict.fromkeys(PREY, "Prey")}
        assert tuple(hello.agents) == (HUNTER, *PREY)
        assert client.observation_space[HUNTER].shape == (13,)
        assert client.observation_space["Prey8"].shape == (8,)
        assert client.action_space["Prey8"] == client.action_space[HUNTER]
    assert Hunter.decision_period == 4 and Prey.decision_period == 8


def test_prey_join_and_leave_while_each_role_decides_at_its_pace(serve: Serve) -> None:
    server = serve(TARGET)
    caught = joined = 0
    with Client(server.host, server.port, timeout=10) as client:
        for seed in range(2):
            episode = _episode(client, seed)
            assert episode["starting"] == [HUNTER, "Prey1", "Prey2"]
            hunter = episode["seen"][HUNTER]
            assert all(tick % 4 == 0 for tick, _ in hunter[:-1])  # every 4 ticks
            assert [tick for tick, _ in hunter[:5]] == [4, 8, 12, 16, 20]
            catches = 0
            for name, answers in episode["seen"].items():
                if name == HUNTER or not answers:
                    continue
                flags = [(o["terminated"], o["truncated"]) for _, o in answers]
                assert not any(any(pair) for pair in flags[:-1])  # one final transition, last
                offset = 2 * (PREY.index(name) % 4)
                first = 0 if name in episode["starting"] else 1
                if first:
                    assert answers[0][1]["reward"] is None  # joined: no reward yet
                    joined += 1
                decided = [tick for tick, _ in answers[first:-1]]
                assert all((tick - offset) % 8 == 0 for tick in decided)  # every 8, staggered
                if flags[-1] == (True, False):
                    catches += 1
                    assert answers[-1][1]["reward"] < 0.0  # the -1 of the catch
            rewards = sum(o["reward"] for _, o in hunter)
            assert rewards == pytest.approx(catches - 0.005 * episode["ticks"])
            caught += catches
    assert caught >= 2 and joined >= 2


def _hunt(client: Client, seed: int, act: Any) -> int:
    """Prey the hunter played by ``act`` catches in one episode, the prey driven by the server."""
    observation, _ = client.reset(seed=seed)
    caught, terminated, truncated = 0, False, False
    while not (terminated or truncated):
        action = {HUNTER: act(observation[HUNTER])} if HUNTER in observation else {}
        observation, _, terminated, truncated, info = client.step(action)
        caught += sum(
            outcome["terminated"] for name, outcome in info["agents"].items() if name != HUNTER
        )
    return caught


def test_the_scripted_hunter_catches_prey_that_a_random_one_misses(serve: Serve) -> None:
    server = serve(TARGET, args=PREY_DRIVEN)
    rng = np.random.default_rng(0)
    with Client(server.host, server.port, timeout=10) as client:
        assert client.hello.driven == PREY
        scripted = [_hunt(client, seed, _hunter.heuristic) for seed in range(3)]
        random = [
            _hunt(client, seed, lambda _: rng.uniform(-1, 1, 2).astype(np.float32))
            for seed in range(3)
        ]
    assert min(scripted) >= 4 and sum(random) < sum(scripted)


def test_gym_make_with_the_prey_driven_is_the_hunters_env() -> None:
    env = gymnasium.make("rlenv/Hunt-v0", server_args=PREY_DRIVEN)
    try:
        assert list(env.observation_space) == list(env.action_space) == [HUNTER]
        assert warnings_of(lambda: check_env(env.unwrapped)) == []
    finally:
        env.close()
