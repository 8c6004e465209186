"""examples.swarm: a flock of 64 as one RLAgentGroup, and as 64 RLAgent nodes, over real servers."""

from __future__ import annotations

import re
from typing import Any

import gymnasium
import numpy as np
from api_warnings import warnings_of
from conftest import Serve
from gymnasium.utils import seeding
from gymnasium.utils.env_checker import check_env

from examples.swarm import (
    GROUP,
    JOIN_TICKS,
    MEMBERS,
    NODE_TARGETS,
    TARGET,
    member_name,
    starting,
)
from examples.swarm.scene import SwarmFloor, steer
from rlenv_client import Client
from rlenv_tools._swarm_bench import measure_swarm, summary_line, swarm_line

STEPS = 60  # 240 ticks: every member that joins has joined, the first are home


def _nodes_action(flock: np.ndarray, observation: dict[str, Any]) -> dict[str, np.ndarray]:
    """The group's action as the per-node version takes it: a row for each member asked."""
    return {name: flock[int(name.removeprefix("Member"))] for name in observation}


def test_the_group_and_the_nodes_move_the_discs_bit_for_bit_alike(serve: Serve) -> None:
    group_server, nodes_server = serve(TARGET), serve(NODE_TARGETS[MEMBERS])
    rng = np.random.default_rng(3)
    with (
        Client(group_server.host, group_server.port, timeout=30, world_data=True) as group,
        Client(nodes_server.host, nodes_server.port, timeout=30, world_data=True) as nodes,
    ):
        flock, info = group.reset(seed=11)
        single, node_info = nodes.reset(seed=11)
        assert np.array_equal(info["world"]["bodies"], node_info["world"]["bodies"], equal_nan=True)
        assert sorted(single) == sorted(member_name(slot) for slot in range(starting(MEMBERS)))
        left = joined = 0
        for _ in range(STEPS):
            action = steer(flock[GROUP]) + rng.normal(0.0, 0.3, (MEMBERS, 2)).astype(np.float32)
            action = np.clip(action, -1.0, 1.0)
            flock, _, _, _, info = group.step({GROUP: action})
            single, _, _, _, node_info = nodes.step(_nodes_action(action, single))
            bodies = info["world"]["bodies"]
            assert np.array_equal(bodies, node_info["world"]["bodies"], equal_nan=True)
            outcome = info["agents"][GROUP]
            rows = np.flatnonzero(outcome["active"])
            assert sorted(single) == sorted(member_name(slot) for slot in rows.tolist())
            for slot in rows.tolist():
                mine = node_info["agents"][member_name(slot)]
                assert np.array_equal(flock[GROUP][slot], single[member_name(slot)])
                assert (mine["terminated"], mine["truncated"]) == (
                    outcome["terminated"][slot],
                    outcome["truncated"][slot],
                )
                if not outcome["joined"][slot]:
                    assert mine["reward"] == outcome["reward"][slot]
            left += int(outcome["terminated"].sum())
            joined += int(outcome["joined"].sum())
            assert not flock[GROUP][~outcome["active"]].any()  # rows not reported are zeros
    assert joined == MEMBERS - starting(MEMBERS)  # everyone who waited joined
    assert left >= MEMBERS // 2  # and members reached the nest and left the room (51 of 64)


def _episode(client: Client, seed: int, act: Any) -> tuple[float, int, int]:
    """One episode: the flock's return (summed over members), members home, steps."""
    observation, _ = client.reset(seed=seed)
    total, home, steps = 0.0, 0, 0
    while True:
        observation, reward, terminated, truncated, info = client.step(
            {GROUP: act(observation[GROUP])}
        )
        total += reward
        home += int(info["agents"][GROUP]["terminated"].sum())
        steps += 1
        if terminated or truncated:
            return total, home, steps


def test_the_hello_lists_the_flock_as_one_group_of_64(serve: Serve) -> None:
    server = serve(TARGET)
    with Client(server.host, server.port, timeout=30) as client:
        assert list(client.hello.agents) == [GROUP]
        spec = client.groups[GROUP]
        assert spec.instance_count == MEMBERS
        assert spec.observation_space.shape == (6,) and spec.action_space.shape == (2,)
        assert client.observation_space[GROUP].shape == (MEMBERS, 6)
        assert client.action_space[GROUP].shape == (MEMBERS, 2)


def test_a_scripted_flock_comes_home_and_a_random_one_does_not(serve: Serve) -> None:
    server = serve(TARGET)
    rng = np.random.default_rng(0)
    with Client(server.host, server.port, timeout=30) as client:
        scripted = [_episode(client, seed, steer) for seed in range(2)]
        random = [
            _episode(client, seed, lambda _: rng.uniform(-1, 1, (MEMBERS, 2)).astype(np.float32))
            for seed in range(2)
        ]
    for total, home, steps in scripted:  # everyone home, the episode terminated early
        assert home == MEMBERS and steps < 600 // 4 and total > MEMBERS
    assert max(total for total, _, _ in random) < min(total for total, _, _ in scripted) / 4
    assert max(home for _, home, _ in random) < MEMBERS // 2


def test_members_join_every_few_ticks_with_a_first_reward_of_zero(serve: Serve) -> None:
    server = serve(TARGET)
    with Client(server.host, server.port, timeout=30) as client:
        observation, _ = client.reset(seed=2)
        first = starting(MEMBERS)
        _, _, _, _, info = client.step({GROUP: np.zeros((MEMBERS, 2), np.float32)}, 2 * JOIN_TICKS)
        outcome = info["agents"][GROUP]
        assert np.flatnonzero(outcome["joined"]).tolist() == [first, first + 1]
        assert outcome["reward"][[first, first + 1]].tolist() == [0.0, 0.0]
        assert outcome["active"].sum() == first + 2


def test_gym_make_swarm_passes_check_env() -> None:
    env = gymnasium.make("rlenv/Swarm-v0")
    try:
        assert list(env.observation_space) == [GROUP]
        assert warnings_of(lambda: check_env(env.unwrapped)) == []
    finally:
        env.close()


def test_the_benchmarks_floor_moves_the_discs_as_the_served_group_does(serve: Serve) -> None:
    """The floor (bare pymunk and numpy) does the group's work: the same bodies, bit for bit."""
    server = serve(TARGET)
    floor = SwarmFloor(MEMBERS)
    rng = np.random.default_rng(5)
    with Client(server.host, server.port, timeout=30, world_data=True) as client:
        observation, info = client.reset(seed=21)
        first = starting(MEMBERS)  # the rows in play; the answer's others are zeros
        assert np.array_equal(
            floor.reset(seeding.np_random(21)[0])[:first], observation[GROUP][:first]
        )
        for _ in range(STEPS):
            action = rng.uniform(-1, 1, (MEMBERS, 2)).astype(np.float32)
            observation, _, _, _, info = client.step({GROUP: action})
            stepped = floor.step(action)
            outcome = info["agents"][GROUP]
            assert stepped == outcome["active"].sum()
            assert np.array_equal(floor.bodies.in_play, ~np.isnan(info["world"]["bodies"][:, 0]))
            positions = np.array([(*body.position, *body.velocity) for body in floor.bodies.bodies])
            in_play = floor.bodies.in_play
            assert np.array_equal(positions[in_play], info["world"]["bodies"][in_play])
            active = outcome["active"]
            assert np.array_equal(floor.observations[active], observation[GROUP][active])


def test_the_swarm_benchmark_prints_its_lines() -> None:
    (rates,) = measure_swarm(rounds=1, steps=10, sizes=(16,), progress=lambda _: None)
    assert re.fullmatch(
        r"swarm N=16: group \d+ agent-steps/s, nodes \d+, floor \d+", swarm_line(rates)
    )
    assert re.fullmatch(
        r"swarm: group/nodes \d+\.\dx, floor/group \d+\.\dx at N=16", summary_line(rates)
    )
    assert min(rates.group + rates.nodes + rates.floor) > 0


def test_a_snapshot_of_the_flock_restores_and_goes_on_bit_for_bit(serve: Serve) -> None:
    first_server, other_server = serve(TARGET), serve(TARGET)
    rng = np.random.default_rng(9)
    actions = [rng.uniform(-1, 1, (MEMBERS, 2)).astype(np.float32) for _ in range(40)]
    with (
        Client(first_server.host, first_server.port, timeout=30, world_data=True) as first,
        Client(other_server.host, other_server.port, timeout=30, world_data=True) as other,
    ):
        observation, _ = first.reset(seed=4)
        left = joined = 0
        for action in actions[:20]:  # members join and leave meanwhile
            pushed = np.clip(steer(observation[GROUP]) + action, -1.0, 1.0)
            observation, _, _, _, info = first.step({GROUP: pushed})
            left += int(info["agents"][GROUP]["terminated"].sum())
            joined += int(info["agents"][GROUP]["joined"].sum())
        assert left > 0 and joined == 80 // JOIN_TICKS
        restored, restored_info = other.restore(first.snapshot())
        assert np.array_equal(
            restored_info["world"]["bodies"], info["world"]["bodies"], equal_nan=True
        )
        for action in actions[20:]:
            one = first.step({GROUP: action})
            two = other.step({GROUP: action})
            assert one[0][GROUP].tobytes() == two[0][GROUP].tobytes()
            assert np.array_equal(
                one[4]["world"]["bodies"], two[4]["world"]["bodies"], equal_nan=True
            )
