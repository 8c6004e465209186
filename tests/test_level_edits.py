"""Edits of levels (issue 33, ACCEL): ``client.edit_level`` over real sockets and in process."""

from __future__ import annotations

import os
from collections import Counter
from typing import Any

import numpy as np
import pytest
from conftest import Serve

from examples.cartpole import TARGET as CARTPOLE
from examples.plinko import (
    BOUNCINESS,
    EDITS,
    MAX_JITTER,
    PEG_BOTTOM,
    PEG_EDGE,
    PEG_GAP,
    PEG_TOP,
    TARGET,
    PlinkoEnvironment,
    follow,
)
from rlenv.protocol import ErrorReply, Request, Response
from rlenv_client import Client, ErrorCode, LocalClient, RemoteError

Pegs = dict[str, tuple[tuple[float, float], float]]


def pegs_of(level: dict[str, Any]) -> Pegs:
    """Each peg's board position and bounciness, by name."""
    root = level["root"]
    pegs = next(child for child in root["children"] if child["name"] == "Pegs")
    origin = np.add(root["properties"]["position"], pegs["properties"]["position"])
    return {
        peg["name"]: (
            tuple(np.add(origin, peg["properties"]["position"]).tolist()),
            peg["children"][0]["properties"]["elasticity"],
        )
        for peg in pegs["children"]
    }


def changes(before: Pegs, after: Pegs) -> Counter[str]:
    """How many pegs were moved, added, removed, given another bounciness."""
    counted: Counter[str] = Counter(
        add=len(after.keys() - before.keys()), remove=len(before.keys() - after.keys())
    )
    for name in before.keys() & after.keys():
        counted["move"] += before[name][0] != after[name][0]
        counted["bounciness"] += before[name][1] != after[name][1]
    return +counted


def assert_valid(before: Pegs, after: Pegs) -> None:
    """Every peg on the board, above the bins, bouncing as Plinko's do; placed ones apart."""
    assert after
    for (x, y), bounciness in after.values():
        assert -PEG_EDGE <= x <= PEG_EDGE and PEG_BOTTOM - MAX_JITTER <= y <= PEG_TOP + MAX_JITTER
        assert BOUNCINESS[0] <= bounciness <= BOUNCINESS[1]
    for name, (spot, _) in after.items():
        if before.get(name, (None,))[0] != spot:  # moved or added
            assert all(
                np.hypot(*np.subtract(spot, other)) >= PEG_GAP
                for each, (other, _) in after.items()
                if each != name
            )


def play(client: Client, steps: int = 200, **reset: Any) -> list[Any]:
    observation, info = client.reset(**reset)
    seen: list[Any] = [observation.tobytes(), info["world"]]
    for _ in range(steps):
        observation, reward, terminated, truncated, info = client.step(follow(observation))
        seen.append((observation.tobytes(), reward, terminated, truncated, info["frames"]))
        if terminated or truncated:
            break
    return seen


def test_edits_are_deterministic_valid_counted_and_playable(serve: Serve) -> None:
    server = serve(TARGET)
    with Client(server.host, server.port, timeout=20, world_data=True) as client:
        seed_level = client.edit_level(5, seed=3)  # no episode needed
        client.reset(seed=5)
        level = client.get_property("World", "level")
        edited = client.edit_level(level, seed=3)
        assert client.edit_level(level, seed=3) == edited == seed_level  # an int: its level
        assert client.edit_level(level, seed=4) != edited
        assert client.get_property("World", "level") == level  # the episode's level stays
        before = pegs_of(level)
        kinds: Counter[str] = Counter()
        for seed in range(12):
            one = pegs_of(client.edit_level(level, seed=seed))
            assert sum(changes(before, one).values()) == 1
            assert_valid(before, one)
            kinds += changes(before, one)
            five = client.edit_level(level, seed=seed, n_edits=5)
            assert 1 <= sum(changes(before, pegs_of(five)).values()) <= 5
            assert_valid(before, pegs_of(five))
        assert set(kinds) == set(EDITS)
        many = client.edit_level(level, seed=1, n_edits=64)
        assert_valid(before, pegs_of(many))
        run = play(client, seed=1, options={"level": many})
        assert run[1]["pegs"] == len(pegs_of(many)) and run[-1][2]  # played to the end
        assert client.get_property("World", "level") == many
        assert play(client, seed=1, options={"level": many}) == run
        with LocalClient(PlinkoEnvironment) as local:  # in process: the same part, same edit
            assert local.edit_level(level, seed=3) == edited
            assert local.edit_level(5, seed=7, n_edits=5) == client.edit_level(5, seed=7, n_edits=5)


def test_the_controller_edits_mid_episode_and_the_episode_goes_on_bit_for_bit(
    serve: Serve,
) -> None:
    """An edit changes nothing of the episode; it takes control (2.6), as it holds the server's
    loop while it builds: an observer's is refused with ``busy``."""
    server = serve(TARGET)
    with (
        Client(server.host, server.port, timeout=20, world_data=True) as controller,
        Client(server.host, server.port, timeout=20) as observer,
    ):

        def run(edit: bool) -> list[Any]:
            observation, info = controller.reset(seed=7)
            seen: list[Any] = [observation.tobytes(), info["world"]]
            level = controller.get_property("World", "level")
            for step in range(200):
                if edit and step in (2, 5):
                    snapshot = controller.snapshot()
                    controller.edit_level(level, seed=step, n_edits=8)
                    controller.edit_level(9, seed=step)
                    with pytest.raises(RemoteError) as busy:
                        observer.edit_level(level, seed=step, n_edits=3)
                    assert busy.value.code == ErrorCode.BUSY
                    assert controller.snapshot() == snapshot
                observation, reward, terminated, truncated, info = controller.step(
                    follow(observation)
                )
                seen.append(
                    (
                        observation.tobytes(),
                        reward,
                        terminated,
                        truncated,
                        info["frames"],
                        info["world"],
                    )
                )
                if terminated or truncated:
                    observation, info = controller.reset()  # its generator goes on
                    return [*seen, observation.tobytes(), info["world"]]
            raise AssertionError("the episode did not end")

        reference = run(edit=False)
        assert len(reference) > 8  # the edits come mid-episode
        assert run(edit=True) == reference
        with pytest.raises(RemoteError) as busy:
            observer.reset(seed=1)  # the refused edits took no control from the controller
        assert busy.value.code == ErrorCode.BUSY


def test_an_environment_without_the_hook_refuses_and_serves_on(serve: Serve) -> None:
    server = serve(CARTPOLE)
    with Client(server.host, server.port, timeout=20) as client:
        observation, _ = client.reset(seed=0)
        with pytest.raises(RemoteError) as refused:
            client.edit_level({"root": {}}, seed=3)
        assert refused.value.code == ErrorCode.BAD_REQUEST
        assert "CartPoleWorld has no _edit_level" in refused.value.message
        client.step(np.zeros(1, np.float32))


def _refusal(client: Client, parts: dict[str, Any]) -> ErrorReply:
    client.send_request(Request(0, parts))
    reply = client.receive_reply()
    assert isinstance(reply, ErrorReply) and not reply.fatal, reply
    return reply


def _chain(depth: int) -> dict[str, Any]:
    """``depth`` Node2D, each the only child of the one before."""
    node: dict[str, Any] = {"class": "Node2D", "name": "Deepest"}
    for _ in range(depth - 1):
        node = {"class": "Node2D", "name": "Level", "children": [node]}
    return node


REFUSALS = [
    pytest.param(
        {"level": 5, "seed": 3, "n_edits": 0},
        ErrorCode.BAD_REQUEST,
        "edit_level.n_edits must be an integer in [1, 64], got 0",
        id="n_edits-0",
    ),
    pytest.param(
        {"level": 5, "seed": 3, "n_edits": 65},
        ErrorCode.BAD_REQUEST,
        "edit_level.n_edits must be an integer in [1, 64], got 65",
        id="n_edits-65",
    ),
    pytest.param(
        {"level": 5, "seed": 3, "n_edits": 1.0},
        ErrorCode.BAD_REQUEST,
        "got 1.0",
        id="n_edits-float",
    ),
    pytest.param(
        {"level": 5, "seed": 3, "n_edits": True},
        ErrorCode.BAD_REQUEST,
        "got True",
        id="n_edits-bool",
    ),
    pytest.param(
        {"level": 5, "seed": -1},
        ErrorCode.BAD_REQUEST,
        "edit_level.seed must be an integer >= 0, got -1",
        id="seed-negative",
    ),
    pytest.param(
        {"level": 5, "seed": "3"},
        ErrorCode.BAD_REQUEST,
        "edit_level.seed must be an integer >= 0, got '3'",
        id="seed-str",
    ),
    pytest.param({"level": 5, "seed": 2.5}, ErrorCode.BAD_REQUEST, "got 2.5", id="seed-float"),
    pytest.param({"level": 5}, ErrorCode.BAD_REQUEST, "got None", id="seed-missing"),
    pytest.param(
        {"seed": 3}, ErrorCode.BAD_REQUEST, "edit_level needs a 'level'", id="level-missing"
    ),
    pytest.param(
        {"level": 5, "seed": 3, "edits": 2},
        ErrorCode.BAD_REQUEST,
        "unknown key 'edits' in edit_level",
        id="unknown-key",
    ),
    pytest.param(
        {"level": -5, "seed": 3},
        ErrorCode.BAD_REQUEST,
        "FragileWorld._edit_level refused the level: a seed must be >= 0, got -5",
        id="level-negative-seed",
    ),
    pytest.param(
        {"level": "refuse", "seed": 3},
        ErrorCode.BAD_REQUEST,
        "FragileWorld._edit_level refused the level: this world edits no such level",
        id="hook-refuses",
    ),
    pytest.param(
        {
            "level": {
                "format": "rlenv.PackedScene",
                "version": 1,
                "root": {"class": "Evil", "name": "Level"},
            },
            "seed": 3,
        },
        ErrorCode.BAD_REQUEST,
        "class 'Evil' is not allowed",
        id="foreign-class",
    ),
    pytest.param(
        {
            "level": {
                "format": "rlenv.PackedScene",
                "version": 1,
                "root": {"class": "Node2D", "name": "Level"},
            },
            "seed": 3,
        },
        ErrorCode.BAD_REQUEST,
        "the level has no Pegs node",
        id="no-pegs",
    ),
    pytest.param(
        {
            "level": {
                "format": "rlenv.PackedScene",
                "version": 1,
                "root": {
                    "class": "Node2D",
                    "name": "Level",
                    "children": [{"class": "Node2D", "name": f"N{index}"} for index in range(1024)],
                },
            },
            "seed": 3,
        },
        ErrorCode.BAD_REQUEST,
        "edit_level.level: a scene holds at most 1,024 nodes",
        id="too-many-nodes",
    ),
    pytest.param(
        {"level": {"format": "rlenv.PackedScene", "version": 1, "root": _chain(250)}, "seed": 3},
        ErrorCode.BAD_REQUEST,
        "edit_level.level: nodes nested more than 64 deep",
        id="too-deep",
    ),
    pytest.param(
        {"level": "crash", "seed": 3},
        ErrorCode.ENVIRONMENT_ERROR,
        "FragileWorld._edit_level raised RuntimeError: the editor broke; nothing changed",
        id="hook-raises",
    ),
    pytest.param(
        {"level": "untravelled", "seed": 3},
        ErrorCode.ENVIRONMENT_ERROR,
        "FragileWorld._edit_level returned data that cannot travel",
        id="untravelled",
    ),
]
"""Edits refused: the request, the error's code, a fragment of its message."""

_BY_THE_HOOK = {
    "level-negative-seed",
    "hook-refuses",
    "foreign-class",
    "no-pegs",
    "hook-raises",
    "untravelled",
}
"""Refusals that come from the world's hook: made once control was granted (an observer's edit
is answered busy before the hook runs); the others come from the request's checks."""


def test_bad_edits_are_refused_and_the_episode_goes_on(serve: Serve) -> None:
    server = serve("level_edit_envs:FragilePlinko", env={"PYTHONPATH": os.path.dirname(__file__)})
    with (
        Client(server.host, server.port, timeout=20) as controller,
        Client(server.host, server.port, timeout=20) as observer,
    ):
        observation, _ = controller.reset(seed=4)
        reference = [observation.tobytes()]
        for case in REFUSALS:
            edit, code, fragment = case.values
            for client in (observer, controller):  # the controller's own failure breaks nothing
                reply = _refusal(client, {"edit_level": edit})
                expected = (
                    (ErrorCode.BUSY, "controlled by another client")
                    if client is observer and case.id in _BY_THE_HOOK
                    else (code, fragment)
                )
                assert reply.code == expected[0] and expected[1] in reply.message, (
                    case.id,
                    reply.message,
                )
                observation, *_ = controller.step(follow(observation), 1)  # no reset_required
                reference.append(observation.tobytes())
        reply = _refusal(controller, {"edit_level": {"level": 4, "seed": 3}, "reset": {}})
        assert "edit_level goes alone" in reply.message
        busy = _ask(observer, {"edit_level": {"level": 4, "seed": 3}})  # checked, but not its
        assert isinstance(busy, ErrorReply) and busy.code == ErrorCode.BUSY
        assert isinstance(_ask(controller, {"edit_level": {"level": 4, "seed": 3}}), Response)
        observation, _ = controller.reset(seed=4)  # the same episode as if nothing was asked
        replayed = [observation.tobytes()]
        for _ in reference[1:]:
            observation, *_ = controller.step(follow(observation), 1)
            replayed.append(observation.tobytes())
        assert replayed == reference


def _ask(client: Client, parts: dict[str, Any]) -> Response | ErrorReply:
    client.send_request(Request(0, parts))
    return client.receive_reply()
