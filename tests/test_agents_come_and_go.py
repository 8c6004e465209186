"""Agents that come and go, and decide at their own pace (issue 42), at the protocol's level.

The games are ``tests/come_and_go_envs.py``'s, whose every tick is known: A and B start, C
joins at tick 6, B is freed at 10, A terminates at 20, C is truncated at 30; and four walkers
at three paces. Most checks run in process (``LocalClient``: the server's own code path); the
wire's run over ``rlenv serve`` subprocesses.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from answers import play
from conftest import Serve

from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv_client import Client, LocalClient

TESTS = Path(__file__).parent
COME_AND_GO = "come_and_go_envs:ComeAndGoEnvironment"
PACED = "come_and_go_envs:PacedEnvironment"
FIXED = "come_and_go_envs:FixedEnvironment"


@pytest.fixture(autouse=True)
def _tests_on_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(TESTS))
    path = os.pathsep.join(filter(None, [str(TESTS), os.environ.get("PYTHONPATH")]))
    monkeypatch.setenv("PYTHONPATH", path)


def _play(client: Any, steps: int = 40) -> list[dict[str, Any]]:
    """Step with +1 for every agent in each answer, until the episode ends: every answer."""
    return play(client, lambda observation: dict.fromkeys(observation, 2), 0, steps)


def test_the_hello_lists_every_possible_agent_and_its_spaces(serve: Serve) -> None:
    with Client(serve(COME_AND_GO).address) as client:
        hello = client.hello
        assert hello.agents == ("A", "B", "C", "D")
        assert hello.possible_agents == dict.fromkeys("ABCD", "Walker")
        assert list(hello.observation_space.spaces) == ["A", "B", "C", "D"]
        assert list(hello.action_space.spaces) == ["A", "B", "C", "D"]
    with Client(serve(FIXED).address) as client:
        assert client.hello.possible_agents is None  # every agent in every answer, as ever


def test_agents_join_and_leave_each_with_one_first_and_one_last_transition() -> None:
    client = LocalClient(COME_AND_GO)
    answers = _play(client)
    seen = [sorted(answer["observation"]) for answer in answers]
    assert seen == [["A", "B"], ["A", "B"], ["A", "B", "C"], ["A", "B", "C"], ["A", "C"],
                    ["A", "C"], ["C"], ["C"], ["C"]]  # fmt: skip
    joined = answers[2]
    assert joined["agents"]["C"] == {"reward": None, "terminated": False, "truncated": False}
    assert joined["observation"]["C"].tolist() == [0.0, 8.0]  # joined at 6: no action yet
    assert joined["reward"] == 8.0  # A's and B's; C's first transition has no reward
    freed = answers[3]  # B freed at tick 10, in the step from 8 to 12
    assert freed["agents"]["B"] == {"reward": 2.0, "terminated": True, "truncated": False}
    assert freed["observation"]["B"].tolist() == [10.0, 10.0]  # taken at tick 10, in the tree
    ended = answers[5]  # A terminated at tick 20 (it stays in the tree)
    assert ended["agents"]["A"] == {"reward": 4.0, "terminated": True, "truncated": False}
    last = answers[-1]
    assert last["agents"] == {"C": {"reward": 2.0, "terminated": False, "truncated": True}}
    assert last["frames"] == 2  # no one left: the step stops at tick 30
    assert (last["terminated"], last["truncated"]) == (False, True)  # joint_end of the three
    environment = client.host.instances[0].environment
    a, c = environment.get_node("A"), environment.get_node("C")
    assert a.observed_at[-1] == 20  # never observed after it left
    assert a.actions[-1][0] == 16 and c.actions[0][0] == 8  # nor stepped; C from its first
    assert environment.agents == []
    with pytest.raises(RemoteError) as ended_episode:
        client.step({"C": 1})
    assert ended_episode.value.code == ErrorCode.RESET_REQUIRED
    client.close()


def test_an_agent_without_a_declaration_may_not_join() -> None:
    client = LocalClient(FIXED)
    observation, _ = client.reset(seed=0)
    client.step(dict.fromkeys(observation, 2))
    with pytest.raises(RemoteError) as refused:
        client.step(dict.fromkeys(observation, 2))  # C is added at tick 6
    assert refused.value.code == ErrorCode.ENVIRONMENT_ERROR
    assert (
        "cannot add agent 'C' to Fixed during an episode: FixedEnvironment declares no "
        "possible_agents (declare RLEnvironment.possible_agents"
    ) in refused.value.message
    client.close()


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        ("add_again", "cannot add agent 'A' to ComeAndGo: the name was used already in this "
                      "episode (an agent's name is never used twice in one episode)"),
        ("add_undeclared", "cannot add agent 'E' to ComeAndGo: "
                           "ComeAndGoEnvironment.possible_agents does not name it (it names A, "
                           "B, C, D)"),
        ("add_wrong_class", "cannot add agent 'D' to ComeAndGo: it is a Sprinter, and "
                            "ComeAndGoEnvironment.possible_agents declares it a Walker"),
    ],
)  # fmt: skip
def test_a_join_outside_the_rules_is_refused_and_the_server_serves_on(
    serve: Serve, setting: str, message: str
) -> None:
    with Client(serve(COME_AND_GO).address) as client:
        client.configure(world={setting: True})
        observation, _ = client.reset(seed=0)
        with pytest.raises(RemoteError) as refused:
            client.step(dict.fromkeys(observation, 2))  # the change is made at tick 3
        assert refused.value.code == ErrorCode.ENVIRONMENT_ERROR
        assert message in refused.value.message
        client.configure(world={setting: False})
        observation, _ = client.reset(seed=0)
        assert sorted(observation) == ["A", "B"]
        client.step(dict.fromkeys(observation, 2))


def test_agents_decide_at_their_own_pace() -> None:
    client = LocalClient(PACED)
    answers = _play(client)
    environment = client.host.instances[0].environment
    deciders = [sorted(answer["observation"]) for answer in answers[1:13]]
    assert deciders == [
        ["Fast", "Plain"],  # tick 2
        ["Plain", "Slow"],  # 3 (Slow: period 6, offset 3)
        ["Fast", "Jerky", "Plain"],  # 4
        ["Fast", "Plain"],  # 6
        ["Fast", "Jerky", "Plain"],  # 8
        ["Plain", "Slow"],  # 9
        ["Fast", "Plain"],  # 10
        ["Fast", "Jerky", "Plain"],  # 12
        ["Fast", "Plain"],  # 14
        ["Plain", "Slow"],  # 15
        ["Fast", "Jerky", "Plain"],  # 16
        ["Fast", "Plain"],  # 18
    ]
    assert [answer["frames"] for answer in answers[1:8]] == [2, 1, 1, 2, 2, 1, 1]
    # Slow's reward is summed over the ticks since its last answer (1 per tick)
    slow = [
        answer["agents"]["Slow"]["reward"] for answer in answers[1:] if "Slow" in answer["agents"]
    ]
    assert slow[:4] == [3.0, 6.0, 6.0, 6.0]
    # Jerky does not act between its decisions: no_action (None here) after each first tick
    jerky = environment.get_node("Jerky").actions
    decided = [tick for tick, action in jerky if action is not None]
    assert decided == [0, 4, 8, 12, 16, 20]
    assert all(action is None for tick, action in jerky if tick not in decided)
    assert answers[-1]["truncated"] and not answers[-1]["terminated"]
    client.close()


def test_an_action_has_entries_for_the_agents_due_and_needs_no_others() -> None:
    client = LocalClient(PACED)
    client.reset(seed=0)
    observation, *_ = client.step(dict.fromkeys(["Fast", "Slow", "Plain", "Jerky"], 2))
    assert sorted(observation) == ["Fast", "Plain"]
    with pytest.raises(RemoteError) as missing:
        client.step({"Fast": 2})
    assert missing.value.code == ErrorCode.INVALID_ACTION
    assert "no action for agent 'Plain'" in missing.value.message
    with pytest.raises(RemoteError) as unknown:
        client.step({"Fast": 2, "Plain": 2, "Nobody": 1})
    assert "action for unknown agent 'Nobody'" in unknown.value.message
    observation, *_ = client.step({"Fast": 2, "Plain": 2, "Slow": 7})  # Slow's: ignored
    assert sorted(observation) == ["Plain", "Slow"]
    client.close()


def test_a_request_that_resets_may_not_act(serve: Serve) -> None:
    with Client(serve(PACED).address) as client:
        with pytest.raises(RemoteError) as refused:
            client.send_request(_reset_and_act())
            client.step_result(client.receive_reply())
        assert refused.value.code == ErrorCode.BAD_REQUEST
        assert "which ones start is known only once the reset ran" in refused.value.message
        observation, _ = client.reset(seed=0)  # still serving
        assert sorted(observation) == ["Fast", "Jerky", "Plain", "Slow"]


def _reset_and_act() -> Any:
    from rlenv.protocol import Request

    return Request(
        99,
        {"reset": {}, "action": dict.fromkeys(["Fast", "Slow", "Plain", "Jerky"], 1),
         "observation": {"agent": {}}},
    )  # fmt: skip


def test_a_snapshot_with_agents_that_came_and_went_replays_bit_for_bit(serve: Serve) -> None:
    with Client(serve(COME_AND_GO).address) as first, Client(serve(COME_AND_GO).address) as other:
        observation, _ = first.reset(seed=3)
        for _ in range(4):  # past C's arrival and B's departure
            observation, *_ = first.step(dict.fromkeys(observation, 2))
        snapshot = first.snapshot()
        restored, _ = other.restore(snapshot)
        assert sorted(restored) == sorted(observation) == ["A", "C"]
        for name in observation:
            assert restored[name].tobytes() == observation[name].tobytes()
        while True:
            one = first.step(dict.fromkeys(observation, 0))
            two = other.step(dict.fromkeys(observation, 0))
            assert sorted(one[0]) == sorted(two[0])
            for name in one[0]:
                assert one[0][name].tobytes() == two[0][name].tobytes()
            assert one[1:4] == two[1:4] and one[4]["agents"] == two[4]["agents"]
            observation = one[0]
            if one[2] or one[3]:
                break


def test_a_snapshot_restores_over_an_episode_whose_agents_all_left() -> None:
    """A reset keeps the settings of the agents in the tree, whoever played; a restore over
    an instance where those agents are gone (or not yet come) sets the ones there are."""
    first, fresh = LocalClient(COME_AND_GO), LocalClient(COME_AND_GO)
    answers = _play(first)
    assert answers[-1]["terminated"] or answers[-1]["truncated"]  # A and C left, B was freed
    first.configure(agent={"A": {"stride": 0.5}})  # A is still in the tree, out of play
    observation, _ = first.reset(seed=1)
    first.configure(agent={"B": {"stride": 3.0}})  # the new B, during the episode
    for _ in range(4):
        observation, *_ = first.step(dict.fromkeys(observation, 2))
    snapshot, at_snapshot = first.snapshot(), observation
    assert snapshot["config"]["agent"] == {"A": {"stride": 0.5}, "C": {"stride": 1.0}}
    for _ in range(10):  # to the end of the episode: no agent is left in play
        observation, _, terminated, truncated, _ = first.step(dict.fromkeys(observation, 2))
        if terminated or truncated:
            break
    assert terminated or truncated
    for client in (first, first, fresh):  # over the ended episode, twice; on a new instance
        restored, _ = client.restore(snapshot)
        assert sorted(restored) == sorted(at_snapshot) == ["A", "C"]
        for name in restored:
            assert restored[name].tobytes() == at_snapshot[name].tobytes()
    first.close()
    fresh.close()


def test_an_environment_without_declaration_nor_periods_answers_every_agent_as_ever() -> None:
    client = LocalClient("examples.pair:PairEnvironment")
    assert client.hello.possible_agents is None
    observation, _ = client.reset(seed=0)
    for _ in range(5):
        observation, *_ = client.step(client.action_space.sample())
        assert sorted(observation) == sorted(client.hello.agents)
    client.close()


def test_steps_columns_keep_a_slot_per_possible_agent_with_due_flags(serve: Serve) -> None:
    with Client(serve(COME_AND_GO, args=["--instances", "2"]).address) as client:
        every = {name: np.full(2, 2, np.int64) for name in "ABCD"}  # whole columns
        client.send_steps(every, reset=np.array([True, True]))
        start = client.receive_steps()
        assert {name: flags.tolist() for name, flags in start.due.items()} == {
            "A": [True, True], "B": [True, True], "C": [False, False], "D": [False, False]
        }  # fmt: skip
        assert start.observation["C"].tolist() == [[0.0, 0.0], [0.0, 0.0]]  # zeros: absent
        client.send_steps(every)
        client.receive_steps()
        client.send_steps(every)  # C joins at tick 6 in both instances
        joined = client.receive_steps()
        assert joined.due["C"].tolist() == [True, True]
        assert joined.info[0]["agents"]["C"]["reward"] is None
        assert joined.observation["C"].tolist() == [[0.0, 8.0], [0.0, 8.0]]
        client.send_steps(every)  # B freed at tick 10: its last row, then never again
        left = client.receive_steps()
        assert left.due["B"].tolist() == [True, True]
        assert left.info[1]["agents"]["B"]["terminated"]
        client.send_steps(every)
        after = client.receive_steps()
        assert after.due["B"].tolist() == [False, False]
        assert after.observation["B"].tolist() == [[0.0, 0.0], [0.0, 0.0]]


def test_driven_agents_due_on_the_way_decide_in_the_server_and_replay_bit_for_bit() -> None:
    prey = {f"Prey{number}": "heuristic" for number in range(1, 9)}
    first = LocalClient("examples.hunt:HuntEnvironment", policies=prey)
    other = LocalClient("examples.hunt:HuntEnvironment", policies=prey)
    observation, _ = first.reset(seed=5)
    for _ in range(30):  # prey decide at ticks 2, 6, ... in the server, between the hunter's
        observation, _, _, _, info = first.step({"Hunter": observation["Hunter"][4:6] / 10})
        assert info["frames"] == 4 and "Hunter" in observation
    snapshot = first.snapshot()
    restored, _ = other.restore(snapshot)
    assert restored["Hunter"].tobytes() == observation["Hunter"].tobytes()
    for _ in range(30):
        action = {"Hunter": observation["Hunter"][4:6] / 10}
        one, two = first.step(action), other.step(action)
        assert sorted(one[0]) == sorted(two[0])
        assert all(one[0][name].tobytes() == two[0][name].tobytes() for name in one[0])
        assert one[1:4] == two[1:4]
        observation = one[0]
        if one[2] or one[3]:
            break
    first.close()
    other.close()


def test_real_time_is_refused_where_agents_come_and_go() -> None:
    client = LocalClient(PACED)
    with pytest.raises(RemoteError) as refused:
        client.configure(real_time=True)
    assert refused.value.code == ErrorCode.INVALID_CONFIG
    assert "real_time is not supported where agents come and go" in refused.value.message
    observation, _ = client.reset(seed=0)  # lockstep, as ever
    assert sorted(observation) == ["Fast", "Jerky", "Plain", "Slow"]
    client.close()
