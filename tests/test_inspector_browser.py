"""The inspector's page in a real browser (headless Chromium) beside a training loop.

Marker ``browser``: ``make test-browser`` runs it (``.ci/run`` installs Debian's chromium, best
effort); without a browser it is skipped, saying why. ``RLENV_SCREENSHOT=PATH`` also saves the
page as a PNG (the README's picture); ``RLENV_SCREENSHOT_DIR=DIR`` saves the time travel
pictures of docs/time-travel.md there (``make screenshot`` sets both).
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

from examples.cartpole import controller
from rlenv_client import Client
from rlenv_client.launcher import ServerProcess
from rlenv_client.replay import EpisodeFile
from rlenv_tools.inspector import Inspector, InspectorServer, Timelines, Watcher

pytestmark = pytest.mark.browser
CHROMIUM = find_chromium()
REBOUND = "rebound.example"  # a DNS name the browser resolves to 127.0.0.1


@pytest.fixture
def browser() -> Iterator[Browser]:
    if CHROMIUM is None:
        pytest.skip(
            "no Chromium found (apt-get install chromium; .ci/run tries it): the "
            "browser tests need one, the HTTP-level ones (test_inspector.py) do not"
        )
    with Browser(CHROMIUM, host_rules=f"MAP {REBOUND} 127.0.0.1") as opened:
        yield opened


def test_the_page_shows_a_training_run_and_edits_it(
    server: ServerProcess, browser: Browser
) -> None:
    with (
        Trainer(server.host, server.port) as trainer,
        Inspector([f"{server.host}:{server.port}"]) as inspector,
        Client(server.host, server.port) as observer,
    ):
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
        paths = browser.wait_for(
            """(() => { const p = [...document.querySelectorAll('#tree li')]
            .map(li => li.dataset.path); return p.length > 5 && p; })()""",
            "no tree",
        )
        for name in ("Agent", "World", "World/Physics/Cart", "World/Physics/Pole"):
            assert f"/root/CartPole/{name}" in paths
        # a property edit: World's gravity, a setting
        browser.evaluate(
            "document.querySelector('#tree li[data-path=\"/root/CartPole/World\"]').click()"
        )
        browser.wait_for(
            "!!document.querySelector('#properties input[name=gravity]')",
            "World's properties did not show",
        )
        browser.wait_for(
            "document.querySelector('#properties input[name=gravity]').value === '[0,-9.81]'",
            "gravity is not shown",
        )
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
    return str(
        browser.wait_for(
            f"(() => {{ const t = document.getElementById('edit-status')"
            f".textContent; return ({answered}) && t; }})()",
            f"the edit of {name} was not answered",
        )
    )


def test_a_camera_observation_is_shown_as_an_image(serve: Serve, browser: Browser) -> None:
    server = serve("examples.pixels:PixelsEnvironment")
    with (
        Inspector([f"{server.host}:{server.port}"]) as inspector,
        Client(server.host, server.port) as controller,
    ):
        controller.reset(seed=0)
        browser.open(inspector.url)
        size = browser.wait_for(
            """(() => { const c = document.querySelector(
            '#observations canvas'); return c && [c.width, c.height]; })()""",
            "no image shown",
        )
        assert size == [84, 84]
        white = browser.evaluate("""(() => { const c = document.querySelector(
            '#observations canvas'); const d = c.getContext('2d').getImageData(0, 0, 84, 84).data;
            let n = 0; for (let i = 0; i < d.length; i += 4) n += d[i] === 255; return n; })()""")
        assert white == 9  # the 3x3 dot on the black screen


def test_properties_stay_shown_across_clicks_and_instances(serve: Serve, browser: Browser) -> None:
    server = serve(args=["--instances", "2"])
    with (
        Inspector([f"{server.host}:{server.port}"]) as inspector,
        Client(server.host, server.port) as controller,
    ):
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


def test_the_browser_cannot_reach_it_from_elsewhere(
    server: ServerProcess, browser: Browser
) -> None:
    with (
        Inspector([f"{server.host}:{server.port}"]) as inspector,
        Client(server.host, server.port) as controller,
    ):
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
        edit = json.dumps(
            {"server": 0, "instance": 0, "path": "World", "property": "damping", "value": 0.9}
        )
        outcome = browser.evaluate(f"""fetch({json.dumps(inspector.url + "api/edit")}, {{
            method: 'POST', mode: 'no-cors', headers: {{'Content-Type': 'text/plain'}},
            body: {json.dumps(edit)}}}).then(() => 'sent', (e) => 'failed: ' + e)""")
        assert outcome in ("sent", "failed: TypeError: Failed to fetch")
        assert controller.get_property("World", "damping") == 0.3  # unchanged


def press(browser: Browser, key: str, kind: str) -> None:
    """A real key event (``keyDown`` or ``keyUp``) from the browser's input pipeline."""
    codes = {"ArrowLeft": 37, "ArrowRight": 39}
    browser.command(
        "Input.dispatchKeyEvent",
        session=True,
        type=kind,
        key=key,
        code=key,
        windowsVirtualKeyCode=codes[key],
    )


def test_a_person_takes_control_and_their_episode_is_recorded(
    server: ServerProcess, browser: Browser, tmp_path: Path
) -> None:
    with Inspector(
        [f"{server.host}:{server.port}"],
        record_demonstrations=tmp_path,
        target="examples.cartpole:CartPoleEnvironment",
        demonstration_rate=120,
    ) as inspector:
        browser.open(inspector.url)
        browser.wait_for(
            "!document.getElementById('take-control').disabled && "
            "!document.getElementById('control').hidden",
            "no Take control",
        )
        browser.evaluate("document.getElementById('take-control').click()")
        browser.wait_for(
            "document.getElementById('control-status').textContent.includes('you control it')",
            "control was not taken",
        )
        status = "document.getElementById('control-status').dataset"
        press(browser, "ArrowLeft", "keyDown")
        held = browser.wait_for(
            f"{status}.held === 'ArrowLeft' && {status}.episodes",
            "the key did not reach the inspector",
        )
        browser.wait_for(f"{status}.episodes > {int(held) + 1}", "no episode recorded")
        press(browser, "ArrowLeft", "keyUp")
        browser.evaluate("document.getElementById('release-control').click()")
        browser.wait_for("!document.getElementById('take-control').hidden", "not released")
    episode = EpisodeFile.load(tmp_path / f"episode-{int(held) + 2:04d}.rlenv")
    pushes = {float(e[1][0]) for e in episode.snapshot["events"] if e[0] == "action"}
    assert pushes == {-1.0}  # the held key's action, all along
    with Client(server.host, server.port) as trainer:  # control was given back
        trainer.reset()


def test_a_person_chooses_the_agent_to_play_from_the_page(
    serve: Serve, browser: Browser, tmp_path: Path
) -> None:
    """examples.tag, Runner2 driven by the server: the menu offers Chaser and Runner1."""
    server = serve("examples.tag:TagEnvironment", args=["--policy", "Runner2=heuristic"])
    with Inspector(
        [f"{server.host}:{server.port}"],
        record_demonstrations=tmp_path,
        target="examples.tag:TagEnvironment",
        demonstration_rate=120,
    ) as inspector:
        browser.open(inspector.url)
        browser.wait_for(
            "!document.getElementById('control-agent').hidden && "
            "!document.getElementById('take-control').disabled",
            "no menu of agents",
        )
        offered = browser.evaluate(
            "[...document.getElementById('control-agent').options].map((o) => o.value).join(',')"
        )
        assert offered == "Chaser,Runner1"
        browser.evaluate("document.getElementById('control-agent').value = 'Runner1'")
        browser.evaluate("document.getElementById('take-control').click()")
        browser.wait_for(
            "document.getElementById('control-status').textContent.includes('you control Runner1')",
            "control was not taken",
        )
        assert browser.evaluate("document.getElementById('control-agent').hidden")
        browser.evaluate("document.getElementById('release-control').click()")
        browser.wait_for("!document.getElementById('take-control').hidden", "not released")


# --- time travel (docs/time-travel.md) -----------------------------------------------------------

POSITION = "document.getElementById('position').dataset"


@pytest.fixture(scope="module")
def failure(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The docs' example: the drifting controller's CartPole episode (the cart leaves the
    track at step 86)."""
    from examples.time_travel import record_failure

    return record_failure(tmp_path_factory.mktemp("failure"))


def key(browser: Browser, name: str, shift: bool = False) -> None:
    """Press and release ``name`` (a real key event; Shift held with ``shift``)."""
    codes = {"ArrowLeft": 37, "ArrowRight": 39, "Escape": 27, " ": 32}
    modifiers = 8 if shift else 0
    for kind in ("keyDown", "keyUp"):
        browser.command(
            "Input.dispatchKeyEvent",
            session=True,
            type=kind,
            key=name,
            code="Space" if name == " " else name,
            windowsVirtualKeyCode=codes[name],
            modifiers=modifiers,
        )


def scrub(browser: Browser, step: int) -> None:
    """Drag the timeline's slider to ``step`` (its input event, as a drag fires it)."""
    browser.evaluate(f"""(() => {{ const s = document.getElementById('scrubber');
        s.value = {step}; s.dispatchEvent(new Event('input')); }})()""")
    at(browser, step)


def at(browser: Browser, step: int, tick: int = 0, branch: int = 0) -> None:
    browser.wait_for(
        f"{POSITION}.step === '{step}' && {POSITION}.tick === '{tick}' && "
        f"{POSITION}.branch === '{branch}' && !window.timeline.inflight",
        f"the page did not show step {step} tick {tick} of branch {branch}",
    )


def shown(browser: Browser, name: str) -> str:
    """The shown value of the selected node's property ``name``."""
    return str(
        browser.wait_for(
            f"(() => {{ const i = document.querySelector("
            f"'#properties input[name={name}]'); return i && i.value; }})()",
            f"no property {name} shown",
        )
    )


def save_screenshot(browser: Browser, name: str) -> None:
    """The whole page as ``$RLENV_SCREENSHOT_DIR/NAME`` (``make screenshot`` sets it)."""
    folder = os.environ.get("RLENV_SCREENSHOT_DIR")
    if folder:
        height = browser.evaluate("document.documentElement.scrollHeight")
        browser.command(
            "Emulation.setDeviceMetricsOverride",
            session=True,
            width=1400,
            height=height,
            deviceScaleFactor=1,
            mobile=False,
        )  # no scroll bar
        try:
            Path(folder, name).write_bytes(browser.screenshot())
        finally:
            browser.command(
                "Emulation.setDeviceMetricsOverride",
                session=True,
                width=1400,
                height=1000,
                deviceScaleFactor=1,
                mobile=False,
            )


def test_time_travel_scrubs_steps_ticks_and_plays_a_recording(
    failure: Path, browser: Browser, tmp_path: Path
) -> None:
    from examples.time_travel import record_failure

    sooner = record_failure(tmp_path, bias=0.03)  # a second file: the pole falls at step 20
    with Inspector([], recordings=[failure, sooner]) as inspector:  # rlenv replay ... --inspect
        browser.open(inspector.url)
        at(browser, 0)
        assert browser.evaluate("document.getElementById('scrubber').max") == "86"
        assert browser.evaluate("document.getElementById('timeline-live').hidden")
        cart = "document.querySelector('#tree li[data-path$=\"/Physics/Cart\"]')"
        browser.wait_for(f"!!{cart}", "no tree at step 0")
        browser.evaluate(f"{cart}.click()")
        # scrub: the scene and the properties are those of the scrubbed step
        scrub(browser, 80)
        late, scene80 = (
            shown(browser, "position"),
            browser.evaluate("document.getElementById('scene').toDataURL()"),
        )
        assert float(json.loads(late)[0]) == pytest.approx(-2.2152, abs=1e-3)
        assert "step 80" in browser.evaluate(
            "document.getElementById('properties').tBodies[0].dataset.moment"
        )
        scrub(browser, 40)
        assert shown(browser, "position") != late
        assert browser.evaluate("document.getElementById('scene').toDataURL()") != scene80
        # a fast drag asks for the step it ends on, not for every step it crossed
        loads = browser.evaluate("window.timeline.loads")
        browser.evaluate("""(() => { const s = document.getElementById('scrubber');
            for (let k = 1; k <= 60; k++) { s.value = k; s.dispatchEvent(new Event('input')); }
            })()""")
        at(browser, 60)
        assert browser.evaluate("window.timeline.loads") - loads < 10
        # steps: the arrow keys and the buttons
        key(browser, "ArrowRight")
        at(browser, 61)
        at61 = shown(browser, "position")
        key(browser, "ArrowLeft")
        at(browser, 60)
        browser.evaluate("document.getElementById('step-forward').click()")
        at(browser, 61)
        # ticks: Shift and the arrows, or the buttons; four ticks make step 62
        key(browser, "ArrowRight", shift=True)
        at(browser, 61, tick=1)
        assert "tick 1 of step 62" in browser.evaluate(
            "document.getElementById('properties').tBodies[0].dataset.moment"
        )
        tick1 = shown(browser, "position")
        assert tick1 != at61
        for tick in (2, 3):
            browser.evaluate("document.getElementById('tick-forward').click()")
            at(browser, 61, tick=tick)
        browser.evaluate("document.getElementById('tick-forward').click()")
        at(browser, 62)
        browser.evaluate("document.getElementById('tick-back').click()")
        at(browser, 61, tick=3)
        key(browser, "ArrowLeft", shift=True)
        at(browser, 61, tick=2)
        # play, pause, and play on to the end, where it stops by itself
        browser.evaluate("document.getElementById('play').click()")
        browser.wait_for(f"+{POSITION}.step > 66", "playing did not step on")
        browser.evaluate("document.getElementById('play').click()")
        browser.wait_for(
            "!window.timeline.inflight && window.timeline.wanted === null",
            "the last step did not arrive",
        )
        paused = browser.evaluate(f"{POSITION}.step")
        browser.evaluate("new Promise((done) => setTimeout(done, 400))")  # four play intervals
        assert browser.evaluate(f"{POSITION}.step") == paused
        assert browser.evaluate("document.getElementById('play').dataset.playing") == "false"
        scrub(browser, 83)
        key(browser, " ")  # Space: play
        at(browser, 86)
        browser.wait_for(
            "document.getElementById('play').dataset.playing === 'false'",
            "playing did not stop at the end",
        )
        assert "terminated" in browser.evaluate("document.getElementById('position').textContent")
        # the other file
        browser.evaluate("""(() => { const s = document.getElementById('timeline-select');
            s.value = '1'; s.dispatchEvent(new Event('change')); })()""")
        browser.wait_for(
            "window.timeline.number === 1 && document.getElementById('scrubber').max === '20'",
            "no second file",
        )
        at(browser, 0)


def test_time_travel_branches_with_keys_and_a_policy_side_by_side(
    failure: Path, browser: Browser
) -> None:
    inspector = InspectorServer(
        Watcher([]), timelines=Timelines([failure], policies={"controller": controller})
    )
    inspector.start()
    try:
        browser.open(inspector.url)
        at(browser, 0)
        assert browser.evaluate("document.getElementById('compare').hidden")
        pole = "document.querySelector('#tree li[data-path$=\"/Physics/Pole\"]')"
        browser.wait_for(f"!!{pole}", "no tree")
        browser.evaluate(f"{pole}.click()")
        scrub(browser, 80)
        save_screenshot(browser, "time-travel-scrub.png")
        # branch with the keys at step 70: each press one more action
        scrub(browser, 70)
        browser.evaluate("document.getElementById('branch-here').click()")
        browser.wait_for(
            "document.getElementById('branch-status').textContent"
            ".includes('ArrowLeft, ArrowRight')",
            "branching did not start",
        )
        key(browser, "ArrowRight")
        at(browser, 71, branch=1)
        key(browser, "ArrowRight")
        at(browser, 72, branch=1)
        tree = "document.getElementById('branches')"
        assert browser.evaluate(f"{tree}.dataset.count") == "2"
        assert (
            browser.evaluate(
                f'{tree}.querySelector(\'li[data-branch="0"] > ul > '
                'li[data-branch="1"] > span\').textContent'
            )
            == "#1 keys ArrowRight ArrowRight · from step 70 · 72 steps"
        )
        compare = "document.getElementById('compare').dataset"
        browser.wait_for(
            f"{compare}.firstDifference === '71' && {compare}.step === '72'",
            "the episode and the key branch are not side by side",
        )
        assert browser.evaluate(f"[{compare}.a, {compare}.b]") == ["0", "1"]
        key(browser, "Escape")
        browser.wait_for("document.getElementById('branch-done').hidden", "still branching")
        # branch with a policy given from Python, from step 60 of the episode
        browser.evaluate(f"{tree}.querySelector('li[data-branch=\"0\"] > span').click()")
        at(browser, 72)
        scrub(browser, 60)
        browser.evaluate("document.getElementById('policy-steps').value = 100")
        browser.evaluate("document.getElementById('branch-policy').click()")
        browser.wait_for(f"{tree}.dataset.count === '3'", "no policy branch")
        at(browser, 60, branch=2)
        assert (
            browser.evaluate(
                f'{tree}.querySelector(\'li[data-branch="0"] > ul > '
                'li[data-branch="2"] > span\').textContent'
            )
            == "#2 policy controller · from step 60 · 160 steps"
        )
        browser.wait_for(
            f"{compare}.firstDifference === '61' && {compare}.b === '2'",
            "the policy branch is not side by side",
        )
        key(browser, "ArrowRight")
        at(browser, 61, branch=2)
        browser.wait_for(f"{compare}.step === '61'", "the side by side did not follow")
        rows = browser.evaluate(
            "[...document.querySelectorAll('#compare-table tr')].map("
            "r => [...r.cells].map(c => c.textContent))"
        )
        assert rows[0] == ["", "A #0", "B #2", "B − A"] and rows[1][0] == "reward"
        assert [row[0] for row in rows[2:]] == [f"Agent[{i}]" for i in range(5)]
        assert any(float(row[3]) != 0 for row in rows[2:])
        status = browser.evaluate("document.getElementById('compare-status').textContent")
        assert status == "first difference at step 61 · returns 342 and 640"  # 160 more steps
        # two branches: the key branch against the policy's
        browser.evaluate("""(() => { const a = document.getElementById('compare-a');
            a.value = '1'; a.dispatchEvent(new Event('change')); })()""")
        browser.wait_for(
            f"{compare}.a === '1' && {compare}.firstDifference === '61'",
            "the two branches are not side by side",
        )
        # the episode against the policy's branch where the episode ends
        browser.evaluate("""(() => { const a = document.getElementById('compare-a');
            a.value = '0'; a.dispatchEvent(new Event('change')); })()""")
        browser.evaluate("""(() => { const s = document.getElementById('scrubber');
            s.value = 86; s.dispatchEvent(new Event('input')); })()""")
        at(browser, 86, branch=2)
        browser.wait_for(
            f"{compare}.a === '0' && {compare}.step === '86'",
            "the side by side did not follow to step 86",
        )
        rows = browser.evaluate(
            "[...document.querySelectorAll('#compare-table tr')].map("
            "r => [...r.cells].map(c => c.textContent))"
        )
        assert rows[1] == ["reward", "2", "4", "2"]  # the episode's last step: half a reward
        for plotted in ("compare-rewards", "compare-returns"):  # 87 and 161 steps' points
            assert browser.evaluate(f"document.getElementById('{plotted}').dataset.points") == "248"
        save_screenshot(browser, "time-travel-branches.png")
        assert browser.console == [] or not any("rror" in line for line in browser.console)
    finally:
        inspector.close()


def test_time_travel_says_why_a_recording_did_not_open_and_tells_twins_apart(
    failure: Path, browser: Browser, tmp_path: Path
) -> None:
    broken = EpisodeFile.load(failure)
    broken.target = "examples.nothing:Nothing"
    broken.save(tmp_path / "broken.rlenv")
    twin = tmp_path / "elsewhere" / failure.name
    twin.parent.mkdir()
    twin.write_bytes(failure.read_bytes())
    timelines = Timelines(
        [tmp_path / "broken.rlenv", failure, twin], policies={"controller": controller}
    )
    timelines.branch_policy(1, 0, 60, "controller", 20)  # made before the page opens it
    inspector = InspectorServer(Watcher([]), timelines=timelines)
    inspector.start()
    try:
        browser.open(inspector.url)
        status = "document.getElementById('timeline-status')"
        browser.wait_for(
            f"{status}.textContent.includes('examples.nothing')",
            "the page did not say why the first recording did not open",
        )
        assert browser.evaluate(f"{status}.classList.contains('bad')")
        assert not browser.evaluate("document.getElementById('timeline').hidden")
        assert browser.evaluate("document.getElementById('timeline-body').hidden")
        options = browser.wait_for(
            """(() => { const o = [...document.querySelectorAll(
            '#timeline-select option')].map(o => o.textContent);
            return o[0].includes('did not open') && o; })()""",
            "the menu did not mark it",
        )
        assert options == [
            "broken.rlenv (did not open)",
            f"{failure.parent.name}/{failure.name}",
            f"elsewhere/{failure.name}",
        ]
        # the menu is still there: another recording opens, with its episode and newest
        # branch side by side
        browser.evaluate("""(() => { const s = document.getElementById('timeline-select');
            s.value = '1'; s.dispatchEvent(new Event('change')); })()""")
        at(browser, 0)
        assert not browser.evaluate("document.getElementById('timeline-body').hidden")
        compare = "document.getElementById('compare').dataset"
        browser.wait_for(
            f"{compare}.a === '0' && {compare}.b === '1'",
            "side by side did not start at the episode and the newest branch",
        )
        assert browser.evaluate(f"{compare}.firstDifference") == "61"
        browser.evaluate("""(() => { const s = document.getElementById('timeline-select');
            s.value = '2'; s.dispatchEvent(new Event('change')); })()""")
        browser.wait_for("window.timeline.number === 2", "the twin did not open")
        at(browser, 0)
        assert browser.evaluate("document.getElementById('compare').hidden")  # no branch yet
    finally:
        inspector.close()


def test_time_travel_on_a_live_run_opens_a_recent_episode(
    server: ServerProcess, browser: Browser
) -> None:
    """The live page lists the watched instance's recent episodes (the server keeps its last 8)
    and opens one as a timeline; Back to live returns to the live scene."""
    with (
        Trainer(server.host, server.port) as trainer,
        Inspector([f"{server.host}:{server.port}"]) as inspector,
    ):
        wait_until(lambda: trainer.episodes > 3, "the trainer did not finish episodes")
        browser.open(inspector.url)
        browser.wait_for("window.inspector.frames > 3", "no live frame")
        items = "document.querySelectorAll('#recent-list li[data-episode]')"
        browser.wait_for(f"{items}.length >= 3", "no recent episodes listed")
        text = browser.evaluate(f"[...{items}].pop().textContent")
        steps = int(text.split(" · ")[1].split()[0])  # "episode 8 of 8 · 23 steps · terminated"
        browser.evaluate(f"[...{items}].pop().click()")
        at(browser, 0)  # found, though the trainer finished more episodes since the list
        assert browser.evaluate("document.getElementById('scrubber').max") == str(steps)
        assert not browser.evaluate("document.getElementById('timeline-live').hidden")
        assert browser.evaluate("document.getElementById('recent').hidden")
        frames = browser.evaluate("window.inspector.frames")
        scrub(browser, steps - 1)
        key(browser, "ArrowRight")
        at(browser, steps)
        assert "terminated" in browser.evaluate(
            "document.getElementById('position').textContent"
        )  # the pole fell: it was kept
        assert browser.evaluate("window.inspector.frames") == frames  # the live scene rests
        browser.evaluate("document.getElementById('timeline-live').click()")
        browser.wait_for(f"window.inspector.frames > {frames + 3}", "live frames did not resume")
        browser.wait_for("!document.getElementById('recent').hidden", "no recent list again")
        assert trainer.error is None
