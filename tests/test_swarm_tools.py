"""The tools with a group of agents (issue 46): check, recordings and replay, timelines, the
inspector's timeline JSON and page, datasets; on ``tests/swarm_envs.py``'s group alone and the
group beside an ordinary agent (members leave at the edge, one joins at tick 10). Real servers
and subprocesses throughout.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Serve
from inspector_http import fetch
from tool_runs import Recorded, Seen, assert_replays_bit_for_bit, report_lines, rlenv

from rlenv_client.env import RemoteEnv
from rlenv_client.replay import EpisodeFile, RecordEpisodes, digest
from rlenv_tools.inspector import InspectorServer, Timelines, Watcher
from rlenv_tools.timeline import Timeline

SWARM = "tests.swarm_envs:SwarmEnvironment"
MIXED = "tests.swarm_envs:MixedEnvironment"
MEMBERS = 8


# --- rlenv check ---------------------------------------------------------------------------------

# PettingZoo's members as named agents are the adaptors' (branch h-swarm-adaptors): its
# parallel_api_test is left to their tests here.
ADAPTORS = {"pettingzoo parallel_api_test"}


@pytest.mark.parametrize("target", [SWARM, MIXED])
def test_check_passes_on_a_group(target: str) -> None:
    result = rlenv("check", target)
    checks = report_lines(result.stdout)
    assert checks["gymnasium check_env"] == "PASS", result.stdout
    assert checks["step returns gymnasium types"] == "PASS"
    assert checks["a bad action is refused and changes nothing"] == "PASS"
    assert {name for name, status in checks.items() if status == "FAIL"} <= ADAPTORS, result.stdout


@pytest.mark.parametrize("target", [SWARM, MIXED])
def test_compliance_passes_on_a_group(serve: Serve, target: str) -> None:
    server = serve(target)
    result = rlenv("check", server.address, "--compliance")
    checks = report_lines(result.stdout)
    assert checks["compliance under hostile input"] == "PASS", result.stdout


# --- recordings and replay -----------------------------------------------------------------------


def record(target: str, directory: Path, seed: int) -> Recorded:
    """One whole episode of ``target``, random actions (members leave at the edge)."""
    env = RecordEpisodes(RemoteEnv(target, max_restarts=0, share_server=False), directory)
    rng = np.random.default_rng(seed)
    seen = Seen()
    try:
        observation, info = env.reset(seed=seed)
        seen.observations.append(observation)
        seen.agents.append(info.get("agents", {}))
        while True:
            action = {
                name: rng.uniform(-1, 1, space.shape).astype(np.float32)
                for name, space in env.action_space.spaces.items()
            }
            observation, _, terminated, truncated, info = env.step(action)
            seen.actions.append(action)
            seen.observations.append(observation)
            seen.agents.append(info["agents"])
            if terminated or truncated:
                break
    finally:
        env.close()
    return Recorded(directory / "episode-0001.rlenv", seen)


@pytest.fixture(scope="module")
def swarm(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    return record(SWARM, tmp_path_factory.mktemp("swarm"), seed=1)


@pytest.fixture(scope="module")
def mixed(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    return record(MIXED, tmp_path_factory.mktemp("mixed"), seed=2)


def members_seen(seen: Seen) -> tuple[list[int], list[int], np.ndarray]:
    """Each member's arrival and departure step (-1: none) and return, from what the client saw,
    one member at a time (the tools do it an array at a time)."""
    arrivals, departures, returns = [-1] * MEMBERS, [-1] * MEMBERS, np.zeros(MEMBERS)
    for step, agents in enumerate(seen.agents[1:], start=1):
        rows = agents["Discs"]
        for i in range(MEMBERS):
            if not rows["active"][i]:
                continue
            if arrivals[i] < 0:
                arrivals[i] = step if rows["joined"][i] else 0
            returns[i] += rows["reward"][i]
            if departures[i] < 0 and (rows["terminated"][i] or rows["truncated"][i]):
                departures[i] = step
    return arrivals, departures, returns


def test_the_recordings_hold_members_that_came_and_went(swarm: Recorded, mixed: Recorded) -> None:
    for recorded in (swarm, mixed):
        arrivals, departures, _ = members_seen(recorded.seen)
        assert 0 < max(arrivals) and sum(a == 0 for a in arrivals) == 6  # 6 start, one joins
        assert any(d >= 0 for d in departures)
        assert recorded.seen.observations[1]["Discs"].shape == (MEMBERS, 4)


@pytest.mark.parametrize("recorded", ["swarm", "mixed"])
def test_a_group_replays_bit_for_bit(recorded: str, request: pytest.FixtureRequest) -> None:
    path = request.getfixturevalue(recorded).path
    assert_replays_bit_for_bit(path)


def test_a_replay_finds_a_member_action_that_differs(mixed: Recorded, tmp_path: Path) -> None:
    episode = EpisodeFile.load(mixed.path)
    events = [list(event) for event in episode.snapshot["events"]]
    actions = [event for event in events if event[0] == "action"]
    pushed = np.array(actions[4][1]["Discs"], np.float32)
    pushed[2] = -pushed[2]  # one member of eight pushes the other way at step 5
    actions[4][1] = {**actions[4][1], "Discs": pushed}
    replace(episode, snapshot={**episode.snapshot, "events": events}).save(
        tmp_path / "tampered.rlenv"
    )
    result = rlenv("replay", str(tmp_path / "tampered.rlenv"), "--trust-target")
    assert result.returncode == 1
    assert "first divergence at step 5" in result.stdout


# --- timelines -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def mixed_timeline(mixed: Recorded) -> Iterator[Timeline]:
    with Timeline.open(mixed.path, trust_target=True, checkpoint_every=8) as timeline:
        yield timeline


def test_a_group_timeline_scrubs_bit_for_bit(mixed_timeline: Timeline, mixed: Recorded) -> None:
    seen = mixed.seen
    assert len(mixed_timeline) == len(seen.actions)
    for step in (len(seen.actions), 3, 0, 17, 4):
        state = mixed_timeline.at(step)
        assert digest(state.observation) == digest(seen.observations[step])
        if step:
            assert digest(state.info["agents"]) == digest(seen.agents[step])


def test_a_group_timeline_says_who_played_and_what_each_member_earned(
    mixed_timeline: Timeline, mixed: Recorded
) -> None:
    arrivals, departures, returns = members_seen(mixed.seen)
    members = mixed_timeline.agents.members("Discs")
    assert members.arrivals.tolist() == arrivals
    assert members.departures.tolist() == departures
    assert members.returns.tolist() == pytest.approx(returns.tolist(), abs=1e-12)
    steps = np.arange(len(mixed_timeline) + 1)
    for i in range(MEMBERS):
        expected = (arrivals[i] >= 0) & (steps >= arrivals[i])
        if departures[i] >= 0:
            expected &= steps <= departures[i]
        assert members.in_play[:, i].tolist() == expected.tolist()
    group_return = mixed_timeline.agents.returns()["Discs"]
    assert isinstance(group_return, float)
    assert group_return == pytest.approx(float(returns.sum()), abs=1e-9)
    shepherd = sum(agents["Shepherd"]["reward"] for agents in mixed.seen.agents[1:])
    assert mixed_timeline.agents.returns()["Shepherd"] == pytest.approx(shepherd, abs=0)
    ended = max(departures)  # the group, as one agent, leaves with its last member
    assert mixed_timeline.agents.departures()["Discs"] == ended
    assert "Discs" not in mixed_timeline.agents.in_play()[ended + 1 :][0]
    with pytest.raises(KeyError, match="no group 'Shepherd'"):
        mixed_timeline.agents.members("Shepherd")


def test_a_group_timeline_ticks_and_branches(mixed_timeline: Timeline, mixed: Recorded) -> None:
    ticks = mixed_timeline.ticks(3)  # the step member 6 joins in
    assert len(ticks) == mixed_timeline.frames(3)
    assert digest(ticks[-1].observation) == digest(mixed_timeline.at(3).observation)
    again = mixed_timeline.branch(10, mixed.seen.actions[10:])
    assert mixed_timeline.diff(again).first_difference is None
    assert again.agents.members("Discs").departures.tolist() == (
        mixed_timeline.agents.members("Discs").departures.tolist()
    )


# --- the inspector -------------------------------------------------------------------------------


def test_the_inspector_shows_a_groups_members_and_return(mixed: Recorded) -> None:
    arrivals, departures, returns = members_seen(mixed.seen)
    page = InspectorServer(Watcher([]), timelines=Timelines([mixed.path], trust_target=True))
    page.start()
    try:
        joined = max(arrivals)
        status, _, state = fetch(page.url, f"api/timeline/step?timeline=0&branch=0&step={joined}")
        assert status == 200, state
        group = state["groups"]["Discs"]
        assert group["arrived"] == [i for i in range(MEMBERS) if arrivals[i] == joined]
        assert group["in_play"] == sum(
            0 <= arrivals[i] <= joined and (departures[i] < 0 or joined <= departures[i])
            for i in range(MEMBERS)
        )
        assert group["returns"] == pytest.approx(returns.tolist(), abs=1e-12)
        assert isinstance(state["agent_returns"]["Discs"], float)
        left = min(d for d in departures if d >= 0)
        status, _, state = fetch(page.url, f"api/timeline/step?timeline=0&branch=0&step={left}")
        assert state["groups"]["Discs"]["left"] == [
            i for i in range(MEMBERS) if departures[i] == left
        ]
        status, _, described = fetch(page.url, "api/timeline?timeline=0")
        assert status == 200 and isinstance(described["agent_returns"]["Discs"], float)
    finally:
        page.close()


def discs_in_space(seen: Seen, step: int) -> int:
    """The discs in the space after ``step``: members that arrived and did not leave at the
    edge (their disc leaves the space; a truncated one stays), and the shepherd's."""
    arrivals, _, _ = members_seen(seen)
    out = {
        i
        for agents in seen.agents[1 : step + 1]
        for i in np.flatnonzero(agents["Discs"]["active"] & agents["Discs"]["terminated"])
    }
    return sum(0 <= arrivals[i] <= step and i not in out for i in range(MEMBERS)) + 1


def test_the_inspector_draws_a_groups_bodies(tmp_path: Path) -> None:
    drawn = record("tests.drawn_swarm_envs:DrawnMixedEnvironment", tmp_path, seed=3)
    arrivals, departures, _ = members_seen(drawn.seen)
    first_out = min(d for d in departures if d >= 0)
    page = InspectorServer(Watcher([]), timelines=Timelines([drawn.path], trust_target=True))
    page.start()
    try:
        for step in (0, max(arrivals), first_out):
            status, _, state = fetch(page.url, f"api/timeline/step?timeline=0&branch=0&step={step}")
            assert status == 200, state
            circles = [shape for shape in state["draw"]["shapes"] if shape[0] == "circle"]
            assert len(circles) == discs_in_space(drawn.seen, step), step
        assert discs_in_space(drawn.seen, 0) == 7 and discs_in_space(drawn.seen, max(arrivals)) > 7
    finally:
        page.close()


@pytest.mark.browser
def test_the_page_shows_a_groups_members(mixed: Recorded) -> None:
    from browser import Browser, find_chromium

    chromium = find_chromium()
    if chromium is None:
        pytest.skip("no Chromium found (apt-get install chromium): the JSON is tested above")
    arrivals, _, _ = members_seen(mixed.seen)
    joined = max(arrivals)
    page = InspectorServer(Watcher([]), timelines=Timelines([mixed.path], trust_target=True))
    page.start()
    try:
        with Browser(chromium) as browser:
            browser.open(page.url)
            agents = "document.getElementById('timeline-agents')"
            browser.wait_for(f"{agents}.dataset.members === 'Discs:6'", "members not shown")
            browser.evaluate(f"""(() => {{ const s = document.getElementById('scrubber');
                s.value = {joined}; s.dispatchEvent(new Event('input')); }})()""")
            browser.wait_for(f"{agents}.textContent.includes('+1]')", "the joined member")
            text = browser.evaluate(f"{agents}.textContent")
            assert "Discs [7 members +1]" in text and "returns: " in text
    finally:
        page.close()


# --- datasets ------------------------------------------------------------------------------------


def member_lives_seen(seen: Seen) -> list[dict[str, Any]]:
    """Each member's life as the client saw it, member by member, step by step."""
    arrivals, departures, _ = members_seen(seen)
    lives = []
    for i in range(MEMBERS):
        if arrivals[i] < 0:
            continue
        end = departures[i] if departures[i] >= 0 else len(seen.actions)
        answers = list(range(arrivals[i], end + 1))
        last = seen.agents[end]["Discs"]
        lives.append(
            {
                "observations": np.stack([seen.observations[k]["Discs"][i] for k in answers]),
                "actions": np.stack([seen.actions[k]["Discs"][i] for k in answers[:-1]]),
                "rewards": [float(seen.agents[k]["Discs"]["reward"][i]) for k in answers[1:]],
                "terminated": bool(last["terminated"][i]),
                "truncated": bool(last["truncated"][i]) or departures[i] < 0,
            }
        )
    return lives


@pytest.mark.minari
@pytest.mark.parametrize("recorded", ["swarm", "mixed"])
def test_a_groups_members_become_a_dataset_each_life_an_episode(
    recorded: str, request: pytest.FixtureRequest, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    minari = pytest.importorskip("minari")
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    chosen = request.getfixturevalue(recorded)
    result = rlenv(
        "dataset", "create", "swarm/discs-v0", "--from", str(chosen.path.parent), "--trust-target"
    )
    assert result.returncode == 0, result.stdout + result.stderr
    lives = member_lives_seen(chosen.seen)
    steps = sum(len(life["actions"]) for life in lives)
    assert f"wrote dataset swarm/discs-Discs-v0: {len(lives)} episodes, {steps} steps" in (
        result.stdout
    )
    dataset = minari.load_dataset("swarm/discs-Discs-v0")
    assert dataset.spec.observation_space.shape == (4,)  # one member's
    episodes = list(dataset.iterate_episodes())
    assert len(episodes) == len(lives) == 7  # 6 started, one joined
    for episode, life in zip(episodes, lives, strict=True):
        assert episode.observations.tobytes() == life["observations"].tobytes()
        assert episode.actions.tobytes() == life["actions"].tobytes()
        assert list(episode.rewards) == life["rewards"]
        assert bool(episode.terminations[-1]) == life["terminated"]
        assert bool(episode.truncations[-1]) == life["truncated"]
    if recorded == "mixed":  # the shepherd: its one life, the whole episode
        shepherd = minari.load_dataset("swarm/discs-Shepherd-v0")
        assert shepherd.total_episodes == 1 and shepherd.total_steps == len(chosen.seen.actions)


# --- a group that decides every 3 ticks ----------------------------------------------------------


@pytest.fixture(scope="module")
def paced(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    """PacedSwarmEnvironment's episode, recorded from a Client's answers (the group is in the
    answers where it decides, and in those where a member left)."""
    from rlenv_client.replay import outcome_digest
    from rlenv_client.session import Session

    target = "tests.swarm_envs:PacedSwarmEnvironment"
    session = Session(target)
    rng = np.random.default_rng(5)
    seen = Seen()
    try:
        client = session.client
        observation, info = client.reset(seed=5)
        seen.observations.append(observation)
        seen.agents.append(info.get("agents", {}))
        digests, outcomes = [digest(observation)], []
        while True:
            action = {"Discs": rng.uniform(-1, 1, (MEMBERS, 2)).astype(np.float32)}
            observation, reward, terminated, truncated, info = client.step(action)
            seen.actions.append(action)
            seen.observations.append(observation)
            seen.agents.append(info["agents"])
            digests.append(digest(observation))
            outcomes.append(outcome_digest(reward, terminated, truncated, info))
            if terminated or truncated:
                break
        path = tmp_path_factory.mktemp("paced") / "episode-0001.rlenv"
        EpisodeFile(
            target, client.snapshot(), digests, terminated, truncated, outcomes=outcomes
        ).save(path)
    finally:
        session.close()
    return Recorded(path, seen)


def test_a_paced_group_replays_and_scrubs_bit_for_bit(paced: Recorded) -> None:
    assert_replays_bit_for_bit(paced.path)
    arrivals, departures, returns = members_seen(paced.seen)
    with Timeline.open(paced.path, trust_target=True) as timeline:
        for step in (len(timeline), 2, 7):
            assert digest(timeline.at(step).observation) == digest(paced.seen.observations[step])
        members = timeline.agents.members("Discs")
        assert members.arrivals.tolist() == arrivals and max(arrivals) > 0
        assert members.departures.tolist() == departures
        assert members.returns.tolist() == pytest.approx(returns.tolist(), abs=1e-12)
        assert timeline.frames(1) == 3  # the group decides every 3 ticks
        ticks = timeline.ticks(4)  # tick 10: a member joins inside this step
        assert digest(ticks[-1].observation) == digest(timeline.at(4).observation)
