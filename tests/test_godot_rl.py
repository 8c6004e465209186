"""Godot RL Agents' own SB3 example, unmodified, trains rlenv environments (make test-godot-rl).

godot-rl pins gymnasium <= 1.0.0, so it lives in a venv of its own: ``GODOT_RL_PYTHON`` is that
venv's Python and ``GODOT_RL_EXAMPLE`` the example script (``examples/stable_baselines3_example.py``
of godot_rl_agents at the Makefile's pinned commit). rlenv runs beside it, from this venv, as
``rlenv godot-rl``. The trainer listens on godot-rl's fixed ports (11008, and 11009 for a second
process), which the example has no flag to change.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

pytestmark = pytest.mark.godot_rl

ROOT = Path(__file__).resolve().parent.parent
GODOT_PYTHON = os.environ.get("GODOT_RL_PYTHON")
EXAMPLE = os.environ.get("GODOT_RL_EXAMPLE")
BUDGET = 300_000
"""The example's ``--timesteps`` for CartPole: its default is 1,000,000."""
_EP_LEN = re.compile(r"\|\s+ep_len_mean\s+\|\s+([0-9.e+]+)")

if GODOT_PYTHON is None or EXAMPLE is None:
    pytest.skip(
        "set GODOT_RL_PYTHON and GODOT_RL_EXAMPLE (make test-godot-rl does)",
        allow_module_level=True,
    )


def _free(port: int) -> bool:
    with socket.socket() as probe:
        return probe.connect_ex(("127.0.0.1", port)) != 0


@pytest.fixture(autouse=True)
def godot_rls_ports() -> None:
    busy = [port for port in (11008, 11009) if not _free(port)]
    if busy:
        pytest.fail(f"godot-rl's ports {busy} are in use: its example cannot listen there")


def _rlenv_environment() -> dict[str, str]:
    paths = [str(ROOT), str(ROOT / "client"), str(ROOT / "tools")]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(paths), "OMP_NUM_THREADS": "1"}


class Processes:
    """Processes started by a test, ended after it (their groups: a launcher's server too)."""

    def __init__(self) -> None:
        self.started: list[subprocess.Popen[str]] = []

    def start(self, command: list[str], cwd: Path, env: dict[str, str]) -> subprocess.Popen[str]:
        process = subprocess.Popen(
            command,
            cwd=cwd,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,
        )
        self.started.append(process)
        return process

    def end(self) -> None:
        for process in self.started:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
            process.communicate()


@pytest.fixture
def processes() -> Iterator[Processes]:
    started = Processes()
    yield started
    started.end()


def _example(processes: Processes, cwd: Path, *args: str) -> subprocess.Popen[str]:
    """godot-rl's SB3 example, unmodified, in godot-rl's venv, without rlenv's PYTHONPATH."""
    environment = {
        key: value for key, value in os.environ.items() if key not in ("PYTHONPATH", "VIRTUAL_ENV")
    }
    environment["OMP_NUM_THREADS"] = "1"
    assert GODOT_PYTHON is not None and EXAMPLE is not None
    return processes.start([GODOT_PYTHON, EXAMPLE, *args], cwd, environment)


def _train_until(example: subprocess.Popen[str], length: float) -> tuple[list[float], str]:
    """The example's ``ep_len_mean`` rows until one reaches ``length`` (then Ctrl-C: the example
    saves and closes its environments) or the run ends; and the end of its output."""
    assert example.stdout is not None
    lengths: list[float] = []
    output: list[str] = []
    for line in example.stdout:
        output = [*output[-40:], line]
        found = _EP_LEN.search(line)
        if found:
            lengths.append(float(found.group(1)))
            if lengths[-1] >= length:
                example.send_signal(signal.SIGINT)
                break
    rest, _ = example.communicate(timeout=120)
    return lengths, "".join(output) + rest[-3000:]


@pytest.mark.timeout(900)  # training: about 2 minutes on an idle machine of 2 cores
def test_the_sb3_example_trains_cartpole_through_the_launcher_with_n_parallel(
    processes: Processes, tmp_path: Path
) -> None:
    launcher = tmp_path / "CartPole.x86_64"
    subprocess.run(
        [sys.executable, "-m", "rlenv", "godot-rl", "rlenv/CartPole-v1", "--instances", "8"]
        + ["--launcher", str(launcher)],
        env=_rlenv_environment(),
        check=True,
        timeout=60,
    )
    example = _example(
        processes,
        tmp_path,
        "--env_path",
        str(launcher),
        "--n_parallel",
        "2",
        "--timesteps",
        str(BUDGET),
    )
    lengths, output = _train_until(example, 400.0)
    assert lengths and max(lengths) >= 400.0, f"ep_len_mean over training: {lengths}\n{output}"
    assert example.returncode in (0, -signal.SIGINT)


@pytest.mark.timeout(400)
def test_the_sb3_example_plays_pair_two_agents_per_instance(
    processes: Processes, tmp_path: Path
) -> None:
    game = processes.start(
        [sys.executable, "-m", "rlenv", "godot-rl", "rlenv/Pair-v0", "--instances", "2"],
        tmp_path,
        _rlenv_environment(),
    )
    example = _example(processes, tmp_path, "--timesteps", "3000")
    output, _ = example.communicate(timeout=300)
    assert example.returncode == 0, output[-3000:]
    declared = next(line for line in output.splitlines() if line.startswith("action space"))
    assert declared.count("'continuous'") == 4  # 2 instances of 2 agents: 4 AIControllers
    steps = [int(n) for n in re.findall(r"total_timesteps\s+\|\s+(\d+)", output)]
    assert steps and steps[-1] >= 3000, output[-3000:]
    assert game.wait(timeout=60) == 0  # the example's close ends the game
