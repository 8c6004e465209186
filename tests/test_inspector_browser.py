"""The inspector's page in a real browser (headless Chromium) beside a training loop.

Marker ``browser``: ``make test-browser`` runs it (``.ci/run`` installs Debian's chromium, best
effort); without a browser it is skipped, saying why. ``RLENV_SCREENSHOT=PATH`` also saves the
page as a PNG (the README's picture).
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit

import pytest
from browser import Browser, find_chromium
from conftest import Serve, wait_until
from inspector_http import Trainer

from rlenv_client import Client
from rlenv_client.inspector import Inspector
from rlenv_client.launcher import ServerProcess
from rlenv_client.replay import EpisodeFile

pytestmark = pytest.mark.browser
CHROMIUM = find_chromium()
REBOUND = "rebound.example"  # a DNS name the browser resolves to 127.0.0.1


@pytest.fixture
def browser() -> Iterator[Browser]:
    if CHROMIUM is None:
        pytest.skip("no Chromium found (apt-get install chromium; .ci/run tries it): the "
                    "browser tests need one, the HTTP-level ones (test_inspector.py) do not")
    with Browser(CHROMIUM, host_rules=f"MAP {REBOUND} 127.0.0.1") as opened:
        yield opened


def test_the_page_shows_a_training_run_and_edits_it(server: ServerProcess,
                                                    browser: Browser) -> None:
    with Trainer(server.host, server.port) as trainer, \
            Inspector([f"{server.host}:{server.port}"]) as inspector, \
            Client(server.host, server.port) as observer:
        wait_until(lambda: trainer.episodes > 1, "the trainer did not start")
        browser.open(inspector.url)
        # the scene: drawn, and redrawn differently as the cart moves
        browser.wait_for("window.inspector && window.inspector.frames > 3", "no frame drawn")
        first = browser.evaluate("document.getElementById('scene').toDataURL()")
        frames = browser.evaluate("window.inspector.frames")
        browser.wait_for(f"window.inspector.frames > {frames + 5}", "the frames stopped")
        second = browser.evaluate("document.getElementById('scene').toDataURL()")
        assert first != second
        painted = browser.evaluate("""(() => {
            const c = document.getElementById('scene');
            const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
            let n = 0; for (let i = 0; i < d.length; i += 4) n += d[i] < 250 || d[i+2] < 250;
            return n; })()""")
        assert painted > 500  # the track, the cart and the pole, not a blank canvas
        # the tree
        paths = browser.wait_for("""(() => { const p = [...document.querySelectorAll('#tree li')]
            .map(li => li.dataset.path); return p.length > 5 && p; })()""", "no tree")
        for name in ("Agent", "World", "World/Physics/Cart", "World/Physics/Pole"):
            assert f"/root/CartPole/{name}" in paths
        # a property edit: World's gravity, a setting
        browser.evaluate("document.querySelector('#tree li[data-path=\"/root/CartPole/World\"]')"
                         ".click()")
        browser.wait_for("!!document.querySelector('#properties input[name=gravity]')",
                         "World's properties did not show")
        browser.wait_for("document.querySelector('#properties input[name=gravity]').value"
                         " === '[0,-9.81]'", "gravity is not shown")
        note = type_into(browser, "gravity", "[0, -3.5]", "t.includes('gravity')")
        assert "kept across episodes" in note
        assert observer.get_property("World/Physics", "gravity") == [0.0, -3.5]
        before = trainer.episodes
        wait_until(lambda: trainer.episodes > before, "the trainer did not reset")
        assert observer.snapshot()["config"]["world"]["gravity"] == [0.0, -3.5]
        # a refused edit shows the server's message
        refused = type_into(browser, "damping", '"thick"', "t.startsWith('refused')")
        assert "CartPoleWorld.damping must be a float" in refused
        # the return plot grows
        plot = "document.getElementById('plot-return').dataset"
        assert int(browser.wait_for(f"{plot}.points", "no return plotted")) > 0
        episodes = int(browser.evaluate(f"{plot}.episodes"))
        browser.wait_for(f"{plot}.episodes > {episodes}", "the return plot did not grow")
        if os.environ.get("RLENV_SCREENSHOT"):
            Path(os.environ["RLENV_SCREENSHOT"]).write_bytes(browser.screenshot())
        assert browser.screenshot().startswith(b"\x89PNG")
        assert trainer.error is None


def type_into(browser: Browser, name: str, text: str, answered: str) -> str:
    """Type ``text`` into the property ``name`` as a person would (then change); the edit
    status the page shows once ``answered`` (a JavaScript test of its text ``t``) holds.
    """
    browser.evaluate(f"""(() => {{ const input =
        document.querySelector('#properties input[name={name}]');
        input.focus(); input.value = {json.dumps(text)};
        input.dispatchEvent(new Event('change')); }})()""")
    return str(browser.wait_for(f"(() => {{ const t = document.getElementById('edit-status')"
                                f".textContent; return ({answered}) && t; }})()",
                                f"the edit of {name} was not answered"))


def test_a_camera_observation_is_shown_as_an_image(serve: Serve, browser: Browser) -> None:
    server = serve("examples.pixels:PixelsEnvironment")
    with Inspector([f"{server.host}:{server.port}"]) as inspector, \
            Client(server.host, server.port) as controller:
        controller.reset(seed=0)
        browser.open(inspector.url)
        size = browser.wait_for("""(() => { const c = document.querySelector(
            '#observations canvas'); return c && [c.width, c.height]; })()""", "no image shown")
        assert size == [84, 84]
        white = browser.evaluate("""(() => { const c = document.querySelector(
            '#observations canvas'); const d = c.getContext('2d').getImageData(0, 0, 84, 84).data;
            let n = 0; for (let i = 0; i < d.length; i += 4) n += d[i] === 255; return n; })()""")
        assert white == 9  # the 3x3 dot on the black screen


def test_properties_stay_shown_across_clicks_and_instances(serve: Serve,
                                                          browser: Browser) -> None:
    server = serve(args=["--instances", "2"])
    with Inspector([f"{server.host}:{server.port}"]) as inspector, \
            Client(server.host, server.port) as controller:
        controller.send_batch([controller.reset_request(1), controller.reset_request(2)])
        controller.receive_batch()
        browser.open(inspector.url)
        rows = "document.querySelectorAll('#properties tbody tr').length"
        world = "document.querySelector('#tree li[data-path=\"/root/CartPole/World\"]')"
        browser.wait_for(f"!!{world}", "no tree")
        browser.evaluate(f"{world}.click()")
        assert browser.wait_for(rows, "no properties") == 5
        browser.evaluate(f"{world}.click()")  # the same node again
        assert browser.wait_for(rows, "the properties went blank after a second click") == 5
        browser.evaluate("""(() => { const select = document.getElementById('target');
            select.value = '0/1'; select.dispatchEvent(new Event('change')); })()""")
        browser.wait_for(f"!!{world}", "no tree for instance 1")
        browser.evaluate(f"{world}.click()")
        assert browser.wait_for(rows, "the properties went blank on instance 1") == 5


def test_the_browser_cannot_reach_it_from_elsewhere(server: ServerProcess,
                                                    browser: Browser) -> None:
    with Inspector([f"{server.host}:{server.port}"]) as inspector, \
            Client(server.host, server.port) as controller:
        controller.reset(seed=0)
        parts = urlsplit(inspector.url)
        body = "document.body.innerText"
        # DNS rebinding: a foreign name that resolves to 127.0.0.1
        browser.open(f"http://{REBOUND}:{parts.port}{parts.path}")
        assert "Host header" in browser.wait_for(body, "no answer to a rebound name")
        # the address without its key
        browser.open(f"http://127.0.0.1:{parts.port}/")
        assert "key" in browser.wait_for(body, "no answer without the key")
        # a page of another origin posting an edit
        browser.open(f"http://{REBOUND}:{parts.port}/elsewhere")
        browser.wait_for(body, "the other origin's page did not load")
        edit = json.dumps({"server": 0, "instance": 0, "path": "World", "property": "damping",
                           "value": 0.9})
        outcome = browser.evaluate(f"""fetch({json.dumps(inspector.url + 'api/edit')}, {{
            method: 'POST', mode: 'no-cors', headers: {{'Content-Type': 'text/plain'}},
            body: {json.dumps(edit)}}}).then(() => 'sent', (e) => 'failed: ' + e)""")
        assert outcome in ("sent", "failed: TypeError: Failed to fetch")
        assert controller.get_property("World", "damping") == 0.3  # unchanged


def press(browser: Browser, key: str, kind: str) -> None:
    """A real key event (``keyDown`` or ``keyUp``) from the browser's input pipeline."""
    codes = {"ArrowLeft": 37, "ArrowRight": 39}
    browser.command("Input.dispatchKeyEvent", session=True, type=kind, key=key, code=key,
                    windowsVirtualKeyCode=codes[key])


def test_a_person_takes_control_and_their_episode_is_recorded(server: ServerProcess,
                                                              browser: Browser,
                                                              tmp_path: Path) -> None:
    with Inspector([f"{server.host}:{server.port}"], record_demonstrations=tmp_path,
                   target="examples.cartpole:CartPoleEnvironment",
                   demonstration_rate=120) as inspector:
        browser.open(inspector.url)
        browser.wait_for("!document.getElementById('take-control').disabled && "
                         "!document.getElementById('control').hidden", "no Take control")
        browser.evaluate("document.getElementById('take-control').click()")
        browser.wait_for("document.getElementById('control-status').textContent"
                         ".includes('you control it')", "control was not taken")
        status = "document.getElementById('control-status').dataset"
        press(browser, "ArrowLeft", "keyDown")
        held = browser.wait_for(f"{status}.held === 'ArrowLeft' && {status}.episodes",
                                "the key did not reach the inspector")
        browser.wait_for(f"{status}.episodes > {int(held) + 1}", "no episode recorded")
        press(browser, "ArrowLeft", "keyUp")
        browser.evaluate("document.getElementById('release-control').click()")
        browser.wait_for("!document.getElementById('take-control').hidden", "not released")
    episode = EpisodeFile.load(tmp_path / f"episode-{int(held) + 2:04d}.rlenv")
    pushes = {float(e[1][0]) for e in episode.snapshot["events"] if e[0] == "action"}
    assert pushes == {-1.0}  # the held key's action, all along
    with Client(server.host, server.port) as trainer:  # control was given back
        trainer.reset()
