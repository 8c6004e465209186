"""rlenv as a library others depend on: what the distribution installs, its license, its
changelog, its one version, and the two names of the examples (building and installing the
wheel is make test-package's: .ci/test-package)."""

from __future__ import annotations

import importlib.metadata
import os
import re
import sys
import tomllib
from pathlib import Path

import pytest

import rlenv
import rlenv_client
from rlenv import targets
from rlenv.protocol import PROTOCOL_VERSION
from rlenv.serving._instance import load_environment
from rlenv_client.registration import ENVIRONMENTS

ROOT = Path(__file__).resolve().parent.parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
SETUPTOOLS = PYPROJECT["tool"]["setuptools"]


def _folders(package: str, folder: Path) -> set[str]:
    """Every package under ``folder`` (a folder with an ``__init__.py``), named from ``package``."""
    return {
        ".".join([package, *init.parent.relative_to(folder).parts])
        for init in folder.rglob("__init__.py")
        if "__pycache__" not in init.parts
    }


def test_the_distribution_installs_one_package_a_layer_at_the_top() -> None:
    packages = SETUPTOOLS["packages"]
    assert {package.split(".")[0] for package in packages} == {
        "rlenv",
        "rlenv_client",
        "rlenv_tools",
    }
    assert SETUPTOOLS["package-dir"] == {
        "rlenv": "rlenv",
        "rlenv.examples": "examples",
        "rlenv_client": "client/rlenv_client",
        "rlenv_tools": "tools/rlenv_tools",
    }
    assert PYPROJECT["project"]["scripts"] == {"rlenv": "rlenv_tools.cli:main"}
    assert "examples" in PYPROJECT["tool"]["ruff"]["lint"]["isort"]["known-first-party"]


def test_every_package_folder_is_listed_and_the_examples_are_rlenv_examples() -> None:
    folders = (
        _folders("rlenv", ROOT / "rlenv")
        | _folders("rlenv.examples", ROOT / "examples")
        | _folders("rlenv_client", ROOT / "client" / "rlenv_client")
        | _folders("rlenv_tools", ROOT / "tools" / "rlenv_tools")
    )
    pages = {"rlenv_tools.inspector.static"}  # the inspector's page: files, no __init__.py
    assert set(SETUPTOOLS["packages"]) == folders | pages
    examples = {
        path.name for path in (ROOT / "examples").iterdir() if (path / "__init__.py").is_file()
    }
    assert {"cartpole", "classic_cartpole", "maze", "plinko"} <= examples
    assert {f"rlenv.examples.{name}" for name in examples} <= set(SETUPTOOLS["packages"])


def test_the_license_is_mit_and_goes_into_the_distributions() -> None:
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("MIT License\n")
    assert "Copyright (c) 2026 The rlenv contributors" in text
    assert 'THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND' in text
    assert PYPROJECT["project"]["license"] == "MIT"
    assert PYPROJECT["project"]["license-files"] == ["LICENSE"]


def test_the_version_has_one_place() -> None:
    project = PYPROJECT["project"]
    assert "version" not in project and project["dynamic"] == ["version"]
    assert SETUPTOOLS["dynamic"]["version"] == {"attr": "rlenv.__version__"}
    assert re.fullmatch(r"\d+\.\d+\.\d+", rlenv.__version__)
    assert rlenv_client.__version__ == rlenv.__version__
    sources = [
        path
        for folder in ("rlenv", "client", "tools", "examples")
        for path in (ROOT / folder).rglob("*.py")
    ]
    literals = [
        path
        for path in sources
        if re.search(r"^__version__ = ['\"]", path.read_text(encoding="utf-8"), re.M)
    ]
    assert literals == [ROOT / "rlenv" / "__init__.py"]


def test_the_version_is_the_installed_metadata() -> None:
    assert rlenv.__version__ == importlib.metadata.version("rlenv")


def test_the_changelog_keeps_a_changelog_with_the_protocol_versions() -> None:
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    headings = re.findall(r"^## \[([^]]+)\]", text, re.M)
    assert headings[0] == "Unreleased" and rlenv.__version__ in headings
    assert "https://keepachangelog.com/en/1.1.0/" in text
    kinds = set(re.findall(r"^### (.+)$", text, re.M))
    assert kinds <= {"Added", "Changed", "Deprecated", "Removed", "Fixed", "Security"}
    major, minor = PROTOCOL_VERSION
    for version in [f"{major}.{number}" for number in range(minor + 1)]:
        assert re.search(rf"\*\*Protocol {re.escape(version)}\*\* \(\d{{4}}-\d\d-\d\d\)", text), (
            version
        )
    assert "(CHANGELOG.md)" in (ROOT / "README.md").read_text(encoding="utf-8")
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    assert "- Changelog: changelog.md" in nav


def test_ci_builds_checks_and_installs_the_wheel() -> None:
    script = ROOT / ".ci" / "test-package"
    assert os.access(script, os.X_OK)
    assert "make test-package" in (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert re.search(r"^test-package: ", (ROOT / "Makefile").read_text(encoding="utf-8"), re.M)
    text = script.read_text(encoding="utf-8")
    for step in (
        "-m build",
        "twine check",
        "-m venv",
        "demo",
        " check rlenv.examples.",
        'gym.make("rlenv/CartPole-v1")',
        " http --port 0",
    ):
        assert step in text, step
    release = PYPROJECT["project"]["optional-dependencies"]["release"]
    assert all(re.fullmatch(r"(build|twine)>=[0-9.]+,<=[0-9.]+", pin) for pin in release)


def test_ci_type_checks_the_runtime_and_the_client_without_silencing_errors() -> None:
    assert re.search(r"^make typecheck$", (ROOT / ".ci" / "run").read_text(encoding="utf-8"), re.M)
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    assert re.search(r"^typecheck: .*\n.*\[test,typecheck\].*\n\t\$\(BIN\)/mypy$", makefile, re.M)
    assert not re.search(r"^test: .*typecheck", makefile, re.M)  # make test does without it
    mypy = PYPROJECT["tool"]["mypy"]
    assert mypy["files"] == ["rlenv", "client/rlenv_client"] and mypy["warn_unused_ignores"]
    assert not {"disable_error_code", "ignore_errors", "ignore_missing_imports"} & set(mypy)
    for override in mypy["overrides"]:  # only named libraries' missing types, nothing of ours
        assert set(override) == {"module", "ignore_missing_imports"}, override
        assert not [name for name in override["module"] if name.startswith("rlenv")]
    assert all(
        re.fullmatch(r"[a-zA-Z-]+>=[0-9.]+(,<=[0-9.]+)?", pin)
        for pin in PYPROJECT["project"]["optional-dependencies"]["typecheck"]
    )


# The examples' two names, in this checkout: one module per example in a process.


def test_registered_ids_name_the_installed_examples() -> None:
    for registration in ENVIRONMENTS.values():
        assert registration.target.startswith("rlenv.examples."), registration.target


def test_in_a_checkout_either_name_loads_the_checkouts_module() -> None:
    assert targets.module_name("rlenv.examples.cartpole") == "examples.cartpole"
    assert targets.module_name("examples.cartpole") == "examples.cartpole"
    assert targets.module_name("mypackage.env") == "mypackage.env"
    for env_id, registration in ENVIRONMENTS.items():
        loaded = load_environment(registration.target)
        module = sys.modules[loaded.__module__]
        assert loaded.__module__.startswith("examples."), env_id
        assert Path(module.__file__).is_relative_to(ROOT / "examples")
        checkout = registration.target.replace("rlenv.examples.", "examples.", 1)
        assert load_environment(checkout) is loaded
    assert not [name for name in sys.modules if name.startswith("rlenv.examples")]


def test_the_examples_name_their_target_by_the_name_they_were_loaded_under() -> None:
    from examples import cartpole, classic_cartpole, faulty  # noqa: F401

    assert cartpole.TARGET == "examples.cartpole:CartPoleEnvironment"
    assert classic_cartpole.CartPoleWorld is cartpole.CartPoleWorld  # a relative import


def test_elsewhere_the_installed_name_is_kept_and_checkout_names_fall_back(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    installed = tmp_path / "site-packages" / "rlenv"
    (installed / "examples").mkdir(parents=True)
    monkeypatch.setattr(targets, "_RLENV_DIR", installed)  # as an installed rlenv is laid out
    before = set(sys.modules)
    try:
        assert targets.module_name("rlenv.examples.cartpole") == "rlenv.examples.cartpole"
        # Here rlenv.examples is this checkout's folder if its editable install maps it, else it
        # does not import and the checkout's examples does: the same file either way.
        module = targets.import_module("rlenv.examples.cartpole")
        assert Path(module.__file__) == ROOT / "examples" / "cartpole" / "__init__.py"
    finally:
        for name in set(sys.modules) - before:
            if name.startswith("rlenv.examples"):
                del sys.modules[name]
    with pytest.raises(ModuleNotFoundError) as missing:
        targets.import_module("examples.no_such_example")
    assert missing.value.name == "examples.no_such_example"  # the error for the name asked


def test_an_example_missing_its_own_imports_is_not_taken_for_a_missing_example(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    import examples

    (tmp_path / "needs_more.py").write_text("import no_such_library_anywhere\n", encoding="utf-8")
    monkeypatch.setattr(examples, "__path__", [*examples.__path__, str(tmp_path)])
    with pytest.raises(ModuleNotFoundError) as missing:
        targets.import_module("rlenv.examples.needs_more")
    assert missing.value.name == "no_such_library_anywhere"  # said as it is, no fallback


def test_targets_compare_across_the_two_names() -> None:
    assert targets.same_target(
        "examples.cartpole:CartPoleEnvironment", "rlenv.examples.cartpole:CartPoleEnvironment"
    )
    assert targets.same_target(
        "rlenv.examples.maze:MazeEnvironment", "rlenv.examples.maze:MazeEnvironment"
    )
    assert not targets.same_target(
        "examples.cartpole:CartPoleEnvironment", "examples.cartpole:Other"
    )
    assert not targets.same_target(
        "myexamples.cartpole:CartPoleEnvironment", "rlenv.examples.cartpole:CartPoleEnvironment"
    )
