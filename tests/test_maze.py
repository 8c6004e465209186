"""Maze: wall density, reachable goals, rays, MiniGrid's reward, ACCEL's edits.

Levels from the seed or as data, the same tests as Plinko's, are in test_levels.py.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from conftest import Serve

import rlenv_client  # noqa: F401  (registers the ids)
from examples.maze import (
    RAYS,
    TARGET,
    MazeEnvironment,
    cell_center,
    cell_of,
    grid_of,
    make_level,
    shortest_path,
)
from rlenv_client import Client, LocalClient

MAX_STEPS = 250
STOP, UP, DOWN, LEFT, RIGHT = range(5)


def toward(position: list[float], here: Any, there: Any) -> int:
    """The action that takes the agent from cell ``here`` on to the next cell ``there``:
    first onto the line between their centres, then along it."""
    x, y = position
    tx, ty = cell_center(there)
    if there[0] != here[0]:  # a move along x: first centre y
        if abs(ty - y) > 0.1:
            return UP if ty > y else DOWN
        return RIGHT if tx > x else LEFT
    if abs(tx - x) > 0.1:
        return RIGHT if tx > x else LEFT
    return UP if ty > y else DOWN


def drive(
    client: Client | LocalClient, level: dict[str, Any] | None = None, **reset: Any
) -> tuple[int, float, bool, dict[str, Any]]:
    """Play the level to its goal along a BFS path, from the level's data and the agent's
    position (world data): the steps taken, the last reward, terminated, the level."""
    options = {"options": {"level": level}} if level is not None else {}
    _, info = client.reset(**reset, **options)
    level = client.get_property("World", "level")
    walls, start, goal = grid_of(level)
    path = shortest_path(walls, start, goal)
    assert path is not None
    steps, reward, terminated = 0, 0.0, False
    while not terminated and steps < 4 * MAX_STEPS:
        position = info["world"]["agent"]
        here = cell_of(position)
        index = path.index(here)  # never off the path
        there = path[index + 1] if index + 1 < len(path) else goal
        _, reward, terminated, _, info = client.step(toward(position, here, there))
        steps += 1
    return steps, reward, terminated, level


def test_difficulty_sets_the_wall_density_and_every_goal_is_reachable() -> None:
    with LocalClient(MazeEnvironment, world_data=True) as client:
        walls = {}
        for difficulty in (0.0, 0.5, 1.0):
            client.configure(world={"difficulty": difficulty})
            walls[difficulty] = []
            for seed in range(50):
                _, info = client.reset(seed=seed)
                cells, start, goal = grid_of(client.get_property("World", "level"))
                assert len(cells) == info["world"]["walls"]
                assert start != goal and shortest_path(cells, start, goal) is not None, seed
                walls[difficulty].append(len(cells))
        assert max(walls[0.0]) < min(walls[0.5]) and max(walls[0.5]) < min(walls[1.0])
        assert 6 <= np.mean(walls[0.0]) <= 10 and 30 <= np.mean(walls[1.0]) <= 37


def test_the_goal_is_seen_only_along_a_clear_ray() -> None:
    with LocalClient(MazeEnvironment) as client:
        # the goal 3 cells right of the start (ray 0 points along +x), nothing between
        observation, _ = client.reset(options={"level": make_level(set(), (2, 5), (5, 5))})
        assert observation[RAYS] == pytest.approx(1 - (3 - 0.4) / 6, abs=1e-5)
        assert observation[RAYS + 8] == 0.0  # not behind
        assert observation[8] == pytest.approx(1.5 / 6, abs=1e-5)  # the border, past cell 1
        # a wall between: the goal is out of sight, the wall 1.5 cells away
        observation, _ = client.reset(options={"level": make_level({(4, 5)}, (2, 5), (5, 5))})
        assert not observation[RAYS : 2 * RAYS].any()
        assert observation[0] == pytest.approx(1.5 / 6, abs=1e-5)


def test_reaching_the_goal_terminates_with_minigrids_reward(serve: Serve) -> None:
    server = serve(TARGET)
    with Client(server.host, server.port, timeout=20, world_data=True) as client:
        client.configure(world={"difficulty": 0.7})
        for seed in range(4):
            steps, reward, terminated, _ = drive(client, seed=seed)
            assert terminated, seed
            assert reward == pytest.approx(1 - 0.9 * steps / MAX_STEPS), seed
        observation, _ = client.reset(seed=0)
        for _ in range(20):  # standing still earns nothing
            assert client.step(STOP)[1:3] == (0.0, False)


def test_edits_are_deterministic_keep_the_goal_reachable_and_play(serve: Serve) -> None:
    server = serve(TARGET)
    with Client(server.host, server.port, timeout=20, world_data=True) as client:
        client.reset(seed=3)
        level = client.get_property("World", "level")
        walls, start, goal = grid_of(level)
        kinds = set()
        for seed in range(30):
            edited = client.edit_level(level, seed=seed, n_edits=1)
            assert client.edit_level(level, seed=seed, n_edits=1) == edited
            cells, begin, end = grid_of(edited)
            assert begin == start and shortest_path(cells, begin, end) is not None
            kinds.add(
                "add"
                if len(cells) > len(walls)
                else "remove"
                if len(cells) < len(walls)
                else "goal"
                if end != goal
                else "none"
            )
        assert {"add", "remove", "goal"} <= kinds
        many = client.edit_level(3, seed=1, n_edits=20)  # an int level is its seed's level
        cells, begin, end = grid_of(many)
        assert begin == start and shortest_path(cells, begin, end) is not None
        assert many != level
        steps, reward, terminated, played = drive(client, many, seed=8)
        assert played == many and terminated
        assert reward == pytest.approx(1 - 0.9 * steps / MAX_STEPS)


def test_the_gymnasium_id_makes_and_steps() -> None:
    env = gym.make("rlenv/Maze-v0")
    try:
        assert env.spec is not None and env.spec.max_episode_steps == MAX_STEPS
        observation, _ = env.reset(seed=0)
        assert env.observation_space.contains(observation)
        assert env.action_space == gym.spaces.Discrete(5)
        truncated = terminated = False
        for _ in range(MAX_STEPS):
            observation, reward, terminated, truncated, _ = env.step(STOP)
            if terminated or truncated:
                break
        assert truncated and not terminated and reward == 0.0  # the time limit
    finally:
        env.close()
