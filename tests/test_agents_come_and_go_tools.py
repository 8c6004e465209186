"""The tools where agents come and go and decide at their own pace (issue 42, item 4's tools).

``rlenv check`` and its compliance suite, recordings and ``rlenv replay``, timelines, the
inspector's timeline JSON and ``rlenv dataset create``, on the hunt (prey that appear and are
caught, two decision periods), ``tests/come_and_go_envs.py``'s environments, and the fixed
multi-agent tag, which must stay as it was. Real servers and subprocesses throughout.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Serve
from inspector_http import fetch
from tool_runs import Recorded, Seen, assert_replays_bit_for_bit, record_one, report_lines, rlenv

from examples import hunt, tag
from rlenv.protocol import Response
from rlenv_client.env import RemoteEnv
from rlenv_client.replay import EpisodeFile, digest
from rlenv_tools.compliance._determinism import _difference, _Record
from rlenv_tools.inspector import InspectorServer, Timelines, Watcher
from rlenv_tools.timeline import Timeline

COME_AND_GO = "tests.come_and_go_envs:ComeAndGoEnvironment"
PACED = "tests.come_and_go_envs:PacedEnvironment"


# --- rlenv check ---------------------------------------------------------------------------------


@pytest.mark.parametrize("target", [hunt.TARGET, PACED])
def test_check_passes_agent_by_agent_where_agents_come_and_go(target: str) -> None:
    result = rlenv("check", target)
    assert result.returncode == 0, result.stdout + result.stderr
    checks = report_lines(result.stdout)
    assert checks["agents come and go"] == "PASS"
    assert checks["step returns gymnasium types"] == "PASS"
    assert checks["gymnasium check_env"] == "PASS"  # on RemoteEnv's fixed slots
    assert "FAIL" not in checks.values(), result.stdout


@pytest.mark.parametrize("target", [hunt.TARGET, COME_AND_GO])
def test_check_with_compliance_passes_at_an_address(serve: Serve, target: str) -> None:
    server = serve(target)
    result = rlenv("check", server.address, "--compliance")
    assert result.returncode == 0, result.stdout + result.stderr
    checks = report_lines(result.stdout)
    assert checks["compliance under hostile input"] == "PASS", result.stdout
    assert checks["agents come and go"] == "PASS"


def test_check_of_a_fixed_multi_agent_example_is_as_before() -> None:
    result = rlenv("check", tag.TARGET)
    assert result.returncode == 0, result.stdout + result.stderr
    checks = report_lines(result.stdout)
    assert checks["gymnasium check_env"] == "PASS"
    assert "agents come and go" not in checks  # only where they do
    assert checks["pettingzoo parallel_api_test"] in ("PASS", "SKIP")


def answer(observation: dict[str, bytes], agents: dict[str, Any]) -> _Record:
    response = Response(
        id=0,
        observation={"agent": observation},
        reward=sum(a["reward"] or 0.0 for a in agents.values()),
        terminated=False,
        truncated=False,
        frames=4,
        agents=agents,
    )
    return _Record.of(response, observation)


def test_determinism_compares_answers_agent_by_agent() -> None:
    start = answer({"A": b"0"}, {})
    a = {"reward": 1.0, "terminated": False, "truncated": False}
    b = {"reward": None, "terminated": False, "truncated": False}
    one = answer({"A": b"1", "B": b"2"}, {"A": a, "B": b})
    same_in_another_order = answer({"B": b"2", "A": b"1"}, {"B": b, "A": a})
    assert _difference([start, one], [start, same_in_another_order]) is None
    other_b = answer({"A": b"1", "B": b"3"}, {"A": a, "B": b})
    found = _difference([start, one], [start, other_b])
    assert found is not None and found.startswith("step 1, at agent 'B':")
    without_b = answer({"A": b"1"}, {"A": a})
    found = _difference([start, one], [start, without_b])
    assert found is not None and "at agent 'B' (in one answer only)" in found


# --- recordings and replay -----------------------------------------------------------------------


def hunt_policy(observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The hunter runs at the nearest prey (its heuristic); the prey stand still: catches."""
    return {
        name: hunt.Hunter.heuristic(None, value)  # type: ignore[arg-type]
        if name == hunt.HUNTER
        else np.zeros(2, np.float32)
        for name, value in observation.items()
    }


def walk(observation: dict[str, np.ndarray]) -> dict[str, int]:
    return {name: 2 for name in observation}


@pytest.fixture(scope="module")
def hunted(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    """A whole hunt (its own 1,200-tick limit ends it): prey appear and are caught."""
    directory = tmp_path_factory.mktemp("hunt")
    seen = record_one(hunt.TARGET, directory, hunt_policy, None, seed=4)
    return Recorded(directory / "episode-0001.rlenv", seen)


@pytest.fixture(scope="module")
def came_and_went(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    """ComeAndGo's whole episode: C joins, B is freed, A terminates, C is truncated."""
    directory = tmp_path_factory.mktemp("come_and_go")
    seen = record_one(COME_AND_GO, directory, walk, 100, seed=1)
    return Recorded(directory / "episode-0001.rlenv", seen)


@pytest.fixture(scope="module")
def tagged(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    """A fixed multi-agent tag episode of 40 steps, random actions."""
    directory = tmp_path_factory.mktemp("tag")
    rng = np.random.default_rng(0)
    env_spaces: dict[str, Any] = {}

    def policy(observation: dict[str, Any]) -> dict[str, Any]:
        return {
            name: rng.uniform(-1, 1, env_spaces[name].shape).astype(np.float32)
            for name in observation
        }

    probe = RemoteEnv(tag.TARGET, max_restarts=0, share_server=False)
    env_spaces.update(probe.action_space.spaces)
    probe.close()
    seen = record_one(tag.TARGET, directory, policy, 40, seed=2)
    return Recorded(directory / "episode-0001.rlenv", seen)


def arrivals_and_departures(seen: Seen) -> tuple[set[str], set[str]]:
    """The agents that joined after the reset, and those that left, as the client saw them."""
    joined = {
        name for agents in seen.agents[1:] for name, a in agents.items() if a["reward"] is None
    }
    left = {
        name
        for agents in seen.agents
        for name, a in agents.items()
        if a["terminated"] or a["truncated"]
    }
    return joined, left


def test_the_recordings_hold_agents_that_came_and_went(
    hunted: Recorded, came_and_went: Recorded
) -> None:
    joined, left = arrivals_and_departures(hunted.seen)
    assert joined and (left - {hunt.HUNTER}), "the hunt had no prey that appeared and was caught"
    assert arrivals_and_departures(came_and_went.seen) == ({"C"}, {"A", "B", "C"})


@pytest.mark.parametrize("recorded", ["hunted", "came_and_went", "tagged"])
def test_replay_is_bit_for_bit_rewards_and_flags_included(
    recorded: str, request: pytest.FixtureRequest
) -> None:
    path = request.getfixturevalue(recorded).path
    assert_replays_bit_for_bit(path)


def test_replay_finds_a_reward_that_differs(came_and_went: Recorded, tmp_path: Path) -> None:
    episode = EpisodeFile.load(came_and_went.path)
    assert episode.outcomes is not None and len(episode.outcomes) == len(came_and_went.seen.actions)
    outcomes = list(episode.outcomes)
    outcomes[2] = digest("another reward")
    tampered = tmp_path / "tampered.rlenv"
    replace(episode, outcomes=outcomes).save(tampered)
    result = rlenv("replay", str(tampered), "--trust-target")
    assert result.returncode != 0
    assert "step 3: the reward or flags differ from the recording" in result.stdout + result.stderr


# --- timelines -----------------------------------------------------------------------------------


def left(agents: dict[str, Any]) -> set[str]:
    """The agents of an answer's ``info["agents"]`` that left in it."""
    return {name for name, a in agents.items() if a["terminated"] or a["truncated"]}


def in_play_seen(seen: Seen) -> list[list[str]]:
    """Each step's agents in play as the client saw them: from joining to leaving, included."""
    in_play = list(seen.observations[0])
    steps = [list(in_play)]
    for before, agents in zip(seen.agents, seen.agents[1:], strict=False):
        in_play = [name for name in in_play if name not in left(before)]
        in_play += [name for name in agents if name not in in_play]
        steps.append(list(in_play))
    return steps


def returns_seen(seen: Seen, upto: int | None = None) -> dict[str, float]:
    """Each agent's return up to step ``upto``, from what the client saw."""
    returns: dict[str, float] = dict.fromkeys(seen.observations[0], 0.0)
    for agents in seen.agents[1 : None if upto is None else upto + 1]:
        for name, a in agents.items():
            returns[name] = returns.get(name, 0.0) + (a["reward"] or 0.0)
    return returns


@pytest.fixture(scope="module")
def hunt_timeline(hunted: Recorded) -> Iterator[Timeline]:
    with Timeline.open(hunted.path, trust_target=True, checkpoint_every=16) as timeline:
        yield timeline


def test_a_hunt_timeline_scrubs_bit_for_bit(hunt_timeline: Timeline, hunted: Recorded) -> None:
    seen = hunted.seen
    assert len(hunt_timeline) == len(seen.actions)
    for step in (150, 3, 0, 77, len(seen.actions), 76, 120):  # back and forth
        state = hunt_timeline.at(step)
        assert list(state.observation) == list(seen.observations[step])  # the answer's agents
        assert digest(state.observation) == digest(seen.observations[step])
        if step:
            assert state.info["agents"] == seen.agents[step]
    assert hunt_timeline.agents.in_play() == in_play_seen(seen)
    departures = hunt_timeline.agents.departures()
    assert set(departures) == set().union(*map(left, seen.agents))
    assert all(name in seen.agents[step] for name, step in departures.items())
    assert hunt_timeline.agents.returns() == pytest.approx(returns_seen(seen), abs=0)
    assert hunt_timeline.agents.returns(60) == pytest.approx(returns_seen(seen, 60), abs=0)


def test_a_hunt_timeline_branches_bit_for_bit(hunt_timeline: Timeline, hunted: Recorded) -> None:
    seen = hunted.seen
    again = hunt_timeline.branch(90, seen.actions[90:])  # the recorded actions again
    assert len(again) == len(hunt_timeline)
    assert hunt_timeline.diff(again).first_difference is None
    assert again.agents.in_play() == hunt_timeline.agents.in_play()
    assert again.agents.returns() == hunt_timeline.agents.returns()
    for step in (91, 140, len(again)):
        assert digest(again.at(step).observation) == digest(seen.observations[step])
    still = hunt_timeline.branch(
        90, policy=lambda o: {name: np.zeros(2, np.float32) for name in o}, max_steps=60
    )
    assert hunt_timeline.diff(still).first_difference == 91
    assert still.agents.in_play()[:91] == hunt_timeline.agents.in_play()[:91]
    saved = Path(hunted.path).with_name("still.rlenv")
    still.save(saved)
    replayed = rlenv("replay", str(saved), "--trust-target")
    assert replayed.returncode == 0 and "every observation identical" in replayed.stdout


def test_a_fixed_multi_agent_timeline_has_every_agent_at_every_step(tagged: Recorded) -> None:
    with Timeline.open(tagged.path, trust_target=True) as timeline:
        agents = list(tagged.seen.observations[0])
        assert timeline.agents.in_play() == [agents] * (len(timeline) + 1)
        assert timeline.agents.departures() == {}
        assert timeline.agents.returns() == pytest.approx(returns_seen(tagged.seen), abs=0)
        assert digest(timeline.at(17).observation) == digest(tagged.seen.observations[17])


def test_the_ticks_of_a_step_where_an_agent_joins_inside_it_are_bit_for_bit(
    came_and_went: Recorded,
) -> None:
    # Every walker walks at +1 a tick from its first decision, and observes [position, tick]:
    # A from tick 1; C joins at tick 6, inside step 2 (ticks 5 to 8), still at 0 until it
    # decides at tick 8; B is freed at tick 10, inside step 3.
    with Timeline.open(came_and_went.path, trust_target=True) as timeline:
        ticks = timeline.ticks(2)
        assert [tick.tick for tick in ticks] == [1, 2, 3, 4] and timeline.frames(2) == 4
        for tick in ticks:
            now = 4 + tick.tick
            assert tick.observation["A"].tolist() == [now, now]
            assert ("C" in tick.observation) == (now >= 6)
            if now >= 6:
                assert tick.observation["C"].tolist() == [0.0, now]
        assert digest(ticks[-1].observation) == digest(timeline.at(2).observation)
        assert ticks[-1].info["agents"] == came_and_went.seen.agents[2]
        page = timeline.ticks(3, first=2, count=2)  # B leaves at tick 10: the step's second
        assert [tick.tick for tick in page] == [2, 3]
        assert "B" not in page[1].observation and page[1].observation["A"].tolist() == [11, 11]
        assert digest(timeline.at(3).observation) == digest(came_and_went.seen.observations[3])


def test_the_ticks_of_a_hunt_step_end_at_its_answer(hunt_timeline: Timeline) -> None:
    joined = next(
        step
        for step in range(1, len(hunt_timeline) + 1)
        if any(a["reward"] is None for a in hunt_timeline.at(step).info["agents"].values())
    )
    ticks = hunt_timeline.ticks(joined)
    assert len(ticks) == hunt_timeline.frames(joined) > 1
    state = hunt_timeline.at(joined)
    assert digest(ticks[-1].observation) == digest(state.observation)
    assert ticks[-1].properties == state.properties
    assert ticks[0].properties != ticks[-1].properties  # the scene moved inside the step
    assert ticks[-2].properties != ticks[-1].properties


# --- the inspector -------------------------------------------------------------------------------


def test_the_inspector_shows_agents_arriving_and_leaving_and_returns_per_agent(
    came_and_went: Recorded,
) -> None:
    seen = came_and_went.seen
    page = InspectorServer(
        Watcher([]), timelines=Timelines([came_and_went.path], trust_target=True)
    )
    page.start()
    try:
        status, _, described = fetch(page.url, "api/timeline?timeline=0")
        assert status == 200, described
        assert described["agents_in_play"] == in_play_seen(seen)
        assert described["departures"] == {
            name: step for step, agents in enumerate(seen.agents) for name in left(agents)
        }
        assert described["agent_returns"] == returns_seen(seen)
        joined = next(k for k, agents in enumerate(seen.agents) if "C" in agents)
        status, _, state = fetch(page.url, f"api/timeline/step?timeline=0&branch=0&step={joined}")
        assert status == 200, state
        assert state["arrived"] == ["C"] and state["left"] == list(left(seen.agents[joined]))
        assert set(state["observation"]) == set(seen.observations[joined])  # the answer's
        assert state["agents_in_play"] == in_play_seen(seen)[joined]
        assert state["agent_returns"] == returns_seen(seen, joined)
        freed = described["departures"]["B"]
        status, _, state = fetch(page.url, f"api/timeline/step?timeline=0&branch=0&step={freed}")
        assert "B" in state["left"] and "B" in state["agents_in_play"]
        status, _, after = fetch(
            page.url, f"api/timeline/step?timeline=0&branch=0&step={freed + 1}"
        )
        assert "B" not in after["agents_in_play"] and "B" not in after["observation"]
        status, _, compared = fetch(page.url, "api/timeline/compare?timeline=0&a=0&b=0&step=1")
        assert status == 200 and compared["a"]["agent_returns"] == returns_seen(seen)
        status, _, ticked = fetch(page.url, "api/timeline/ticks?timeline=0&branch=0&step=2")
        assert status == 200 and [tick["tick"] for tick in ticked["ticks"]] == [1, 2, 3, 4]
    finally:
        page.close()


# --- datasets ------------------------------------------------------------------------------------


@dataclass
class Life:
    """One agent's life as the recording's client saw it."""

    observations: list[Any]
    actions: list[Any]
    rewards: list[float]
    terminated: bool
    truncated: bool


def lives_seen(seen: Seen) -> dict[str, Life]:
    """Each agent's life: the answers it appears in, the actions sent after each but its last,
    the rewards of each but its first, its flags at its last (truncated: still in play)."""
    lives = {}
    names = dict.fromkeys(name for observation in seen.observations for name in observation)
    for name in names:
        answers = [k for k, observation in enumerate(seen.observations) if name in observation]
        last = seen.agents[answers[-1]].get(name, {})
        ended = bool(last.get("terminated") or last.get("truncated"))
        lives[name] = Life(
            [seen.observations[k][name] for k in answers],
            [seen.actions[k][name] for k in answers[:-1]],
            [seen.agents[k][name]["reward"] for k in answers[1:]],
            bool(last.get("terminated")),
            bool(last.get("truncated")) or not ended,
        )
    return {name: life for name, life in lives.items() if life.actions}


def assert_lives(dataset: Any, lives: list[Life]) -> None:
    """The dataset's episodes are these lives, bit for bit, in order."""
    episodes = list(dataset.iterate_episodes())
    assert len(episodes) == len(lives)
    for episode, life in zip(episodes, lives, strict=True):
        observations = np.stack(life.observations)
        assert episode.observations.dtype == observations.dtype
        assert episode.observations.tobytes() == observations.tobytes()
        assert np.array_equal(episode.actions, np.asarray(life.actions))
        assert list(episode.rewards) == life.rewards
        ending = np.zeros(len(life.actions), bool)
        ending[-1] = True
        assert list(episode.terminations) == list(ending & life.terminated)
        assert list(episode.truncations) == list(ending & life.truncated)


@pytest.mark.minari
@pytest.mark.parametrize(
    ("recorded", "dataset_id", "classes"),
    [
        ("came_and_went", "walkers/come-and-go-v0", {"Walker": ["A", "B", "C"]}),
        ("hunted", "hunt/recorded-v0", None),
        ("driven_steady", "walkers/driven-v0", {"Walker": ["Leader"]}),  # Steady: driven
    ],
)
def test_agents_that_come_and_go_become_a_dataset_per_class_each_life_an_episode(
    recorded: str,
    dataset_id: str,
    classes: dict[str, list[str]] | None,
    request: pytest.FixtureRequest,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    minari = pytest.importorskip("minari")
    from rlenv_tools.datasets import class_dataset_id

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    chosen = request.getfixturevalue(recorded)
    lives = lives_seen(chosen.seen)
    if classes is None:  # the hunt: a hunter and the prey that appeared
        classes = {
            "Hunter": [hunt.HUNTER],
            "Prey": [name for name in lives if name != hunt.HUNTER],
        }
        assert len(classes["Prey"]) > 2  # prey joined during the episode
    result = rlenv(
        "dataset", "create", dataset_id, "--from", str(chosen.path.parent), "--trust-target"
    )
    assert result.returncode == 0, result.stdout + result.stderr
    for cls, names in classes.items():
        steps = sum(len(lives[name].actions) for name in names)
        one = class_dataset_id(dataset_id, cls)
        assert f"wrote dataset {one}: {len(names)} episodes, {steps} steps" in result.stdout
        dataset = minari.load_dataset(one)
        assert_lives(dataset, [lives[name] for name in names])
    assert result.stdout.count("wrote dataset") == len(classes)


@pytest.mark.minari
def test_create_dataset_of_agents_that_come_and_go_says_to_make_one_per_class(
    came_and_went: Recorded, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("minari")
    from rlenv_tools.datasets import create_dataset

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    with pytest.raises(ValueError, match="make one dataset per agent class with create_datasets"):
        create_dataset("walkers/one-v0", came_and_went.path.parent, trust_target=True)
    assert not any((tmp_path / "datasets").rglob("*.hdf5"))


# --- the page, in a browser ----------------------------------------------------------------------


@pytest.mark.browser
def test_the_page_shows_who_is_in_play_and_their_returns(came_and_went: Recorded) -> None:
    from browser import Browser, find_chromium

    chromium = find_chromium()
    if chromium is None:
        pytest.skip("no Chromium found (apt-get install chromium): the JSON is tested above")
    seen = came_and_went.seen
    joined = next(k for k, agents in enumerate(seen.agents) if "C" in agents)
    page = InspectorServer(
        Watcher([]), timelines=Timelines([came_and_went.path], trust_target=True)
    )
    page.start()
    try:
        with Browser(chromium) as browser:
            browser.open(page.url)
            agents = "document.getElementById('timeline-agents')"
            browser.wait_for(f"{agents}.dataset.inPlay === 'A,B'", "step 0's agents not shown")
            browser.evaluate(f"""(() => {{ const s = document.getElementById('scrubber');
                s.value = {joined}; s.dispatchEvent(new Event('input')); }})()""")
            shown = in_play_seen(seen)[joined]
            browser.wait_for(
                f"{agents}.dataset.inPlay === '{','.join(shown)}'", "the joined agent not shown"
            )
            text = browser.evaluate(f"{agents}.textContent")
            assert "+C" in text and not browser.evaluate(f"{agents}.hidden")
            assert "returns: A " in text
    finally:
        page.close()


# --- driven agents deciding during steps -------------------------------------------------------

DRIVEN = "tests.come_and_go_envs:DrivenEnvironment"
STEADY = ["--policy=Follower=heuristic", "--policy=Late=heuristic"]
PREY_DRIVEN = [f"--policy=Prey{number}=heuristic" for number in range(1, 9)]


def hunter_alone(observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The hunter runs at the nearest prey (the prey are the server's)."""
    return {hunt.HUNTER: hunt.Hunter.heuristic(None, observation[hunt.HUNTER])}  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def driven_steady(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    """DrivenEnvironment with its Steady agents driven: they decide inside the leader's steps,
    one of them joining and one leaving inside a step."""
    directory = tmp_path_factory.mktemp("driven")
    seen = record_one(DRIVEN, directory, lambda o: {"Leader": 2}, None, 3, server_args=STEADY)
    return Recorded(directory / "episode-0001.rlenv", seen)


@pytest.fixture(scope="module")
def driven_prey(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    """A whole hunt whose prey (every 8 ticks) the server drives beside the hunter (every 4)."""
    directory = tmp_path_factory.mktemp("driven_prey")
    seen = record_one(hunt.TARGET, directory, hunter_alone, None, 3, server_args=PREY_DRIVEN)
    return Recorded(directory / "episode-0001.rlenv", seen)


def parts(path: Path) -> list[list[Any]]:
    """The recording's parts of steps that went on while driven agents decided."""
    return [event for event in EpisodeFile.load(path).snapshot["events"] if len(event) == 4]


def test_recordings_of_driven_agents_hold_steps_that_went_on(
    driven_steady: Recorded, driven_prey: Recorded
) -> None:
    assert {"Follower", "Late"} == {
        name for event in parts(driven_steady.path) for name in event[1]
    }
    assert parts(driven_prey.path)  # prey decided between the hunter's decisions
    assert EpisodeFile.load(driven_prey.path).driven == [f"Prey{n}" for n in range(1, 9)]
    seen = driven_steady.seen
    assert all(set(observation) <= {"Leader"} for observation in seen.observations)
    joined, gone = arrivals_and_departures(seen)
    assert joined == {"Late"} and "Late" in gone  # joined and freed inside steps


@pytest.mark.parametrize("recorded", ["driven_steady", "driven_prey"])
def test_a_recording_whose_driven_agents_decided_during_steps_replays_bit_for_bit(
    recorded: str, request: pytest.FixtureRequest
) -> None:
    path = request.getfixturevalue(recorded).path
    assert_replays_bit_for_bit(path)


def test_a_replay_of_driven_agents_finds_an_action_that_differs(
    driven_prey: Recorded, tmp_path: Path
) -> None:
    episode = EpisodeFile.load(driven_prey.path)
    events = [list(event) for event in episode.snapshot["events"]]
    for event in events:
        if len(event) == 4:  # the prey that decided during steps stand still instead
            event[1] = {name: np.zeros(2, np.float32) for name in event[1]}
    replace(episode, snapshot={**episode.snapshot, "events": events}).save(
        tmp_path / "tampered.rlenv"
    )
    result = rlenv("replay", str(tmp_path / "tampered.rlenv"), "--trust-target")
    assert result.returncode == 1
    assert "first divergence at step" in result.stdout


ACT_FOR_EVERY_AGENT = {
    "driven_steady": {"Leader": 2, "Follower": 2, "Late": 2},
    "driven_prey": {name: np.zeros(2, np.float32) for name in hunt.HuntEnvironment.possible_agents},
}


@pytest.mark.parametrize("recorded", ["driven_steady", "driven_prey"])
def test_a_timeline_of_driven_agents_deciding_during_steps_is_bit_for_bit(
    recorded: str, request: pytest.FixtureRequest
) -> None:
    seen = request.getfixturevalue(recorded).seen
    path = request.getfixturevalue(recorded).path
    with Timeline.open(path, trust_target=True, checkpoint_every=4) as timeline:
        assert len(timeline) == len(seen.actions)
        for step in (len(seen.actions), 1, 5, 2, len(seen.actions) - 1, 3):
            state = timeline.at(step)
            assert digest(state.observation) == digest(seen.observations[step])
            if step:
                assert state.info["agents"] == seen.agents[step]
        assert timeline.agents.in_play() == in_play_seen(seen)
        assert timeline.agents.returns() == pytest.approx(returns_seen(seen), abs=0)
        assert timeline.frames(1) == 4  # its parts' ticks together
        middle = len(timeline) // 2
        # No one drives in a timeline's server: a branch's actions act for the driven too.
        again = timeline.branch(middle, [ACT_FOR_EVERY_AGENT[recorded]] * 6)
        assert digest(again.at(middle).observation) == digest(seen.observations[middle])
        assert len(again) > middle
        saved = path.with_name(f"branch-{recorded}.rlenv")
        again.save(saved)
    replayed = rlenv("replay", str(saved), "--trust-target")
    assert replayed.returncode == 0, replayed.stdout + replayed.stderr
