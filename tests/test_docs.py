"""The documentation site: it builds without a warning, and its reference covers what users touch.

Run by ``make docs`` (the ``docs`` extra: mkdocs, Material, mkdocstrings); ``make test`` leaves
it out. Each build is a real ``mkdocs build --strict`` in a subprocess.
"""

from __future__ import annotations

import html
import importlib.util
import os
import re
import subprocess
import sys
import textwrap
import zlib
from pathlib import Path

import pytest

pytestmark = pytest.mark.docs

ROOT = Path(__file__).resolve().parent.parent
BUILD_TIMEOUT = 300

# What new users had to guess (issue 19), with words the rendered entry must contain.
EXPECTED = {
    "rlenv.node.Node": ["ready", "process_mode"],
    "rlenv.node.Node.child_entered_tree": ["child_entered_tree(node)"],
    "rlenv.signals.Signal": ["arguments"],
    "rlenv.tree.SceneTree": ["physics_ticks_per_second"],
    "rlenv.timer.PhysicsFramesTimer": ["timeout"],
    "rlenv.environment.RLEnvironment": ["repeat_action"],
    "rlenv.environment.RLEnvironment._reset": [],
    "rlenv.environment.RLEnvironment._step": [],
    "rlenv.environment.RLEnvironment._get_info": [],
    "rlenv.agent.RLAgent": ["action_space", "observation_space"],
    "rlenv.agent.RLAgent._after_physics_tick": ["after the physics stepped"],
    "rlenv.world.RLEnvWorld": [],
    "rlenv.world.RLEnvWorld._edit_level": ["n_edits", "bad_request"],
    "rlenv_client.base.BaseClient.edit_level": ["n_edits", "takes control"],
    "rlenv.world.RLEnvWorld.check_options": ["before anything changes", "bad_request"],
    "rlenv.rl_node.RLNode": ["configurable"],
    "rlenv.scene2d.physics.world.PhysicsWorld": ["gravity"],
    "rlenv.scene2d.physics.body.RigidBody": ["mass", "moment"],
    "rlenv.scene2d.physics.body.RigidBody.apply_force": ["world coordinates", "body's own frame"],
    "rlenv.scene2d.physics.body.StaticBody": ["never moves"],
    "rlenv.scene2d.physics.body.KinematicBody": ["velocity"],
    "rlenv.scene2d.physics.body.PhysicsBody.body_entered": ["body_entered(body)"],
    "rlenv.scene2d.physics.body.PhysicsBody.position": ["world coordinates"],
    "rlenv.scene2d.physics.body.PhysicsBody.angle": ["radians"],
    "rlenv.scene2d.physics.collision_shape.CollisionShape.box": ["width", "height", "mass"],
    "rlenv.scene2d.physics.collision_shape.CollisionShape.segment": ["radius", "body's frame"],
    "rlenv.scene2d.physics.collision_shape.CollisionShape.circle": ["radius"],
    "rlenv.scene2d.physics.collision_shape.CollisionShape.collision_started": [
        "collision_started(shape)"
    ],
    "rlenv.scene2d.physics.joint.Joint.pivot": ["world coordinates"],
    "rlenv.scene2d.camera.Camera": ["row 0", "pixels"],
    "rlenv.scene2d.render.draw_list": [],
    "rlenv.views.View": [],
    "rlenv.serving.server.Server": ["instances"],
    "rlenv_client.base.BaseClient.step": ["repeat_action"],
    "rlenv_client.client.Client": ["timeout", "shared_memory"],
    "rlenv_client.client.Client.shared_memory": ["shared-memory lane"],
    "rlenv_client.local.LocalClient": [],
    "rlenv_client.env.RemoteEnv": ["max_restarts"],
    "rlenv_client.vector.RemoteVectorEnv": ["autoreset"],
    "rlenv_client.launcher.ServerProcess": [],
    "rlenv.protocol.errors.RemoteError": [],
    "rlenv.protocol.errors.RequestTimeout": [],
    "rlenv.protocol.errors.ConnectionLost": [],
    "rlenv_client.sb3.SB3VecEnv": [],
    "rlenv_client.pettingzoo.RemoteParallelEnv": [],
    "rlenv_client.replay.RecordEpisodes": [],
    "rlenv_client.curriculum.sampler.LevelSampler": ["staleness", "robust"],
    "rlenv_client.curriculum.scores.learnability": ["p * (1 - p)"],
    "rlenv_tools.compliance.check_server": [],
}


def build(config: Path, site: Path) -> subprocess.CompletedProcess[str]:
    """``mkdocs build --strict`` of ``config`` into ``site``, in a subprocess."""
    if importlib.util.find_spec("mkdocs") is None:
        pytest.fail("mkdocs is not installed: `make docs` installs the docs extra")
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "--config-file",
            str(config),
            "--site-dir",
            str(site),
        ],
        cwd=config.parent,
        capture_output=True,
        text=True,
        timeout=BUILD_TIMEOUT,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    site = tmp_path_factory.mktemp("site")
    result = build(ROOT / "mkdocs.yml", site)
    output = result.stdout + result.stderr
    problems = [line for line in output.splitlines() if "WARNING" in line or "ERROR" in line]
    assert result.returncode == 0 and not problems, output
    return site


def inventory(site: Path) -> dict[str, str]:
    """The documented objects: identifier -> page (from the site's ``objects.inv``)."""
    data = (site / "objects.inv").read_bytes()
    lines = zlib.decompress(data.split(b"\n", 4)[4]).decode().splitlines()
    entries = {}
    for line in lines:
        name, _domain, _priority, uri, *_ = line.split(" ")
        entries[name] = uri.split("#", 1)[0]
    return entries


def entry_text(site: Path, page: str, identifier: str) -> str:
    """The text of ``identifier``'s entry on ``page``: from its heading to the next heading."""
    document = (site / page / "index.html").read_text(encoding="utf-8")
    start = document.index(f'id="{identifier}" class="doc doc-heading"')
    end = document.find('class="doc doc-heading"', start + len(identifier) + 30)
    text = re.sub(r"<[^>]+>", "", document[start : end if end > 0 else None])
    return html.unescape(re.sub(r"\s+", " ", text))


def test_the_site_builds_without_a_warning_and_has_every_page(site: Path) -> None:
    for page in (
        "index.html",
        "architecture/index.html",
        "protocol/index.html",
        "protocol/vectors/index.html",
        "reference/index.html",
        "changelog/index.html",
    ):
        assert (site / page).is_file(), page
    home = (site / "index.html").read_text(encoding="utf-8")
    assert "Writing an environment" in home  # the README is the home page
    changelog = (site / "changelog" / "index.html").read_text(encoding="utf-8")
    assert "Unreleased" in changelog and "Protocol 2.3" in changelog  # made from CHANGELOG.md
    assert 'href="changelog/"' in home  # the README's link to CHANGELOG.md leads to that page


@pytest.mark.parametrize("identifier", sorted(EXPECTED))
def test_the_reference_documents_what_users_touch(site: Path, identifier: str) -> None:
    pages = inventory(site)
    assert identifier in pages, f"{identifier} is not in the reference"
    text = entry_text(site, pages[identifier], identifier)
    for words in EXPECTED[identifier]:
        assert words in text, f"the entry of {identifier} does not say {words!r}: {text[:500]}"


def test_no_sphinx_role_is_left_as_text(site: Path) -> None:
    leaks = [
        str(page.relative_to(site))
        for page in site.rglob("*.html")
        if re.search(r":(class|meth|func|attr|mod|data|exc|obj):", page.read_text("utf-8"))
    ]
    assert leaks == []
    physics = (site / "reference" / "scene2d" / "index.html").read_text(encoding="utf-8")
    assert 'href="#rlenv.scene2d.physics.world.PhysicsWorld"' in physics  # roles became links


def test_a_reference_to_a_missing_name_fails_the_build(tmp_path: Path) -> None:
    package = tmp_path / "src" / "sample"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text(
        textwrap.dedent('''
        """A sample package."""


        def present() -> None:
            """Exists."""


        def caller() -> None:
            """Calls :func:`present`, then :func:`vanished`."""
    ''')
    )
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "index.md").write_text("# Sample\n\n::: sample\n")
    (tmp_path / "mkdocs.yml").write_text(
        textwrap.dedent(f"""
        site_name: sample
        plugins:
          - mkdocstrings:
              handlers:
                python:
                  paths: [src]
                  options:
                    extensions:
                      - {ROOT / "docs" / "hooks" / "sphinx_roles.py"}:SphinxRoles:
                          checked: [sample]
    """)
    )
    result = build(tmp_path / "mkdocs.yml", tmp_path / "site")
    output = result.stdout + result.stderr
    assert result.returncode != 0, output
    assert "'vanished', which does not exist" in output
    assert "'present'" not in output
