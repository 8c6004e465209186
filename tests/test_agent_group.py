"""A group of agents (issue 46): ``RLAgentGroup``, its members as arrays, on the wire and back.

The environments are ``tests/swarm_envs.py``'s: 8 discs (6 start, one joins at tick 10), pushed
by their actions into each other and out of the square, where they leave; a time limit
truncates those left. The wire's checks run over ``rlenv serve`` subprocesses, the rest in
process (``LocalClient``: the server's own code path).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from answers import play
from conftest import Serve
from gymnasium import spaces

from rlenv import RLAgentGroup
from rlenv.protocol import GroupSpec
from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv_client import Client, LocalClient, ServerStartError

TESTS = Path(__file__).parent
SWARM = "swarm_envs:SwarmEnvironment"
MIXED = "swarm_envs:MixedEnvironment"
PACED = "swarm_envs:PacedSwarmEnvironment"
DISCRETE = "swarm_envs:DiscreteSwarmEnvironment"
PUSH = np.tile(np.array([1.0, 0.3], np.float32), (8, 1))  # every disc to the right, a little up


@pytest.fixture(autouse=True)
def _tests_on_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(TESTS))
    path = os.pathsep.join(filter(None, [str(TESTS), os.environ.get("PYTHONPATH")]))
    monkeypatch.setenv("PYTHONPATH", path)


def _play(client: Any, seed: int = 1, steps: int = 60) -> list[dict[str, Any]]:
    """Reset, then push the discs until the episode ends: every answer (copies of its arrays)."""
    action = {"Discs": PUSH}
    if "Shepherd" in client.hello.agents:
        action["Shepherd"] = np.array([0.0, 1.0], np.float32)
    return play(client, lambda _: dict(action), seed, steps)


def _group(client: LocalClient) -> Any:
    """The group node of a LocalClient's (first) environment."""
    return client.host.instances[0].environment.get_node("Discs")  # type: ignore[union-attr]


# --- spaces and the hello --------------------------------------------------------------------


def test_the_hello_lists_the_group_with_its_members_spaces_and_stacked_ones(serve: Serve) -> None:
    with Client(serve(MIXED).address) as client:
        assert client.hello.protocol == (2, 7)
        assert client.hello.agents == ("Discs", "Shepherd")
        member_observation = spaces.Box(-50.0, 50.0, (4,), np.float32)
        member_action = spaces.Box(-1.0, 1.0, (2,), np.float32)
        assert client.groups == {"Discs": GroupSpec(8, member_observation, member_action)}
        assert client.observation_space["Discs"] == spaces.Box(-50.0, 50.0, (8, 4), np.float32)
        assert client.action_space["Discs"] == spaces.Box(-1.0, 1.0, (8, 2), np.float32)
        assert client.hello.possible_agents is None  # a fixed group: every agent in every answer


def test_a_group_alone_still_has_keyed_spaces_and_discrete_members_stack(serve: Serve) -> None:
    with Client(serve(DISCRETE).address) as client:
        assert list(client.observation_space.spaces) == ["Discs"]
        assert client.action_space["Discs"] == spaces.MultiDiscrete([5] * 8)
        assert client.groups["Discs"].action_space == spaces.Discrete(5)
        client.reset(seed=0)
        observation, _, _, _, info = client.step({"Discs": np.full(8, 1, np.int64)})
        assert observation["Discs"].shape == (8, 4)
        assert info["agents"]["Discs"]["reward"].shape == (8,)


def test_an_environment_without_a_group_says_so_in_its_hello() -> None:
    client = LocalClient("examples.pair:PairEnvironment")
    assert client.groups == {} and client.hello.groups == {}
    client.close()


def test_member_spaces_and_counts_outside_the_rules_are_refused_naming_the_class() -> None:
    box = spaces.Box(-1.0, 1.0, (2,), np.float32)

    def group(**attributes: Any) -> type[RLAgentGroup]:
        defaults = {"instance_count": 4, "member_observation_space": box}
        defaults["member_action_space"] = box
        return type("Herd", (RLAgentGroup,), {**defaults, **attributes})

    for count in (0, 65_537, 2.0, None):
        with pytest.raises(ValueError, match=r"Herd.instance_count must be an integer in 1..65536"):
            group(instance_count=count)()
    nested = spaces.Dict({"a": box})
    with pytest.raises(TypeError, match="Herd.member_action_space is a Dict: a group's members"):
        group(member_action_space=nested)()
    with pytest.raises(TypeError, match="Herd must set member_observation_space"):
        group(member_observation_space=None)()
    with pytest.raises(TypeError, match="Herd sets observation_space: a group derives it"):
        group(observation_space=box)()
    assert group()().observation_space == spaces.Box(-1.0, 1.0, (4, 2), np.float32)


def test_a_server_of_a_group_with_a_bad_count_does_not_start_and_says_why(serve: Serve) -> None:
    with pytest.raises(ServerStartError, match=r"TooManyDiscs.instance_count must be an integer"):
        serve("swarm_envs:BadCountEnvironment")


# --- the arrays --------------------------------------------------------------------------------


def test_the_groups_arrays_are_allocated_once_and_written_in_place() -> None:
    client = LocalClient(SWARM)
    group = _group(client)
    arrays = [group.observations, group.actions, group.rewards, group.terminations]
    arrays += [group.truncations, group.active]
    client.reset(seed=1)
    for _ in range(4):
        client.step({"Discs": PUSH})
    assert all(a is b for a, b in zip(arrays, [group.observations, group.actions, group.rewards,
               group.terminations, group.truncations, group.active], strict=True))  # fmt: skip
    assert np.array_equal(group.applied[-1][:6], PUSH[:6])  # set_action copied the action in
    group.rewards += 0.0  # in place: allowed
    with pytest.raises(AttributeError, match=r"Discs.rewards is allocated once .* never replace"):
        group.rewards = np.zeros(8)
    with pytest.raises(ValueError, match="read-only"):
        group.active[0] = False
    with pytest.raises(AttributeError):
        group.active = np.ones(8, bool)
    client.close()


def test_members_out_of_play_get_no_action_rows_and_zero_observation_rows() -> None:
    client = LocalClient(SWARM)
    group = _group(client)
    observation, info = client.reset(seed=1)
    assert info["agents"]["Discs"]["active"].tolist() == [True] * 6 + [False] * 2
    assert not observation["Discs"][6:].any()  # slots 6, 7 are not in play yet
    client.step({"Discs": np.ones((8, 2), np.float32)})
    assert not group.applied[-1][6:].any()  # rows out of play: no_action's (zero force)
    client.close()


# --- members that come and go ----------------------------------------------------------------


def test_a_reset_chooses_who_starts_and_a_slot_left_out_is_free_to_join() -> None:
    client = LocalClient("swarm_envs:ChosenSwarmEnvironment")
    group = _group(client)
    answers = _play(client, steps=3)
    assert answers[0]["agents"]["Discs"]["active"].tolist() == [False] + [True] * 5 + [False, True]
    assert not answers[0]["agents"]["Discs"]["joined"].any()  # starting is not joining
    assert answers[3]["agents"]["Discs"]["joined"].tolist() == [True] + [False] * 7  # slot 0
    assert group.applied[0][6].tolist() == [-1.0, 0.0]  # out of play: the overridden no_action
    assert group.applied[0][7].tolist() == pytest.approx([1.0, 0.3])
    client.close()


def test_members_leave_once_with_a_final_transition_and_are_never_observed_again() -> None:
    client = LocalClient(SWARM)
    answers = _play(client)
    last = answers[-1]
    assert last["terminated"] and not last["truncated"]  # every member left at the edge
    ended_at = {}
    for number, answer in enumerate(answers[1:], 1):
        group = answer["agents"]["Discs"]
        for member in np.flatnonzero(group["terminated"]):
            assert member not in ended_at, f"member {member} ended twice"
            ended_at[int(member)] = number
            assert group["active"][member]  # its final transition is reported...
            final = answer["observation"]["Discs"][member]
            assert abs(final[:2]).max() > 3.0  # ...with its observation past the edge
        for member, number_ended in ended_at.items():
            if number > number_ended:  # ...then never again
                assert not group["active"][member] and not group["terminated"][member]
                assert group["reward"][member] == 0.0
                assert not answer["observation"]["Discs"][member].any()
    assert sorted(ended_at) == [0, 1, 2, 3, 4, 5, 6]  # slot 7 never played
    assert last["frames"] < 4  # the step stopped when the last member left, not before
    assert all(answer["frames"] == 4 for answer in answers[1:-1])  # one member's end: no stop


def test_a_member_joins_once_with_reward_zero_and_takes_the_lowest_free_slot() -> None:
    client = LocalClient(SWARM)
    answers = _play(client)
    joined = [number for number, a in enumerate(answers) if a["agents"]["Discs"]["joined"].any()]
    assert joined == [3]  # tick 10 is in the third step (ticks 9 to 12)
    group = answers[3]["agents"]["Discs"]
    assert group["joined"].tolist() == [False] * 6 + [True, False]
    assert group["active"][6] and group["reward"][6] == 0.0
    assert answers[3]["observation"]["Discs"][6].any()  # observed from its first transition
    assert answers[4]["agents"]["Discs"]["reward"][6] < 0.0  # then rewarded as the others
    assert answers[3]["reward"] == pytest.approx(group["reward"].sum())
    client.close()


def test_hostile_member_changes_are_environment_errors_naming_the_group_and_it_serves_on() -> None:
    client = LocalClient(SWARM)
    for setting, message in [
        ("overfill", "group Discs has no free member slot: its instance_count of 8 are all used"),
        ("rejoin", "member 0 of group Discs already played in this episode"),
        ("remove_twice", "member 5 of group Discs is not in play"),
        ("nan", "the observation of member 1 of group /root/Swarm/Discs is not finite at [1, 0]"),
    ]:
        client.configure(world={setting: True})
        client.reset(seed=0)
        with pytest.raises(RemoteError) as refused:
            client.step({"Discs": PUSH})
        assert refused.value.code == ErrorCode.ENVIRONMENT_ERROR
        assert message in refused.value.message
        client.configure(world={setting: False})
        client.reset(seed=0)
        assert client.step({"Discs": PUSH})[4]["frames"] == 4  # serving on
    client.close()


def test_wrong_group_actions_are_refused_precisely_and_the_server_serves_on(serve: Serve) -> None:
    with Client(serve(SWARM).address) as client:
        client.reset(seed=0)
        for action, message in [
            ({"Discs": np.zeros((7, 2), np.float32)}, "action['Discs']"),
            ({"Discs": np.zeros((8, 3), np.float32)}, "action['Discs']"),
            ({"Discs": np.full((8, 2), 2.0, np.float32)}, "action['Discs']"),
            ({"Discs": np.full((8, 2), np.nan, np.float32)}, "action['Discs']"),
            (np.zeros((8, 2), np.float32), "map from agent name"),
            ({}, "no action for agent 'Discs'"),
        ]:
            with pytest.raises(RemoteError) as refused:
                client.step(action)
            assert refused.value.code == ErrorCode.INVALID_ACTION
            assert message in refused.value.message
        assert client.step({"Discs": PUSH})[4]["frames"] == 4


# --- the episode's end, decision periods, a group beside an agent ------------------------------


def test_the_group_ends_truncated_when_every_member_that_left_was_truncated() -> None:
    client = LocalClient(SWARM)
    client.reset(seed=0)
    for _ in range(40):  # no push: the discs stay in the square until the time limit
        _, _, terminated, truncated, info = client.step({"Discs": np.zeros((8, 2), np.float32)})
        if terminated or truncated:
            break
    assert truncated and not terminated
    group = info["agents"]["Discs"]
    assert group["truncated"].tolist() == [True] * 7 + [False]  # slot 7 never played
    assert not group["terminated"].any()
    client.close()


def test_a_group_with_a_decision_period_decides_as_a_whole_and_reports_ends_at_decisions() -> None:
    client = LocalClient(PACED)
    assert client.hello.possible_agents == {"Discs": "PacedDiscs"}
    answers = _play(client)
    assert all(answer["frames"] == 3 for answer in answers[1:-1])
    ended = np.zeros(8, int)
    for answer in answers[1:]:
        ended += answer["agents"]["Discs"]["terminated"]
    assert ended.tolist() == [1] * 7 + [0]  # each final transition once, the last one's too
    assert answers[-1]["terminated"]
    client.close()


def test_a_group_beside_an_ordinary_agent_answers_both(serve: Serve) -> None:
    with Client(serve(MIXED).address) as client:
        answers = _play(client)
    for answer in answers[1:]:
        shepherd, discs = answer["agents"]["Shepherd"], answer["agents"]["Discs"]
        assert set(shepherd) == {"reward", "terminated", "truncated"}
        assert answer["reward"] == pytest.approx(shepherd["reward"] + discs["reward"].sum())
        assert answer["observation"]["Shepherd"].shape == (2,)
    gone = [n for n, a in enumerate(answers) if not a["agents"]["Discs"]["active"].any()]
    assert gone and gone[0] < len(answers) - 1  # the group ended, the shepherd went on
    assert answers[-1]["truncated"] and answers[-1]["agents"]["Shepherd"]["truncated"]


# --- steps, snapshots, replays -------------------------------------------------------------------


def test_steps_columns_stack_each_instances_group_array(serve: Serve) -> None:
    with Client(serve(MIXED, args=["--instances", "3"]).address) as client:
        action = {"Discs": np.tile(PUSH, (3, 1, 1)), "Shepherd": np.zeros((3, 2), np.float32)}
        client.send_steps(action, reset=np.ones(3, bool))
        start = client.receive_steps()
        assert start.observation["Discs"].shape == (3, 8, 4)
        for _ in range(3):  # the member at slot 6 joins in the third step
            client.send_steps(action)
            answer = client.receive_steps()
        for row in range(3):
            group = answer.info[row]["agents"]["Discs"]
            assert group["joined"].tolist() == [False] * 6 + [True, False]
            assert answer.reward[row] == pytest.approx(
                group["reward"].sum() + answer.info[row]["agents"]["Shepherd"]["reward"]
            )
        assert np.array_equal(answer.observation["Discs"][0], answer.observation["Discs"][2])


def _same(one: Any, two: Any) -> None:
    assert sorted(one[0]) == sorted(two[0])
    for name in one[0]:
        assert one[0][name].tobytes() == two[0][name].tobytes()
    assert one[1:4] == two[1:4]
    for name, outcome in one[4]["agents"].items():
        other = two[4]["agents"][name]
        for key, value in outcome.items():
            assert np.asarray(value).tobytes() == np.asarray(other[key]).tobytes(), (name, key)


@pytest.mark.parametrize("target", [SWARM, PACED])
def test_a_snapshot_with_members_that_came_and_went_replays_bit_for_bit(
    serve: Serve, target: str
) -> None:
    with Client(serve(target).address) as first, Client(serve(target).address) as other:
        observation, _ = first.reset(seed=3)
        for _ in range(6):  # past the join (tick 10) and the first departures
            observation, _, _, _, info = first.step({"Discs": PUSH})
        group = info["agents"]["Discs"]
        in_play = group["active"] & ~group["terminated"]
        assert in_play.sum() < 7
        restored, restored_info = other.restore(first.snapshot())
        assert restored_info["agents"]["Discs"]["active"].tolist() == in_play.tolist()
        # the restore's answer tells no final transition (the original's last answer did)
        assert restored["Discs"][in_play].tobytes() == observation["Discs"][in_play].tobytes()
        assert not restored["Discs"][~in_play].any()
        while True:
            one, two = first.step({"Discs": PUSH}), other.step({"Discs": PUSH})
            _same(one, two)
            if one[2] or one[3]:
                break


def test_a_kept_episode_with_members_that_came_and_went_replays_bit_for_bit(serve: Serve) -> None:
    with Client(serve(SWARM, args=["--keep-episodes", "2"]).address) as client:
        answers = _play(client, seed=4)
        client.reset(seed=5)  # finishes the episode: the server keeps it
        (episode,) = client.episodes(last=1)
    assert episode.terminated and not episode.truncated
    events = episode.snapshot["events"]
    actions = [number for number, event in enumerate(events) if event[0] == "action"]
    assert len(actions) == len(answers) - 1
    with Client(serve(SWARM).address) as other:
        for step in range(1, len(answers) - 1):  # its log replayed to each step
            cut = {**episode.snapshot, "events": events[: actions[step - 1] + 1]}
            restored, info = other.restore(cut)
            group = answers[step]["agents"]["Discs"]
            in_play = group["active"] & ~group["terminated"]
            assert info["agents"]["Discs"]["active"].tolist() == in_play.tolist()
            expected = answers[step]["observation"]["Discs"][in_play]
            assert restored["Discs"][in_play].tobytes() == expected.tobytes()


def test_steps_of_a_paced_group_say_where_it_is_due(serve: Serve) -> None:
    with Client(serve(PACED, args=["--instances", "2"]).address) as client:
        action = {"Discs": np.tile(PUSH, (2, 1, 1))}
        client.send_steps(action, reset=np.ones(2, bool))
        assert client.receive_steps().due["Discs"].tolist() == [True, True]
        client.send_steps(action)
        answer = client.receive_steps()
        assert answer.frames.tolist() == [3, 3]  # the group's period
        assert answer.due["Discs"].tolist() == [True, True]
        assert answer.observation["Discs"].shape == (2, 8, 4)
        assert answer.info[0]["agents"]["Discs"]["active"].sum() == 6


def test_an_observer_sees_the_members_in_play_and_takes_no_reward(serve: Serve) -> None:
    server = serve(SWARM)
    with Client(server.address) as trainer, Client(server.address) as observer:
        trainer.reset(seed=0)
        trainer.step({"Discs": PUSH})
        seen, reward, _, _, info = observer.poll()
        assert reward == 0.0 and not info["agents"]["Discs"]["reward"].any()
        assert info["agents"]["Discs"]["active"].tolist() == [True] * 6 + [False] * 2
        _, reward, _, _, info = trainer.step({"Discs": PUSH})
    alone = _play(LocalClient(SWARM), seed=0, steps=2)[2]  # the same steps, no observer
    assert reward == alone["reward"] < 0.0
    assert (
        info["agents"]["Discs"]["reward"].tobytes() == alone["agents"]["Discs"]["reward"].tobytes()
    )


def test_member_slots_out_of_range_or_not_ints_are_refused_naming_the_group() -> None:
    from swarm_envs import Discs

    group = Discs("Herd")
    group._members.begin()  # a reset's start: slots 0 to 5 in play
    for index, message in [
        (8, "member 8 is out of range: group Herd has slots 0..7"),
        (-1, "member -1 is out of range"),
        (True, "a member is an int slot in 0..7, got True"),
        (2.0, "a member is an int slot in 0..7, got 2.0"),
    ]:
        with pytest.raises(ValueError, match=message):
            group.add_member(index)
    assert group.add_member() == 6 and group.add_member(np.int64(7)) == 7
    with pytest.raises(ValueError, match="group Herd has no free member slot"):
        group.add_member()
