"""The command line, the README's promises and the client's import footprint."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import Serve
from tool_runs import ROOT, rlenv

from rlenv_client import Client


def test_demo_balances_the_pole_and_prints_each_return() -> None:
    result = rlenv("demo", "--episodes", "2", "--max-seconds", "5")
    assert result.returncode == 0, result.stderr
    returns = re.findall(r"episode (\d): return (\d+)", result.stdout)
    assert [episode for episode, _ in returns] == ["1", "2"]
    assert all(int(value) == 300 for _, value in returns)  # 5 s at 60 ticks: never fell


def test_serve_refuses_a_bad_target_clearly() -> None:
    result = rlenv("serve", "examples.cartpole:Nothing")
    assert result.returncode != 0
    assert "module 'examples.cartpole' has no attribute 'Nothing'" in result.stderr
    result = rlenv("serve", "examples.cartpole")
    assert "expected MODULE:CLASS" in result.stderr


def test_serve_prints_where_it_listens(serve: Serve) -> None:
    server = serve()
    assert server.host == "127.0.0.1" and server.port > 0
    assert f"listening on {server.host}:{server.port}" in server.output


def test_the_client_imports_no_physics_no_server_and_no_ray() -> None:
    code = (
        "import sys, rlenv_client, rlenv_client.rllib; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('pymunk', 'examples', 'ray', 'torch') or m in ('rlenv.node', "
        "'rlenv.environment', 'rlenv.agent', 'rlenv.world', 'rlenv.rl_node', "
        "'rlenv.serving', 'rlenv.scene2d')))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    )
    assert result.stdout.strip() == "[]"


def test_the_readme_example_environment_serves(serve: Serve, tmp_path: Path) -> None:
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Writing an environment", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)  # type: ignore[union-attr]
    (tmp_path / "readme_push.py").write_text(code)
    from rlenv_client import ServerProcess

    with (
        ServerProcess("readme_push:PushEnvironment", env={"PYTHONPATH": str(tmp_path)}) as server,
        Client(server.host, server.port, timeout=10) as client,
    ):
        observation, _ = client.reset(seed=1)
        start = float(np.linalg.norm(observation))
        toward_centre = np.clip(-observation, -1, 1).astype(np.float32)
        observation, reward, _, _, info = client.step(toward_centre, repeat_action=8)
        assert info["frames"] <= 8 and reward < 0
        assert float(np.linalg.norm(observation)) < start


def test_check_reports_a_good_environment() -> None:
    result = rlenv("check", "examples.cartpole:CartPoleEnvironment", "--compliance")
    assert result.returncode == 0, result.stdout + result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("PASS  connect")
    assert any(line.startswith("PASS  gymnasium check_env") for line in lines)
    assert any(
        line.startswith("PASS  compliance under hostile input") and "0 failures" in line
        for line in lines
    )
    assert re.search(r"^\d+ passed, 0 failed$", lines[-1])


def test_check_fails_a_broken_environment(serve: Serve) -> None:
    server = serve("examples.faulty:WrongShapeEnvironment")
    result = rlenv("check", server.address)
    assert result.returncode == 1
    assert re.search(r"^FAIL  gymnasium check_env .*observation", result.stdout, re.M)
    assert re.search(r"^\d+ passed, [1-9]\d* failed$", result.stdout.splitlines()[-1])
    result = rlenv("check", "127.0.0.1:1")
    assert result.returncode == 1 and "FAIL  connect" in result.stdout


def test_bench_prints_every_figure_with_its_baseline(tmp_path: Path) -> None:
    out = tmp_path / "figures.json"
    result = rlenv(
        "bench", "--rounds", "1", "--steps", "40", "--quick", "--json", str(out), timeout=300
    )
    assert result.returncode == 0, result.stderr
    assert "... (a, b, c, g) ping-pong" in result.stderr  # progress on stderr
    figures = {figure["name"]: figure for figure in json.loads(out.read_text())}
    for name in (
        "msgpack ping-pong over loopback",
        "remote CartPole Client.step (repeat 4)",
        "remote 84x84x3 observation step",
        "gymnasium AsyncVectorEnv(8) CartPole-v1",
        "RemoteVectorEnv 64 envs, 2 servers x 32 (repeat 1, zero actions)",
        "make_vec('rlenv/CartPole-v0', 64) against the floor",
        "p99 remote step latency (repeat 4)",
        "one more CartPole instance in a process",
    ):
        assert name in figures and figures[name]["value"] > 0, name
        assert name in result.stdout
    step = figures["remote CartPole Client.step (repeat 4)"]
    assert step["ratio"] == pytest.approx(step["value"] / step["baseline"])
