"""The live inspector over HTTP: its API beside a trainer, its safety rules, its processes.

The browser itself is driven in ``test_inspector_browser.py`` (marker ``browser``).
"""

from __future__ import annotations

import json
import select
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import urlsplit

import numpy as np
import pytest
from conftest import Serve, wait_until
from inspector_http import Trainer, fetch

from examples.cartpole import controller
from rlenv_client import Client, RemoteEnv
from rlenv_client.launcher import ServerProcess
from rlenv_tools.inspector import Inspector, InspectorError, InspectorServer, Watcher

POLE = "/root/CartPole/World/Physics/Pole"
TESTS = Path(__file__).resolve().parent


@contextmanager
def watching(server: ServerProcess, token: str | None = None) -> Iterator[str]:
    """The URL of an inspector in this process watching ``server`` (closed afterwards)."""
    inspector = InspectorServer(Watcher([f"{server.host}:{server.port}"], token=token))
    inspector.start()
    try:
        yield inspector.url
    finally:
        inspector.close()


@pytest.fixture
def page(server: ServerProcess) -> Iterator[str]:
    """The URL of an inspector (in this process) watching the CartPole ``server``."""
    with watching(server) as url:
        yield url


def _port(url: str) -> int:
    port = urlsplit(url).port
    assert port is not None
    return port


def test_the_page_and_its_assets_come_with_safe_headers(page: str) -> None:
    status, headers, html = fetch(page)
    assert status == 200 and headers["content-type"].startswith("text/html")
    assert b'src="static/inspector.js"' in html and b'<canvas id="scene"' in html
    for name, kind in (("inspector.js", "text/javascript"), ("inspector.css", "text/css")):
        status, headers, _ = fetch(page, f"static/{name}")
        assert status == 200 and headers["content-type"].startswith(kind)
    assert "script-src 'self'" in headers["content-security-policy"]
    assert headers["x-frame-options"] == "DENY" and headers["referrer-policy"] == "no-referrer"
    assert not [name for name in headers if name.startswith("access-control")]
    status, headers, _ = fetch(page.rstrip("/"))
    assert status == 308 and headers["location"] == urlsplit(page).path


def test_foreign_hosts_origins_and_missing_keys_are_refused(page: str) -> None:
    port = _port(page)
    base = f"http://127.0.0.1:{port}/"
    key = urlsplit(page).path.strip("/")
    refusals = [
        (base, "api/servers", {}, "key"),  # no key
        (base + "wrong-key/", "api/servers", {}, "key"),
        (page, "api/servers", {"Host": "attacker.example"}, "Host"),
        (page, "api/servers", {"Host": f"attacker.example:{port}"}, "Host"),
        (page, "api/servers", {"Host": f"127.0.0.1.attacker.example:{port}"}, "Host"),
        (page, "api/servers", {"Host": "127.0.0.1:1"}, "Host"),  # another port
        (page, "", {"Origin": "http://attacker.example"}, "origin"),
        (page, "api/servers", {"Origin": f"http://127.0.0.1:{port + 1}"}, "origin"),
    ]
    for url, path, headers, word in refusals:
        status, _, body = fetch(url, path, headers=headers)
        assert status == 403 and word in body["error"], (url, path, headers, body)
    for host in (f"localhost:{port}", f"127.0.0.1:{port}", f"[::1]:{port}"):
        assert fetch(page, "api/servers", headers={"Host": host})[0] == 200
    assert fetch(page, "api/servers", headers={"Origin": f"http://localhost:{port}"})[0] == 200
    edit = {"server": 0, "instance": 0, "path": "World", "property": "damping", "value": 0.5}
    status, _, body = fetch(
        page, "api/edit", method="POST", body=edit, headers={"Origin": "http://attacker.example"}
    )
    assert status == 403
    status, _, body = fetch(base + "nokey/", "api/edit", method="POST", body=edit)
    assert status == 403
    assert fetch(page, "api/edit")[0] == 404  # a change is a POST
    status, _, body = fetch(
        page,
        "api/edit",
        method="POST",
        raw=b"damping=0.5",
        headers={"Content-Type": "application/x-www-form-urlencoded"},
    )
    assert status == 415  # what a cross-site form could send
    status, headers, _ = fetch(
        page,
        "api/edit",
        method="OPTIONS",
        headers={"Origin": "http://attacker.example", "Access-Control-Request-Method": "POST"},
    )
    assert status in (403, 405) and not [h for h in headers if h.startswith("access-control")]
    assert fetch(page, "api/edit", method="PUT", body=edit)[0] == 405
    assert key not in str(fetch(base, "api/servers")[2])  # a refusal never tells the key


def test_malformed_edits_get_precise_errors(page: str, client: Client) -> None:
    client.reset(seed=0)
    cases = [
        (b"{not json", "not JSON"),
        (b'{"server": 0}', "exactly"),
        (
            b'{"server": -1, "instance": 0, "path": "World", "property": "damping", "value": 1}',
            "server must be an integer >= 0",
        ),
        (
            b'{"server": 0, "instance": 0, "path": 3, "property": "damping", "value": 1}',
            "path must be a string",
        ),
    ]
    for raw, words in cases:
        status, _, body = fetch(page, "api/edit", method="POST", raw=raw)
        assert status == 400 and words in body["error"], (raw, body)
    edit = {"server": 0, "instance": 0, "path": POLE, "property": "angle", "value": "steep"}
    status, _, body = fetch(page, "api/edit", method="POST", body=edit)
    assert status == 422 and "RigidBody.angle must be a float" in body["error"]
    status, _, body = fetch(
        page, "api/edit", method="POST", raw=json.dumps({**edit, "value": float("nan")}).encode()
    )
    assert status == 400 and "NaN is not a value an edit may carry" in body["error"]
    status, _, body = fetch(
        page, "api/edit", method="POST", raw=b"{}", headers={"Content-Length": "abc"}
    )
    assert status == 400 and "Content-Length" in body["error"]
    edit = {**edit, "server": 3}
    assert fetch(page, "api/edit", method="POST", body=edit)[0] == 404
    assert fetch(page, "api/node?path=Nowhere")[2]["error"].endswith("no node at path 'Nowhere'")
    assert fetch(page, "api/stats?since=-2")[0] == 400
    assert fetch(page, "api/frame?instance=1")[0] == 404


def test_it_watches_a_trainer_and_edits_between_its_steps(server: ServerProcess, page: str) -> None:
    with Trainer(server.host, server.port) as trainer:
        wait_until(lambda: trainer.episodes > 3, "the trainer did not run")
        status, _, servers = fetch(page, "api/servers")
        assert status == 200 and servers[0]["environment"] == "CartPole"
        assert servers[0]["instances"] == 1 and servers[0]["protocol"] == "2.7"
        frames = [fetch(page, "api/frame")[2] for _ in range(3)]
        assert all(len(f["draw"]["shapes"]) == 3 for f in frames)
        assert len({str(f["draw"]["shapes"]) for f in frames}) > 1  # the cart moves
        assert len(frames[0]["observation"]["Agent"]["numbers"]) == 5
        tree = fetch(page, "api/tree")[2]
        assert {node["path"].rpartition("/")[2] for node in tree} >= {
            "CartPole",
            "Agent",
            "World",
            "Physics",
            "Cart",
            "Pole",
            "Hinge",
        }
        edit = {
            "server": 0,
            "instance": 0,
            "path": "/root/CartPole/World",
            "property": "gravity",
            "value": [0.0, -20.0],
        }
        status, _, body = fetch(page, "api/edit", method="POST", body=edit)
        assert (status, body) == (200, {"scope": "setting"})
        edit = {**edit, "path": POLE, "property": "angular_velocity", "value": 1.0}
        assert fetch(page, "api/edit", method="POST", body=edit)[2] == {"scope": "episode"}
        snapshot = fetch(page, "api/snapshot")[2]
        before = trainer.episodes
        wait_until(lambda: trainer.episodes > before + 2, "the trainer stopped")
        stats = fetch(page, "api/stats")[2]
        assert trainer.error is None
    assert fetch(page, "api/node?path=World/Physics")[2]["exported"]["gravity"] == [0.0, -20.0]
    assert ["config", {"world": {"gravity": [0.0, -20.0]}}] in snapshot["events"] or snapshot[
        "config"
    ]["world"]["gravity"] == [0.0, -20.0]  # a reset came in between
    assert stats["next"] >= 3 and stats["steps"] > 0 and stats["restarts"] == 0
    assert all(e["end"] in ("terminated", "truncated", "reset") for e in stats["episodes"])
    assert sum(e["length"] for e in stats["episodes"]) <= stats["steps"]
    later = fetch(page, f"api/stats?since={stats['next'] - 1}")[2]["episodes"]
    assert [e["episode"] for e in later][:1] == [stats["next"] - 1]


def test_the_token_stays_out_of_the_page(serve: Serve) -> None:
    token = "s3cret-token-for-the-inspector-test"
    server = serve(args=["--token", token])
    with (
        watching(server, token) as url,
        Client(server.host, server.port, token=token) as controller,
    ):
        controller.reset(seed=0)
        controller.step(np.zeros(1, np.float32))
        bodies = [
            fetch(url, path)[2]
            for path in (
                "",
                "static/inspector.js",
                "api/servers",
                "api/frame",
                "api/tree",
                "api/node?path=World",
                "api/stats",
                "api/snapshot",
            )
        ]
    assert all(token not in str(body) for body in bodies)
    assert "error" not in bodies[2][0] and bodies[3]["draw"]["shapes"]
    with watching(server, token="") as url:
        assert "unauthorized" in fetch(url, "api/servers")[2][0]["error"]


def test_several_instances_are_chosen_one_by_one(serve: Serve) -> None:
    server = serve(args=["--instances", "2"])
    with watching(server) as url:
        with Client(server.host, server.port) as controller:
            controller.send_batch([controller.reset_request(1), controller.reset_request(2)])
            controller.receive_batch()
            assert fetch(url, "api/servers")[2][0]["instances"] == 2
            first = fetch(url, "api/frame?instance=0")[2]
            second = fetch(url, "api/frame?instance=1")[2]
            assert first["observation"] != second["observation"]  # other seeds
            assert fetch(url, "api/frame?instance=2")[0] == 404
            edit = {
                "server": 0,
                "instance": 1,
                "path": "Agent",
                "property": "max_force",
                "value": 3.0,
            }
            fetch(url, "api/edit", method="POST", body=edit)
            forces = [
                fetch(url, f"api/node?path=Agent&instance={i}")[2]["exported"]["max_force"]
                for i in (0, 1)
            ]
            assert forces == [10.0, 3.0]


def test_camera_observations_come_as_images(serve: Serve) -> None:
    server = serve("examples.pixels:PixelsEnvironment")
    with watching(server) as url:
        with Client(server.host, server.port) as controller:
            controller.reset(seed=0)
            frame = fetch(url, "api/frame")[2]
    image = frame["observation"]["Agent"]["image"]
    assert (image["width"], image["height"], image["channels"]) == (84, 84, 3)
    assert [shape[0] for shape in frame["draw"]["shapes"]] == ["polygon", "polygon"]


@pytest.mark.parametrize(
    "target",
    [
        "examples.cartpole:CartPoleEnvironment",
        "examples.seeker:SeekerEnvironment",
        "examples.seeker:SeekerPixelsEnvironment",
        "examples.reacher:ReacherEnvironment",
        "examples.pair:PairEnvironment",
        "examples.pixels:PixelsEnvironment",
    ],
)
def test_every_example_can_be_watched(serve: Serve, target: str) -> None:
    server = serve(target)
    with watching(server) as url:
        with Client(server.host, server.port) as controller:
            controller.reset(seed=0)
            controller.step(controller.action_space.sample())
            frame = fetch(url, "api/frame")[2]
            tree = fetch(url, "api/tree")[2]
            stats = fetch(url, "api/stats")[2]
    assert frame["draw"]["shapes"]
    assert set(frame["observation"]) == set(controller.hello.agents)
    for shown in frame["observation"].values():
        assert "image" in shown or "numbers" in shown or "parts" in shown
    assert tree[0]["path"] == f"/root/{controller.hello.environment}"
    assert stats["current"]["length"] == 1
    if len(controller.hello.agents) > 1:
        assert set(stats["current"]["returns"]) == set(controller.hello.agents)


def test_an_agents_setting_is_its_own_among_several(serve: Serve) -> None:
    """The node panel sets one agent of several (config.agent by its name): it lasts, and
    the other agent keeps its own value."""
    server = serve("compliance_envs:GainPairEnvironment", env={"PYTHONPATH": str(TESTS)})
    with watching(server) as url:
        with Client(server.host, server.port) as controller:
            controller.reset(seed=0)
            red = fetch(url, "api/node?path=Red")[2]
            assert red["configurable"] == ["gain"] and red["settings"] == ["gain"]
            edit = {"server": 0, "instance": 0, "path": "Red", "property": "gain", "value": 5.0}
            assert fetch(url, "api/edit", method="POST", body=edit)[2] == {"scope": "setting"}
            controller.reset(seed=1)  # a setting outlives the episode
            gains = [controller.get_property(name, "gain") for name in ("Red", "Blue")]
            kept = controller.snapshot()["config"]["agent"]
    assert gains == [5.0, 1.0]
    assert kept == {"Red": {"gain": 5.0}, "Blue": {"gain": 1.0}}


def test_a_dead_inspector_never_stops_the_training() -> None:
    env = RemoteEnv("examples.cartpole:CartPoleEnvironment", inspector=True, max_restarts=1)
    try:
        assert env.inspector is not None and env.server is not None
        url, process = env.inspector.url, env.inspector._process
        env.reset(seed=0)
        assert fetch(url, "api/servers")[2][0]["environment"] == "CartPole"  # connected
        process.kill()  # while it watches: its observer connection drops mid-episode
        process.wait()

        def train(steps: int) -> float:
            observation, _ = env.reset(seed=1)
            total = 0.0
            for _ in range(steps):
                observation, reward, terminated, truncated, info = env.step(controller(observation))
                assert info["frames"] == 4 and not truncated
                total += reward
                if terminated:
                    observation, _ = env.reset()
            return total

        assert train(100) == 400.0  # the controller balances the pole: +1 for every tick
        first = env.server.pid
        env.server.process.kill()  # the restart is reported to the dead inspector ...
        *_, truncated, info = env.step(np.zeros(1, np.float32))
        assert truncated and "server_restarted" in info
        assert env.server.pid != first
        assert train(100) == 400.0  # ... which lets it go: the training goes on
    finally:
        env.close()  # closing what is left of the inspector raises nothing either
    assert process.returncode is not None


def test_rlenv_inspect_prints_its_page_and_ends_with_its_parent(server: ServerProcess) -> None:
    with Inspector([f"{server.host}:{server.port}"]) as inspector:
        assert inspector.url.startswith("http://127.0.0.1:")
        assert fetch(inspector.url, "api/servers")[2][0]["environment"] == "CartPole"
        process = inspector._process
    assert process.returncode is not None  # closing its standard input ended it
    bad = subprocess.run(
        [sys.executable, "-m", "rlenv", "inspect", "nowhere"],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert bad.returncode == 2 and "HOST:PORT" in bad.stderr


def test_a_remote_env_inspector_follows_a_restarted_server() -> None:
    env = RemoteEnv("examples.cartpole:CartPoleEnvironment", inspector=True, max_restarts=1)
    try:
        assert env.inspector is not None
        url = env.inspector.url
        env.reset(seed=0)
        first = fetch(url, "api/servers")[2][0]["address"]
        assert first == env.client.address
        assert env.server is not None
        env.server.process.kill()
        *_, truncated, info = env.step(np.zeros(1, np.float32))
        assert truncated and "server_restarted" in info
        env.reset(seed=1)

        def moved() -> bool:
            described = fetch(url, "api/servers")[2][0]
            return described["address"] == env.client.address and "error" not in described

        wait_until(moved, "the inspector did not follow the restarted server")
        assert fetch(url, "api/servers")[2][0]["restarts"] == 1
        assert fetch(url, "api/frame")[0] == 200
    finally:
        env.close()
    assert env.inspector is None


def test_rlenv_serve_inspect_starts_an_inspector_that_ends_with_it(serve: Serve) -> None:
    server = serve(args=["--inspect"])
    wait_until(
        lambda: "inspector on " in server.output,
        "rlenv serve --inspect printed no inspector address",
    )
    url = server.output.split("inspector on ", 1)[1].split()[0]
    assert fetch(url, "api/servers")[2][0]["address"] == f"{server.host}:{server.port}"
    server.close()
    wait_until(lambda: _refused(url), "the inspector outlived its server")


def test_rlenv_serve_inspect_may_record_demonstrations(serve: Serve, tmp_path: Path) -> None:
    server = serve(args=["--inspect", "--record-demonstrations", str(tmp_path)])
    wait_until(
        lambda: "inspector on " in server.output,
        "rlenv serve --inspect printed no inspector address",
    )
    url = server.output.split("inspector on ", 1)[1].split()[0]
    assert fetch(url, "api/control")[2]["enabled"] is True
    alone = subprocess.run(
        [
            sys.executable,
            "-m",
            "rlenv",
            "serve",
            "examples.cartpole:CartPoleEnvironment",
            "--record-demonstrations",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert alone.returncode == 2 and "it goes with --inspect" in alone.stderr


def _refused(url: str) -> bool:
    try:
        fetch(url, "api/servers")
    except OSError:
        return True
    return False


def test_restarts_count_new_processes_not_idle_reconnections(serve: Serve) -> None:
    first = serve(args=["--idle-timeout", "3.0"])  # the controller's steps within it
    watcher = Watcher([f"{first.host}:{first.port}"])
    try:
        with Client(first.host, first.port) as controller:
            controller.reset(seed=0)
            for _ in range(3):
                controller.step(np.zeros(1, np.float32))
            assert watcher.stats(0, 0, 0)["restarts"] == 0
            connection = watcher._servers[0].client
            assert connection is not None and connection._sock is not None
            idle = connection._sock
            wait_until(
                lambda: select.select([idle], [], [], 0)[0] != [],
                "the server kept an idle connection",
            )
            wait_until(lambda: _answers(watcher), "the inspector did not reconnect")
            assert watcher.stats(0, 0, 0)["restarts"] == 0  # the same server: no restart
        port = first.port
        first.close()
        wait_until(lambda: not _answers(watcher), "the server did not go away")
        serve(port=port)  # a new process at the same address
        wait_until(lambda: _answers(watcher), "the inspector did not reach the new server")
        assert watcher.stats(0, 0, 0)["restarts"] == 1
    finally:
        watcher.close()


def _answers(watcher: Watcher) -> bool:
    try:
        watcher.stats(0, 0, 0)
    except InspectorError:
        return False
    return True
