"""The versions rlenv allows are those it was tested with (pyproject.toml, .ci/lowest.txt)."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from packaging.version import Version

ROOT = Path(__file__).resolve().parent.parent
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
REQUIREMENT = re.compile(r"^(?P<name>[A-Za-z0-9_.-]+)(?:\[[^]]*\])?(?P<spec>[^;]*)")


def _specs(requirements: list[str]) -> dict[str, str]:
    found = {}
    for requirement in requirements:
        match = REQUIREMENT.match(requirement.replace(" ", ""))
        assert match, requirement
        found[match["name"].lower()] = match["spec"]
    return found


def _lowest() -> dict[str, str]:
    lines = (ROOT / ".ci" / "lowest.txt").read_text(encoding="utf-8").splitlines()
    pins = [line.split("==") for line in lines if line and not line.startswith("#")]
    return {name.lower(): Version(version) for name, version in pins}


def test_ci_tests_the_lowest_version_of_everything_rlenv_imports() -> None:
    imported = {
        **_specs(PROJECT["dependencies"]),
        **_specs(PROJECT["optional-dependencies"]["http"]),
    }
    floors = {name: Version(re.search(r">=([0-9.]+)", spec)[1]) for name, spec in imported.items()}
    assert _lowest() == floors


def test_the_libraries_whose_internals_rlenv_uses_are_capped_at_a_tested_version() -> None:
    allowed = {
        **_specs(PROJECT["dependencies"]),
        **_specs(PROJECT["optional-dependencies"]["http"]),
        **_specs(PROJECT["optional-dependencies"]["test"]),
    }
    for name in ("pymunk", "uvicorn", "starlette"):
        assert re.search(r"<=[0-9.]+", allowed[name]), (name, allowed[name])
