"""Levels from the seed or as data (rlenv.LevelWorld), the same tests for Plinko and Maze."""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np
import pytest
from conftest import Serve

from examples import maze, plinko
from rlenv_client import Client, ErrorCode, LocalClient, RemoteError


@dataclass(frozen=True)
class Levels:
    """An example with levels, and how the tests play it."""

    target: str
    steps: int
    policy: Callable[[np.ndarray, int], Any]
    """The action for an observation at a step."""
    draws_besides_the_level: bool
    """Whether a reset draws from the seed besides the level (Plinko's ball)."""
    classes: frozenset[str]
    """Classes a level built from the seed holds."""
    ends: bool
    """Whether the episode of seed 5 ends within :attr:`steps` (Plinko's ball falls through)."""


_MAZE_ACTIONS = np.random.default_rng(0).integers(5, size=60)

EXAMPLES = [
    pytest.param(
        Levels(
            plinko.TARGET,
            200,
            lambda observation, _: plinko.follow(observation),
            True,
            frozenset({"Peg", "Marker2D", "Divider", "BinFloor"}),
            True,
        ),
        id="plinko",
    ),
    pytest.param(
        Levels(
            maze.TARGET,
            60,
            lambda _, step: int(_MAZE_ACTIONS[step]),
            False,
            frozenset({"Wall", "Goal", "Marker2D"}),
            False,
        ),
        id="maze",
    ),
]


def play(
    client: Client | LocalClient, example: Levels, steps: int | None = None, **reset: Any
) -> list[Any]:
    """Reset, then the example's policy until the episode ends or ``steps`` (the example's by
    default) were taken: every observation's bytes."""
    observation, info = client.reset(**reset)
    seen: list[Any] = [observation.tobytes(), info["world"]["level"]]
    for step in range(example.steps if steps is None else steps):
        observation, reward, terminated, truncated, _ = client.step(
            example.policy(observation, step)
        )
        seen.append((observation.tobytes(), reward, terminated, truncated))
        if terminated or truncated:
            break
    return seen


def _entries(entry: dict[str, Any]) -> list[dict[str, Any]]:
    found = [entry]
    for child in entry.get("children", []):
        found += _entries(child)
    return found


@pytest.mark.parametrize("example", EXAMPLES)
def test_the_seed_makes_the_level_and_episode_on_any_server(serve: Serve, example: Levels) -> None:
    first, second = serve(example.target), serve(example.target)
    with (
        Client(first.host, first.port, timeout=20, world_data=True) as a,
        Client(second.host, second.port, timeout=20, world_data=True) as b,
    ):
        b.reset(seed=11)  # another history first: it must not matter
        play(b, example, steps=5)
        run = play(a, example, seed=5)
        assert play(b, example, seed=5) == run
        if example.ends:
            assert len(run) > 10 and run[-1][2]  # the ball fell through and the episode ended
        level = a.get_property("World", "level")
        assert b.get_property("World", "level") == level
        assert level["root"]["class"] == "Node2D"
        assert example.classes <= {entry["class"] for entry in _entries(level["root"])}
        other = play(a, example, seed=6)
        assert other[1] != run[1]  # another level (its data's digest)
        assert a.get_property("World", "level") != level
        assert other[0] != run[0]


@pytest.mark.parametrize("example", EXAMPLES)
def test_a_level_given_as_data_is_played(serve: Serve, example: Levels) -> None:
    first, second = serve(example.target), serve(example.target)
    with (
        Client(first.host, first.port, timeout=20, world_data=True) as a,
        Client(second.host, second.port, timeout=20, world_data=True) as b,
    ):
        run = play(a, example, seed=5)
        level = msgpack.unpackb(msgpack.packb(a.get_property("World", "level")))
        # what a reset draws before the level is drawn before it: the same seed on the given
        # level is the same run
        assert play(b, example, seed=5, options={"level": level}) == run
        assert b.get_property("World", "level") == level
        again = play(b, example, seed=9, options={"level": level})
        assert again[1] == run[1]  # the same level (its data's digest)
        if example.draws_besides_the_level:
            assert again[0] != run[0]  # another ball
        else:
            assert again == run  # nothing else is drawn


def _deep(depth: int) -> dict[str, Any]:
    """A level whose root holds a chain of ``depth`` Node2D, one inside the other."""
    node: dict[str, Any] = {"class": "Node2D", "name": f"N{depth}"}
    for level in range(depth - 1, 0, -1):
        node = {"class": "Node2D", "name": f"N{level}", "children": [node]}
    return {"format": "rlenv.PackedScene", "version": 1, "root": node}


def _wide(nodes: int) -> dict[str, Any]:
    """A level of ``nodes`` plain Node2D: a root and its children."""
    children = [{"class": "Node2D", "name": f"N{index}"} for index in range(nodes - 1)]
    return {
        "format": "rlenv.PackedScene",
        "version": 1,
        "root": {"class": "Node2D", "name": "Level", "children": children},
    }


@pytest.mark.parametrize("example", EXAMPLES)
def test_a_refused_level_costs_nothing_and_the_episode_goes_on(
    serve: Serve,
    example: Levels,
) -> None:
    """Level data that fails its checks (a foreign class, a Maze level without its Goal, more
    nodes or deeper than the hello's limits) is refused with ``bad_request`` before anything
    changes: the controller's episode goes on as if nothing was asked, bit for bit, and a
    watcher still observes it. Before, the reset had begun: ``environment_error ... reset
    required``, and the watcher was refused too."""
    first, second = serve(example.target), serve(example.target)
    with (
        Client(first.host, first.port, timeout=20) as client,
        Client(first.host, first.port, timeout=20) as watcher,
        Client(second.host, second.port, timeout=20) as alone,
    ):
        limits = client.hello.limits
        assert (limits["max_level_nodes"], limits["max_level_depth"]) == (1024, 64)
        observation, _ = client.reset(seed=5)
        level = client.get_property("World", "level")
        foreign = copy.deepcopy(level)
        foreign["root"]["children"][0]["children"][0]["class"] = "Evil"
        hollow = copy.deepcopy(level)  # no Goal for Maze; for Plinko no Pegs, which it allows
        hollow["root"]["children"] = [
            child for child in hollow["root"]["children"] if child["name"] != "Goal"
        ]
        refusals = [
            (foreign, "class 'Evil' is not allowed"),
            (_wide(1025), "a scene holds at most 1,024 nodes"),
            (_deep(66), "nodes nested more than 64 deep"),
            (_deep(250), "nodes nested more than 64 deep"),
        ]
        if example.target == maze.TARGET:
            refusals.append((hollow, "the level has no Goal"))
        seen = [observation.tobytes()]
        expected, _ = alone.reset(seed=5)
        expect = [expected.tobytes()]
        for step, (wrong, why) in enumerate(refusals):
            with pytest.raises(RemoteError) as refused:
                client.reset(seed=5, options={"level": wrong})
            assert refused.value.code == ErrorCode.BAD_REQUEST, refused.value.message
            assert refused.value.message.startswith("reset.options"), refused.value.message
            assert why in refused.value.message
            assert watcher.observe() is not None  # the episode is there to watch
            observation, *_ = client.step(example.policy(observation, step))  # no reset first
            seen.append(observation.tobytes())
            expected, *_ = alone.step(example.policy(expected, step))
            expect.append(expected.tobytes())
        assert seen == expect
        with pytest.raises(RemoteError) as bad:
            client.configure(world={"difficulty": 1.5})
        assert bad.value.code == ErrorCode.INVALID_CONFIG and "[0, 1]" in bad.value.message
        if example.target == plinko.TARGET:  # any level will do: the limits themselves play
            client.reset(seed=5, options={"level": _deep(64)})
            client.reset(seed=5, options={"level": _wide(1024)})
            client.step(example.policy(observation, 0))
        assert first.is_alive()


@pytest.mark.parametrize("example", EXAMPLES)
def test_an_int_level_is_the_level_its_seed_resets_to_and_a_negative_one_is_refused(
    example: Levels,
) -> None:
    world = example.target.split(":")[1].replace("Environment", "World")
    with LocalClient(example.target, world_data=True) as client:
        client.configure(world={"difficulty": 0.8})
        client.reset(seed=7)
        level = client.get_property("World", "level")
        edited = client.edit_level(7, seed=3, n_edits=4)
        assert client.edit_level(level, seed=3, n_edits=4) == edited != level
        _, info = client.reset(seed=1, options={"level": edited})
        assert client.get_property("World", "level") == edited
        assert info["world"]["level"] != client.reset(seed=7)[1]["world"]["level"]
        for wrong, why in (
            (-5, "a seed must be >= 0, got -5"),
            ({"root": {}}, "a scene's data is a map with exactly 'format', 'version' and 'root'"),
            (
                level
                | {
                    "root": level["root"]
                    | {"children": [level["root"]["children"][0] | {"class": "Evil"}]}
                },
                "class 'Evil' is not allowed",
            ),
        ):
            with pytest.raises(RemoteError) as refused:
                client.edit_level(wrong, seed=3)
            assert refused.value.code == ErrorCode.BAD_REQUEST
            assert refused.value.message.startswith(
                f"edit_level: {world}._edit_level refused the level: "
            ), refused.value.message
            assert why in refused.value.message


def test_level_world_is_rlenv_api_and_the_examples_old_name_the_same_class() -> None:
    import rlenv
    from examples import levels
    from rlenv.levels import LevelWorld

    assert rlenv.LevelWorld is LevelWorld is levels.LevelWorld
    assert issubclass(plinko.PlinkoWorld, LevelWorld) and issubclass(maze.MazeWorld, LevelWorld)
    assert issubclass(LevelWorld, rlenv.RLEnvWorld)
