"""What an inspector watches: vector draw lists of the scene and the server's episode statistics."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from conftest import Serve

from examples.cartpole import CartPoleEnvironment
from rlenv_client import Client, ErrorCode, LocalClient, RemoteError

EXAMPLES = [
    "examples.cartpole:CartPoleEnvironment",
    "examples.seeker:SeekerEnvironment",
    "examples.seeker:SeekerPixelsEnvironment",
    "examples.reacher:ReacherEnvironment",
    "examples.pair:PairEnvironment",
    "examples.pixels:PixelsEnvironment",
]
_GEOMETRY = {"circle": 4, "segment": 5, "polygon": 2}  # numbers after kind and colour


def test_the_draw_list_follows_the_scene(client: Client) -> None:
    with pytest.raises(RemoteError) as error:
        client.draw()
    assert error.value.code == ErrorCode.RESET_REQUIRED
    client.reset(seed=3)
    first = client.draw()
    assert first["view"] == list(CartPoleEnvironment.render_view)
    kinds = [shape[0] for shape in first["shapes"]]
    assert kinds == ["segment", "polygon", "segment"]  # track, cart, pole
    for _ in range(2):
        client.step(np.full(1, 0.5, np.float32))  # push the cart to +x
    second = client.draw()
    cart_before = np.mean(np.reshape(first["shapes"][1][3], (-1, 2)), axis=0)
    cart_after = np.mean(np.reshape(second["shapes"][1][3], (-1, 2)), axis=0)
    assert cart_after[0] > cart_before[0] + 0.01
    assert cart_after[0] == pytest.approx(client.observe()["agent"][0], abs=1e-4)
    tip = client.observe()["world"]["pole_tip"]
    assert second["shapes"][2][4:6] == pytest.approx(tip)  # the pole's far end


@pytest.mark.parametrize("target", EXAMPLES)
def test_every_example_draws_a_few_hundred_bytes(target: str) -> None:
    with LocalClient(target) as client:
        client.reset(seed=0)
        drawn = client.draw()
    assert len(drawn["view"]) == 4 and drawn["view"][0] < drawn["view"][2]
    assert drawn["shapes"]
    for shape in drawn["shapes"]:
        kind, color, *geometry = shape
        assert 0 <= color <= 0xFFFFFF
        assert len(geometry) == _GEOMETRY[kind]
        if kind == "polygon":
            assert len(geometry[1]) % 2 == 0 and len(geometry[1]) >= 6
    assert len(msgpack.packb(drawn)) < 4096


def test_stats_count_what_the_controller_was_given(client: Client) -> None:
    returns, lengths = [], []
    for seed in range(3):
        client.reset(seed=seed)
        total, length, terminated = 0.0, 0, False
        while not terminated:
            _, reward, terminated, *_ = client.step(np.ones(1, np.float32))
            total += reward
            length += 1
        returns.append(total)
        lengths.append(length)
    client.reset(seed=9)
    _, reward, *_ = client.step(np.zeros(1, np.float32))
    client.reset(seed=10)  # cuts the episode short (a time limit, say)
    stats = client.stats()
    episodes = stats["episodes"]
    assert [e["return"] for e in episodes] == returns + [reward]
    assert [e["length"] for e in episodes] == lengths + [1]
    assert [e["end"] for e in episodes] == ["terminated"] * 3 + ["reset"]
    assert [e["episode"] for e in episodes] == [0, 1, 2, 3]
    assert stats["next"] == 4 and stats["steps"] == sum(lengths) + 1
    assert stats["ticks"] == sum(e["ticks"] for e in episodes)
    assert stats["current"] == {"return": 0.0, "length": 0, "ticks": 0}
    assert [e["episode"] for e in client.stats(since=2)["episodes"]] == [2, 3]
    assert client.stats(since=4)["episodes"] == []


def test_an_observer_reading_stats_takes_no_reward_from_the_controller(
    server: object, client: Client
) -> None:
    client.reset(seed=0)
    client.step(np.zeros(1, np.float32))
    with Client(server.host, server.port) as inspector:  # type: ignore[attr-defined]
        assert inspector.stats()["current"]["length"] == 1
        inspector.draw()
        inspector.observe()
    _, reward, *_ = client.step(np.zeros(1, np.float32))
    assert reward == 4.0  # the second step's 4 ticks, all reported to the controller
    assert client.stats()["current"] == {"return": 8.0, "length": 2, "ticks": 8}


def test_stats_count_environment_errors(serve: Serve) -> None:
    server = serve("examples.faulty:FaultyEnvironment")
    with Client(server.host, server.port) as client:
        client.reset(seed=0)
        client.step(0)
        with pytest.raises(RemoteError):
            client.step(1)  # its tick raises
        stats = client.stats()
    assert stats["errors"] == 1
    assert [(e["end"], e["length"]) for e in stats["episodes"]] == [("error", 1)]


def test_stats_keep_returns_per_agent(serve: Serve) -> None:
    server = serve("examples.pair:PairEnvironment")
    with Client(server.host, server.port) as client:
        client.reset(seed=0)
        seen: dict[str, float] = {}
        for _ in range(3):
            action = {name: client.action_space[name].sample() for name in client.action_space}
            _, _, _, _, info = client.step(action)
            for name, outcome in info["agents"].items():
                seen[name] = seen.get(name, 0.0) + outcome["reward"]
        current = client.stats()["current"]
    assert current["returns"] == pytest.approx(seen)
    assert current["return"] == pytest.approx(sum(seen.values()))


def test_an_observers_failing_request_leaves_the_episode_to_its_controller(serve: Serve) -> None:
    server = serve("examples.faulty:FaultyEnvironment")
    with (
        Client(server.host, server.port) as controller,
        Client(server.host, server.port) as inspector,
    ):
        controller.reset(seed=0)
        controller.step(0)
        with pytest.raises(RemoteError, match="cannot draw; the episode goes on") as error:
            inspector.draw()
        assert error.value.code == ErrorCode.ENVIRONMENT_ERROR and not error.value.fatal
        _, reward, *_ = controller.step(0)  # the episode is still the controller's
        assert reward == 1.5  # 3 ticks of 0.5
        with pytest.raises(RemoteError, match="cannot draw; reset required"):
            controller.draw()  # the controller's own failure ends its episode, as before
        assert controller.stats()["errors"] == 1
