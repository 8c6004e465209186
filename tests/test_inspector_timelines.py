"""The inspector's time travel over HTTP: timelines' routes, their refusals, rlenv replay --inspect.

The page itself is driven in ``test_inspector_browser.py`` (marker ``browser``).
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from urllib.parse import urlsplit

import numpy as np
import pytest
from conftest import alive, wait_until
from inspector_http import Trainer, fetch

from examples.cartpole import TARGET, controller
from rlenv_client.launcher import ServerProcess
from rlenv_client.replay import EpisodeFile, digest
from rlenv_tools.demonstrations import record
from rlenv_tools.inspector import (
    Inspector,
    InspectorServer,
    Timelines,
    Watcher,
    inspect_recordings,
)
from rlenv_tools.inspector._timelines import episode_id
from rlenv_tools.timeline import Timeline

BIAS = 0.03  # a controller pushing a little too far right: the pole falls at step 20


def biased(observation: np.ndarray) -> np.ndarray:
    """The balancing controller with a bias: an agent that fails."""
    return np.clip(controller(observation) + BIAS, -1.0, 1.0).astype(np.float32)


def push_left(observation: np.ndarray) -> np.ndarray:
    """A scripted policy given from Python."""
    return np.full(1, -1.0, np.float32)


def fails_at_the_third_step(observation: np.ndarray, calls: list[int] = []) -> np.ndarray:  # noqa: B006
    """A policy that raises after two steps."""
    calls.append(1)
    if len(calls) % 3 == 0:
        raise ZeroDivisionError("division by zero")
    return np.full(1, 1.0, np.float32)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One CartPole episode of the failing agent (20 steps)."""
    return record(TARGET, biased, 1, tmp_path_factory.mktemp("episodes"), seed=0)[0]


@pytest.fixture
def page(recording: Path) -> Iterator[str]:
    """An inspector in this process with the recording as timeline 0 (no server watched)."""
    inspector = InspectorServer(
        Watcher([]),
        timelines=Timelines(
            [recording],
            policies={"push-left": push_left, "broken": fails_at_the_third_step},
            unavailable={"absent": "no onnxruntime"},
        ),
    )
    inspector.start()
    try:
        yield inspector.url
    finally:
        inspector.close()


def test_inspect_recordings_serves_them_with_python_policies(recording: Path) -> None:
    page = inspect_recordings([recording], policies={"push-left": push_left})
    try:
        assert fetch(page.url, "api/timelines")[2]["policies"] == ["push-left"]
        status, made = post(
            page.url,
            "api/timeline/policy",
            {"timeline": 0, "branch": 0, "step": 2, "policy": "push-left", "max_steps": 3},
        )
        assert status == 200 and made["branches"][1]["length"] <= 5  # type: ignore[index]
        timeline = page.timelines._recordings.roots()[0].timeline
        assert timeline is not None and timeline.processes
        pids = timeline.processes
    finally:
        page.close()
    for pid in pids:  # closing the page ended the timeline's processes
        wait_until(lambda pid=pid: not alive(pid), f"process {pid} outlived the page")


def page_recording(url: str) -> str:
    """The file of the page's timeline 0."""
    return str(fetch(url, "api/timelines")[2]["timelines"][0]["origin"]["file"])


def post(url: str, path: str, body: object) -> tuple[int, object]:
    status, _, answer = fetch(url, path, method="POST", body=body)
    return status, answer


def test_a_recording_is_scrubbed_ticked_branched_and_compared(page: str, recording: Path) -> None:
    status, headers, html = fetch(page)
    assert status == 200 and b'<script src="static/timeline.js" defer>' in html
    status, headers, script = fetch(page, "static/timeline.js")
    assert status == 200 and headers["content-type"].startswith("text/javascript")
    assert "script-src 'self'" in headers["content-security-policy"]
    assert b"api/${path}" in script or b"timeline/step" in script
    listed = fetch(page, "api/timelines")[2]
    assert (
        listed["timelines"][0]["name"] == recording.name
        and listed["policies"] == ["broken", "push-left"]
        and listed["unavailable"] == {"absent": "no onnxruntime"}
    )
    status, _, info = fetch(page, "api/timeline?timeline=0")
    assert status == 200 and info["length"] == 20 and info["agents"] == ["Agent"]
    assert info["keys"] == ["ArrowLeft", "ArrowRight"]  # CartPole's demonstration_keys
    assert [b["how"] for b in info["branches"]] == ["episode"]
    episode = EpisodeFile.load(recording)
    # every step: what the recording saw, with the scene and the properties at that moment
    with Timeline.open(recording) as reference:
        for step in (0, 19, 5, 20, 1):
            state = fetch(page, f"api/timeline/step?timeline=0&branch=0&step={step}")[2]
            expected = reference.at(step)
            assert state["step"] == step and state["length"] == 20
            assert state["reward"] == expected.reward
            assert state["observation"]["Agent"]["numbers"] == [
                round(float(x), 5) for x in expected.observation
            ]
            assert state["draw"]["shapes"] and len(state["draw"]["shapes"]) == 3
            cart = state["properties"]["/root/CartPole/World/Physics/Cart"]
            assert cart["position"] == pytest.approx(
                list(expected.properties["/root/CartPole/World/Physics/Cart"]["position"])
            )
            assert digest(expected.observation) == episode.observations[step]
        assert state["terminated"] is False
        assert fetch(page, "api/timeline/step?timeline=0&step=20")[2]["terminated"] is True
        ticks = fetch(page, "api/timeline/ticks?timeline=0&branch=0&step=7")[2]["ticks"]
        assert [t["tick"] for t in ticks] == [1, 2, 3, 4]
        assert sum(t["reward"] for t in ticks) == reference.at(7).reward
        assert (
            ticks[-1]["properties"]
            == fetch(page, "api/timeline/step?timeline=0&step=7")[2]["properties"]
        )
    # a key branch at step 10, lengthened key by key: one branch in the tree
    status, made = post(
        page, "api/timeline/branch", {"timeline": 0, "branch": 0, "step": 10, "key": "ArrowLeft"}
    )
    assert status == 200 and made["branch"] == 1
    for _ in range(2):
        status, made = post(
            page, "api/timeline/extend", {"timeline": 0, "branch": 1, "key": "ArrowLeft"}
        )
        assert status == 200 and made["branch"] == 1
    keys = made["branches"][1]
    assert (keys["parent"], keys["at"], keys["how"], keys["length"]) == (0, 10, "keys", 13)
    assert keys["label"] == "keys ArrowLeft ArrowLeft ArrowLeft" and not keys["ended"]
    pushed = fetch(page, "api/timeline/step?timeline=0&branch=1&step=13")[2]
    assert (
        pushed["observation"]
        != fetch(page, "api/timeline/step?timeline=0&step=13")[2]["observation"]
    )
    # pushing left that hard: the pole falls at step 14, and the branch grows no more
    status, made = post(
        page, "api/timeline/extend", {"timeline": 0, "branch": 1, "key": "ArrowLeft"}
    )
    assert status == 200 and made["branches"][1]["ended"]
    assert made["branches"][1]["length"] == 14
    status, refused = post(
        page, "api/timeline/extend", {"timeline": 0, "branch": 1, "key": "ArrowRight"}
    )
    assert status == 409 and "episode ended at step 14" in refused["error"]
    # a branch of that branch, by the policy given from Python
    status, made = post(
        page,
        "api/timeline/policy",
        {"timeline": 0, "branch": 1, "step": 12, "policy": "push-left", "max_steps": 5},
    )
    assert status == 200 and made["branch"] == 2
    assert {k: made["branches"][2][k] for k in ("parent", "at", "how", "label")} == {
        "parent": 1,
        "at": 12,
        "how": "policy",
        "label": "policy push-left",
    }
    assert 12 < made["branches"][2]["length"] <= 17
    # side by side: the episode and the key branch
    status, _, compared = fetch(page, "api/timeline/compare?timeline=0&a=0&b=1&step=12")
    assert status == 200 and compared["first_difference"] == 11
    assert len(compared["a"]["rewards"]) == 21 and len(compared["b"]["rewards"]) == 15
    assert compared["a"]["rewards"][:11] == compared["b"]["rewards"][:11]
    a = np.array(compared["a"]["observation"]["Agent"]["numbers"])
    b = np.array(compared["b"]["observation"]["Agent"]["numbers"])
    difference = np.array(compared["difference"]["Agent"]["numbers"])
    assert np.allclose(b - a, difference, atol=1e-4) and np.abs(difference).max() > 0
    beyond = fetch(page, "api/timeline/compare?timeline=0&a=0&b=1&step=18")[2]
    assert beyond["b"]["observation"] is None and beyond["difference"] is None
    same = fetch(page, "api/timeline/compare?timeline=0&a=0&b=0&step=3")[2]
    assert same["first_difference"] is None


def test_the_timeline_routes_refuse_what_they_cannot_do(page: str) -> None:
    bad_gets = [
        ("api/timeline/step?timeline=0&branch=0&step=21", 400, "no step 21"),
        ("api/timeline/step?timeline=0&step=-1", 400, "step must be in"),
        ("api/timeline/step?timeline=0&step=ten", 400, "step must be an integer"),
        ("api/timeline/ticks?timeline=0&step=0", 400, "step 0 has no action"),
        ("api/timeline/step?timeline=7&step=0", 404, "no timeline 7"),
        ("api/timeline?timeline=7", 404, "no timeline 7"),
        ("api/timeline/step?timeline=0&branch=3&step=0", 404, "no branch 3"),
        ("api/timeline/compare?timeline=0&a=0&b=5&step=0", 404, "no branch 5"),
        ("api/timeline/compare?timeline=0&a=0&b=0&step=99", 400, "no step 99"),
    ]
    if hasattr(Watcher, "recent_episodes"):  # the live servers keep their recent episodes
        bad_gets.append(("api/timeline/recent?server=0&instance=0", 404, "no server 0"))
    else:
        bad_gets.append(("api/timeline/recent?server=0&instance=0", 501, "cannot list"))
    for path, status, words in bad_gets:
        answer = fetch(page, path)
        assert answer[0] == status and words in answer[2]["error"], (path, answer)
    bad_posts = [
        ({"timeline": 0, "branch": 0, "step": 30, "key": "ArrowLeft"}, 400, "no step 30"),
        ({"timeline": 0, "branch": 0, "step": 2, "key": "q"}, 422, "none of the agent's keys"),
        ({"timeline": 0, "branch": 0, "step": -2, "key": "ArrowLeft"}, 400, "step must be"),
        ({"timeline": 0, "branch": 0, "step": 2.5, "key": "ArrowLeft"}, 400, "step must be"),
        ({"timeline": 0, "branch": 0, "step": 2, "key": 37}, 400, "key must be a string"),
        ({"timeline": 4, "branch": 0, "step": 2, "key": "ArrowLeft"}, 404, "no timeline 4"),
        ({"timeline": 0, "branch": 0, "step": 2}, 400, "exactly"),
    ]
    for body, status, words in bad_posts:
        answer = post(page, "api/timeline/branch", body)
        assert answer[0] == status and words in answer[1]["error"], (body, answer)  # type: ignore
    status, answer = post(
        page, "api/timeline/extend", {"timeline": 0, "branch": 0, "key": "ArrowLeft"}
    )
    assert status == 409 and "only a key branch grows" in answer["error"]  # type: ignore
    policy = {"timeline": 0, "branch": 0, "step": 2, "policy": "elsewhere", "max_steps": 5}
    status, answer = post(page, "api/timeline/policy", policy)
    assert status == 404 and "the policies are broken, push-left" in answer["error"]  # type: ignore
    status, answer = post(
        page, "api/timeline/policy", {**policy, "policy": "push-left", "max_steps": 0}
    )
    assert status == 400 and "max_steps" in answer["error"]  # type: ignore
    status, answer = post(page, "api/timeline/policy", {**policy, "policy": "broken"})
    assert status == 422 and "policy broken failed: ZeroDivisionError" in answer["error"]  # type: ignore
    with Timeline.open(page_recording(page)) as reference:  # the timeline is still right after
        expected = [round(float(x), 5) for x in reference.at(4).observation]
    assert (
        fetch(page, "api/timeline/step?timeline=0&step=4")[2]["observation"]["Agent"]["numbers"]
        == expected
    )
    status, answer = post(page, "api/timeline/policy", {**policy, "policy": "absent"})
    assert status == 422 and "absent is unavailable: no onnxruntime" in answer["error"]  # type: ignore
    # the page's rules: a change is a JSON POST, from this origin, with the key
    branch = {"timeline": 0, "branch": 0, "step": 2, "key": "ArrowLeft"}
    assert fetch(page, "api/timeline/branch")[0] == 404  # GET: nothing there
    assert fetch(page, "api/timeline/step?timeline=0", method="POST", body={})[0] == 404
    assert fetch(page, "api/timeline/branch", method="PUT", body=branch)[0] == 405
    status, _, answer = fetch(
        page,
        "api/timeline/branch",
        method="POST",
        body=branch,
        headers={"Origin": "http://attacker.example"},
    )
    assert status == 403 and "origin" in answer["error"]
    status, _, answer = fetch(
        page, "api/timeline/step?timeline=0", headers={"Host": "attacker.example"}
    )
    assert status == 403 and "Host" in answer["error"]
    port = urlsplit(page).port
    assert fetch(f"http://127.0.0.1:{port}/", "api/timelines")[0] == 403  # no key
    status, _, _ = fetch(
        page,
        "api/timeline/branch",
        method="POST",
        raw=b"step=2",
        headers={"Content-Type": "application/x-www-form-urlencoded"},
    )
    assert status == 415
    # nothing was made by the refusals
    assert len(fetch(page, "api/timeline?timeline=0")[2]["branches"]) == 1


def test_recent_episodes_need_a_watcher_that_keeps_them(page: str, recording: Path) -> None:
    """Live mode: the page lists an instance's recent episodes and opens one as a timeline."""

    class Keeping(Watcher):
        def recent_episodes(self, server: int, instance: int) -> list[EpisodeFile]:
            kept = EpisodeFile.load(recording)  # as a server keeps it: no observations
            return [
                EpisodeFile(kept.target, kept.snapshot, [], kept.terminated, kept.truncated)
            ] * 2

    inspector = InspectorServer(Keeping([]), timelines=Timelines(max_recent=1))
    inspector.start()
    try:
        url = inspector.url
        listed = fetch(url, "api/timeline/recent?server=0&instance=0")[2]
        assert [e["steps"] for e in listed] == [20, 20]
        assert listed[0]["id"] == listed[1]["id"] == episode_id(EpisodeFile.load(recording))
        status, info = post(
            url, "api/timeline/open", {"server": 0, "instance": 0, "id": listed[1]["id"]}
        )
        assert status == 200 and info["length"] == 20  # type: ignore[index]
        assert info["origin"] == {
            "server": 0,
            "instance": 0,  # type: ignore[index]
            "recent": listed[1]["id"],
        }
        state = fetch(url, f"api/timeline/step?timeline={info['timeline']}&step=3")[2]  # type: ignore
        with Timeline.open(recording) as reference:
            expected = reference.at(3).observation
        assert state["step"] == 3 and state["observation"]["Agent"]["numbers"] == [
            round(float(x), 5) for x in expected
        ]
        status, again = post(
            url, "api/timeline/open", {"server": 0, "instance": 0, "id": listed[0]["id"]}
        )
        assert [t["timeline"] for t in fetch(url, "api/timelines")[2]["timelines"]] == [
            again["timeline"]
        ]  # type: ignore[index]  # max_recent=1: the older one closed
        status, answer = post(
            url, "api/timeline/open", {"server": 0, "instance": 0, "id": "0" * 32}
        )
        assert status == 404 and "keeps no episode" in answer["error"]  # type: ignore
        status, answer = post(url, "api/timeline/open", {"server": 0, "instance": 0, "episode": 0})
        assert status == 400 and "exactly" in answer["error"]  # type: ignore
    finally:
        inspector.close()


def test_rlenv_replay_inspect_serves_the_recordings_until_stdin_closes(
    recording: Path, tmp_path: Path
) -> None:
    second = tmp_path / "episode-0002.rlenv"
    second.write_bytes(recording.read_bytes())
    with Inspector([], recordings=[recording, second]) as inspector:
        assert inspector.url.startswith("http://127.0.0.1:")
        names = [t["name"] for t in fetch(inspector.url, "api/timelines")[2]["timelines"]]
        assert names == [recording.name, second.name]
        assert fetch(inspector.url, "api/servers")[2] == []
        state = fetch(inspector.url, "api/timeline/step?timeline=1&step=20")[2]
        assert state["terminated"] is True
        process = inspector._process
    assert process.returncode is not None  # closing its standard input ended it
    run = [sys.executable, "-m", "rlenv", "replay"]
    untargeted = tmp_path / "untargeted.rlenv"
    episode = EpisodeFile.load(recording)
    EpisodeFile(None, episode.snapshot, episode.observations).save(untargeted)
    for arguments, words in (
        ([str(recording), str(second)], "one file at a time"),
        ([str(recording), "--policy", "x.onnx"], "go with --inspect"),
        ([str(tmp_path / "nothing.rlenv"), "--inspect"], "nothing.rlenv"),
        ([str(untargeted), "--inspect"], "pass --target"),
        ([str(recording), "--inspect", "--policy", str(tmp_path / "absent.onnx")], "absent.onnx"),
    ):
        done = subprocess.run(
            run + arguments, capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL
        )
        assert done.returncode == 2 and words in done.stderr, (arguments, done.stderr)
    done = subprocess.run(run + [str(recording)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and "every observation identical" in done.stdout  # as before


@pytest.mark.onnx
def test_an_onnx_policy_from_the_command_line_branches(recording: Path, tmp_path: Path) -> None:
    torch = pytest.importorskip("torch")
    pytest.importorskip("onnxruntime")
    from gymnasium import spaces

    from rlenv_tools.policies import export_onnx

    torch.manual_seed(0)
    model = torch.nn.Sequential(torch.nn.Linear(5, 8), torch.nn.Tanh(), torch.nn.Linear(8, 1))
    high = np.array(
        [4.8, 5.8, np.pi, np.finfo(np.float32).max, np.finfo(np.float32).max], np.float32
    )
    path = export_onnx(
        model,
        tmp_path / "steady.onnx",
        spaces.Box(-high, high),
        spaces.Box(-1.0, 1.0, (1,), np.float32),
    )
    with Inspector([], recordings=[recording], policies=[path]) as inspector:
        assert fetch(inspector.url, "api/timelines")[2]["policies"] == ["steady"]
        status, made = post(
            inspector.url,
            "api/timeline/policy",
            {"timeline": 0, "branch": 0, "step": 5, "policy": "steady", "max_steps": 8},
        )
        assert status == 200 and made["branches"][1]["label"] == "policy steady"  # type: ignore
        assert 5 < made["branches"][1]["length"] <= 13  # type: ignore[index]


def test_a_live_instances_recent_episodes_open_as_timelines(server: ServerProcess) -> None:
    """Live mode against a real server keeping its last episodes (rlenv serve --keep-episodes)."""
    inspector = InspectorServer(Watcher([f"{server.host}:{server.port}"]))
    inspector.start()
    try:
        url = inspector.url
        with Trainer(server.host, server.port) as trainer:
            wait_until(lambda: trainer.episodes > 3, "the trainer did not finish episodes")
            listed = fetch(url, "api/timeline/recent?server=0&instance=0")[2]
            assert 3 <= len(listed) <= 8 and all(e["steps"] > 0 for e in listed)
            assert all(e["target"] == TARGET for e in listed)
            newest = listed[-1]
            before = trainer.episodes  # the server drops it once 8 more have finished ...
            wait_until(lambda: trainer.episodes > before + 9, "the trainer stopped")
            ids = [e["id"] for e in fetch(url, "api/timeline/recent?server=0&instance=0")[2]]
            assert newest["id"] not in ids  # ... and the page still opens what it listed
            status, info = post(
                url, "api/timeline/open", {"server": 0, "instance": 0, "id": newest["id"]}
            )
            assert status == 200, info
            number, length = info["timeline"], info["length"]  # type: ignore[index]
            assert length == newest["steps"]
            state = fetch(url, f"api/timeline/step?timeline={number}&step={length}")[2]
            assert state["step"] == length and state["draw"]["shapes"]
            assert state["terminated"] or state["truncated"]  # it ended there: it was kept
            status, made = post(
                url,
                "api/timeline/branch",
                {"timeline": number, "branch": 0, "step": 1, "key": "ArrowRight"},
            )
            assert status == 200 and made["branches"][1]["length"] == 2  # type: ignore[index]
            assert trainer.error is None
        assert fetch(url, "api/timeline/recent?server=0&instance=1")[0] == 404
    finally:
        inspector.close()


def test_concurrent_requests_on_one_timeline_are_taken_one_at_a_time(page: str) -> None:
    """The page's requests arrive on several threads; a root's lock keeps its timeline whole."""
    paths = [f"api/timeline/step?timeline=0&step={k}" for k in (20, 3, 17, 0, 9, 12, 5, 20)]
    alone = [fetch(page, path)[2]["observation"] for path in paths]
    status, _ = post(
        page, "api/timeline/branch", {"timeline": 0, "branch": 0, "step": 4, "key": "ArrowRight"}
    )
    assert status == 200
    paths += [
        "api/timeline/step?timeline=0&branch=1&step=5",
        "api/timeline/ticks?timeline=0&step=6",
        "api/timeline/compare?timeline=0&a=0&b=1&step=5",
    ]
    with ThreadPoolExecutor(len(paths)) as pool:
        together = list(pool.map(lambda path: fetch(page, path), paths * 2))
    assert all(status == 200 for status, _, _ in together)
    assert [answer["observation"] for _, _, answer in together[:8]] == alone
    assert [answer["observation"] for _, _, answer in together[11:19]] == alone
    assert together[10][2]["first_difference"] == 5


def test_the_ticks_route_pages_and_the_list_tells_files_apart(
    recording: Path, tmp_path: Path
) -> None:
    """Files of one name differ by their folder; one that does not open says why; a page of
    ticks holds at most MAX_TICKS (the ticks route's ``first`` and ``count``)."""
    twin = tmp_path / "elsewhere" / recording.name
    twin.parent.mkdir()
    twin.write_bytes(recording.read_bytes())
    broken = EpisodeFile.load(recording)
    broken.target = "examples.nothing:Nothing"
    broken.save(tmp_path / "broken.rlenv")
    inspector = InspectorServer(
        Watcher([]), timelines=Timelines([recording, twin, tmp_path / "broken.rlenv"])
    )
    inspector.start()
    try:
        page = inspector.url
        listed = fetch(page, "api/timelines")[2]["timelines"]
        assert [entry["name"] for entry in listed] == [
            f"{recording.parent.name}/{recording.name}",
            f"elsewhere/{recording.name}",
            "broken.rlenv",
        ]
        status, _, answer = fetch(page, "api/timeline?timeline=2")
        assert status == 422 and "examples.nothing" in answer["error"]
        assert "examples.nothing" in fetch(page, "api/timelines")[2]["timelines"][2]["error"]
        first = fetch(page, "api/timeline/ticks?timeline=0&branch=0&step=3&first=2&count=2")[2]
        assert (first["frames"], first["first"], first["next"]) == (4, 2, 4)
        assert [tick["tick"] for tick in first["ticks"]] == [2, 3]
        rest = fetch(page, "api/timeline/ticks?timeline=0&branch=0&step=3&first=4")[2]
        assert rest["next"] is None and [tick["tick"] for tick in rest["ticks"]] == [4]
        whole = fetch(page, "api/timeline/ticks?timeline=0&branch=0&step=3")[2]
        assert whole["ticks"][1:3] == first["ticks"] and whole["ticks"][3:] == rest["ticks"]
        for query, words in (
            ("first=5", "step 3 has ticks 1 to 4, not 5"),
            ("first=0", "step 3 has ticks 1 to 4, not 0"),
            ("count=101", "count must be 1 to 100"),
            ("count=0", "count must be 1 to 100"),
        ):
            status, _, answer = fetch(page, f"api/timeline/ticks?timeline=0&step=3&{query}")
            assert status == 400 and words in answer["error"], (query, answer)
    finally:
        inspector.close()
