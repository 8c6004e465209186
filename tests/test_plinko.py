"""Plinko: snapshots, colours, difficulty, level data's wiring, over sockets.

Levels from the seed or as data, the same tests as Maze's, are in test_levels.py.
"""

from __future__ import annotations

import inspect
from typing import Any

import numpy as np
from conftest import Serve

from examples.plinko import TARGET, PlinkoEnvironment, follow
from rlenv import CollisionShape, StaticBody
from rlenv.scene2d.packed_scene import CONNECTABLE
from rlenv.signals import Signal
from rlenv_client import Client, LocalClient, RemoteError

STILL = np.zeros(1, np.float32)


def play(client: Client | LocalClient, steps: int = 200, **reset: Any) -> list[Any]:
    """Reset, then follow the ball until the episode ends: every observation's bytes."""
    observation, info = client.reset(**reset)
    seen: list[Any] = [observation.tobytes(), info["world"]["level"]]
    for _ in range(steps):
        observation, reward, terminated, truncated, _ = client.step(follow(observation))
        seen.append((observation.tobytes(), reward, terminated, truncated))
        if terminated or truncated:
            break
    return seen


def colors_of(level: dict[str, Any]) -> set[tuple[int, ...]]:
    found = set()
    stack = [level["root"]]
    while stack:
        entry = stack.pop()
        stack.extend(entry.get("children", []))
        color = entry.get("properties", {}).get("color")
        if color is not None:
            found.add(tuple(color))
    return found


def test_a_snapshot_restores_exactly_on_the_other_server(serve: Serve) -> None:
    first, second = serve(TARGET), serve(TARGET)
    with (
        Client(first.host, first.port, timeout=20) as a,
        Client(second.host, second.port, timeout=20) as b,
    ):
        a.configure(world={"difficulty": 0.8})
        observation, _ = a.reset(seed=5)
        for _ in range(6):
            observation, *_ = a.step(follow(observation))
        snapshot = a.snapshot()
        b.reset(seed=2)
        restored, _ = b.restore(snapshot)
        assert restored.tobytes() == observation.tobytes()
        assert b.snapshot() == snapshot
        assert b.get_property("World", "level") == a.get_property("World", "level")
        for _ in range(30):
            one = a.step(follow(observation))
            two = b.step(follow(observation))
            assert one[0].tobytes() == two[0].tobytes() and one[1:4] == two[1:4]
            observation = one[0]
            if one[2]:
                break


def test_a_frame_shows_the_level_colours(serve: Serve) -> None:
    server = serve(TARGET)
    with Client(server.host, server.port, timeout=20) as client:
        client.reset(seed=5)
        frame = client.render()
        level = client.get_property("World", "level")
        colors = colors_of(level)
        assert len(colors) >= 6  # rows of pegs and bins, each coloured from a gradient
        pixels = {tuple(p) for p in frame.reshape(-1, 3)}
        assert colors <= pixels, colors - pixels
        client.reset(seed=6)
        assert not np.array_equal(client.render(), frame)


def test_difficulty_changes_the_levels_and_following_the_ball_pays() -> None:
    with LocalClient(PlinkoEnvironment, world_data=True) as client:
        pegs = {}
        for difficulty in (0.0, 1.0):
            client.configure(world={"difficulty": difficulty})
            pegs[difficulty] = [client.reset(seed=seed)[1]["world"]["pegs"] for seed in range(5)]
        assert max(pegs[0.0]) < min(pegs[1.0])
        caught = {"follow": 0.0, "still": 0.0}
        for seed in range(10):
            caught["follow"] += sum(step[1] for step in play(client, seed=seed)[2:])
            observation, _ = client.reset(seed=seed)
            for _ in range(200):
                observation, reward, terminated, *_ = client.step(STILL)
                caught["still"] += reward
                if terminated:
                    break
        assert caught["follow"] >= 8 > 5 >= caught["still"]


def _level_wiring(owner: str, signal: str, target: str, method: str) -> dict:
    """A peg (a body and its shape, "Skin") with ``owner``'s ``signal`` wired, as data, to the
    ``method`` of the node at ``target`` (a path from ``owner``)."""
    connection = [[signal, target, method, False]]
    return {
        "format": "rlenv.PackedScene",
        "version": 1,
        "root": {
            "class": "StaticBody",
            "name": "Peg",
            "connections": connection if owner == "Peg" else [],
            "children": [
                {
                    "class": "CollisionShape",
                    "name": "Skin",
                    "properties": {"shape": {"kind": "circle", "radius": 0.1}},
                    "connections": connection if owner == "Skin" else [],
                }
            ],
        },
    }


def _members(kind: type, signals: bool) -> list[str]:
    return sorted(
        name
        for name in dir(kind)
        if not name.startswith("__")
        and (
            isinstance(getattr(kind, name), Signal)
            if signals
            else inspect.isfunction(inspect.getattr_static(kind, name))
        )
    )


def test_level_data_wiring_any_signal_to_any_method_never_breaks_the_server(
    serve: Serve,
) -> None:
    """The attack of issue 32: signals of level data wired to lifecycle and structure methods.

    Before, ``ready -> _enter_tree`` put the shape in its space twice and Chipmunk aborted the
    process, and ``child_exiting_tree -> remove_child`` broke the instance for good. Now data
    may connect only to what a level needs; whatever it tries, a normal reset works after it.
    """
    kinds = {"Peg": StaticBody, "Skin": CollisionShape}
    paths = {
        ("Peg", "Peg"): ".",
        ("Peg", "Skin"): "Skin",
        ("Skin", "Skin"): ".",
        ("Skin", "Peg"): "..",
    }
    assert "_enter_tree" in _members(CollisionShape, False)
    assert "remove_child" in _members(StaticBody, False)
    server = serve(TARGET)
    accepted, tried = set(), 0
    with Client(server.host, server.port, timeout=20) as client:
        for (owner, target), path in paths.items():
            for signal in _members(kinds[owner], True):
                for method in _members(kinds[target], False):
                    tried += 1
                    try:
                        client.reset(
                            seed=1, options={"level": _level_wiring(owner, signal, path, method)}
                        )
                    except RemoteError as error:
                        assert (
                            "data may not connect to" in error.message
                            or "does not take" in error.message
                        ), (owner, signal, method, error.message)
                        continue
                    accepted.add(method)
                    client.step(STILL)
                    client.reset(seed=2)
                observation, _ = client.reset(seed=2)  # a normal level, served as ever
                client.step(follow(observation))
        assert server.is_alive()
    assert tried > 500 and accepted == set(CONNECTABLE)
