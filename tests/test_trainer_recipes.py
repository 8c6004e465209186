"""The recipes for other trainers (examples/recipes) and the matrix that runs them.

The libraries' own recipes run in venvs of their own (``make test-trainers``); here, what needs
none of them: the measure all recipes share, gymnasium's ``benchmark_step`` recipe end to end
(gymnasium is rlenv's own dependency), and ``.ci/test-trainers``' verdicts on a library pip
cannot install, a recipe that fails, and a recipe it does not know.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest
from gymnasium.utils import performance

ROOT = Path(__file__).resolve().parent.parent
RECIPES = ROOT / "examples" / "recipes"
MATRIX = ROOT / ".ci" / "test-trainers"

sys.path.insert(0, str(RECIPES))
import _turns  # noqa: E402


def test_a_contest_takes_turns_and_gives_the_ratio_round_by_round() -> None:
    order: list[str] = []

    def side(name: str, rates: list[float]) -> _turns.Measure:
        def measure() -> float:
            order.append(name)
            return rates.pop(0)

        return measure

    result = _turns.contest(
        "demo", side("rlenv", [1.0, 2.0, 3.0]), side("native", [4.0, 4.0, 6.0]), rounds=3
    )
    assert order == ["rlenv", "native", "native", "rlenv", "rlenv", "native"]
    assert result.ratios == [0.25, 0.5, 0.5]
    assert str(result) == (
        "demo: rlenv/CartPole-v1 min 1, median 2 steps/s; CartPole-v1 min 4, median 4 steps/s; "
        "ratio over 3 rounds in turns: min 0.250, median 0.500"
    )


def test_a_rate_counts_the_steps_of_whole_calls() -> None:
    calls = []

    def stepper() -> int:
        calls.append(1)
        return 10

    assert _turns.rate(stepper, 0.0) > 0 and len(calls) == 1  # at least one call, however short


def _checkout_environment(**extra: str) -> dict[str, str]:
    paths = [str(ROOT), str(ROOT / "client"), str(ROOT / "tools")]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(paths), **extra}


@pytest.mark.timeout(300)
def test_the_benchmark_step_recipe_measures_rlenv_against_native_cartpole() -> None:
    run = subprocess.run(
        [sys.executable, str(RECIPES / "benchmark_step_recipe.py"), "--smoke"],
        env=_checkout_environment(),
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    lines = run.stdout.splitlines()
    if not hasattr(performance, "benchmark_vector_step"):  # gymnasium < 1.3 (make test-lowest)
        assert lines[1:] == [
            f"gymnasium benchmark_vector_step: not in gymnasium {gym.__version__}, not run"
        ]
        lines = lines[:1]
    assert [line.split(":")[0] for line in lines] == [
        "gymnasium benchmark_step",
        "gymnasium benchmark_vector_step, make_vec(8) against CartPole-v1's CartPoleVectorEnv",
        "gymnasium benchmark_vector_step, make_vec(8) against CartPole-v1's SyncVectorEnv",
    ][: len(lines)]
    assert all("ratio over 2 rounds in turns: min " in line for line in lines)


def _matrix(venvs: Path, *recipes: str, **extra: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(MATRIX), str(venvs), *recipes],
        env={**os.environ, "PYTHON": sys.executable, **extra},
        capture_output=True,
        text=True,
        timeout=240,
    )


@pytest.mark.timeout(300)
def test_a_library_pip_cannot_install_is_not_run_with_pips_reason(tmp_path: Path) -> None:
    nothing = tmp_path / "no-wheels"
    nothing.mkdir()
    run = _matrix(
        tmp_path / "venvs",
        "benchmark-step",
        PIP_CONFIG_FILE=os.devnull,  # no index, no wheels on disk: nothing installs
        PIP_NO_INDEX="1",
        PIP_FIND_LINKS=str(nothing),
    )
    assert run.returncode == 0, run.stdout + run.stderr
    lines = run.stdout.splitlines()
    assert lines[0].startswith(
        "make test-trainers: benchmark-step: not run: cannot install it here: "
        "pip install -e .: ERROR: "
    ), lines
    assert lines[-1] == "trainers: 0 passed, 0 failed, 1 skipped"
    assert not (tmp_path / "venvs" / "recipes-benchmark-step" / ".installed").exists()


def test_a_recipe_that_fails_fails_the_matrix(tmp_path: Path) -> None:
    venv = tmp_path / "recipes-benchmark-step"
    (venv / "bin").mkdir(parents=True)
    failing = venv / "bin" / "python"
    failing.write_text("#!/bin/sh\nexit 3\n")
    failing.chmod(0o755)
    (venv / ".installed").write_text("-e .\n")  # the steps the matrix would take: made already
    run = _matrix(tmp_path, "benchmark-step")
    assert run.returncode == 1
    assert run.stdout.splitlines()[0].startswith(
        "make test-trainers: benchmark-step: FAILED (exit 3) after "
    )
    assert run.stdout.splitlines()[-1] == "trainers: 0 passed, 1 failed, 0 skipped"


def test_an_unknown_recipe_fails_the_matrix_naming_those_there_are(tmp_path: Path) -> None:
    run = _matrix(tmp_path, "tensorflow-agents")
    assert run.returncode == 1
    assert run.stdout.splitlines() == [
        "make test-trainers: no recipe tensorflow-agents (pufferlib, torchrl, sample-factory, "
        "benchmark-step)",
        "trainers: 0 passed, 1 failed, 0 skipped",
    ]
