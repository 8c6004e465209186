"""``rlenv check`` on multi-agent environments and unusual spaces, run as users run it.

Each test runs the command in a subprocess (``tests/`` on ``PYTHONPATH`` for the environments of
``tests/check_envs.py``) and reads its report; one reads it on a terminal (a pty), where the
statuses are coloured unless ``NO_COLOR`` is set.
"""

from __future__ import annotations

import importlib.util
import os
import pty
import re
import select
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from conftest import Serve

from rlenv_client import ServerProcess
from rlenv_tools.observations import observation_difference

TESTS = Path(__file__).parent
PAIR = "examples.pair:PairEnvironment"
TAG = "examples.tag:TagEnvironment"  # agents of two classes: spaces, max_force, rewards differ
HAS_PETTINGZOO = importlib.util.find_spec("pettingzoo") is not None
HAS_SB3 = importlib.util.find_spec("stable_baselines3") is not None


def _environ(**extra: str) -> dict[str, str]:
    """This process's environment, ``tests/`` on ``PYTHONPATH``, no ``NO_COLOR``, and ``extra``."""
    path = os.pathsep.join(filter(None, [str(TESTS), os.environ.get("PYTHONPATH")]))
    environ = {key: value for key, value in os.environ.items() if key != "NO_COLOR"}
    return {**environ, "PYTHONPATH": path, **extra}


def check(*args: str) -> subprocess.CompletedProcess[str]:
    """``rlenv check ARGS`` with its output on pipes."""
    return subprocess.run(
        [sys.executable, "-m", "rlenv", "check", *args],
        capture_output=True,
        text=True,
        timeout=300,
        stdin=subprocess.DEVNULL,
        env=_environ(),
    )


def line_of(output: str, name: str) -> str:
    """The report's line of the check called ``name``."""
    found = [line for line in output.splitlines() if line[6:].startswith(name)]
    assert len(found) == 1, f"no single line for {name!r} in:\n{output}"
    return found[0]


def test_the_pair_example_passes() -> None:
    result = check(PAIR)
    assert result.returncode == 0, result.stdout + result.stderr
    for name in (
        "gymnasium check_env",
        "seeded reset is reproducible",
        "step returns gymnasium types",
        "a bad action is refused and changes nothing",
    ):
        assert line_of(result.stdout, name).startswith("PASS  "), result.stdout
    sb3 = line_of(result.stdout, "stable-baselines3 check_env")
    assert sb3.startswith("SKIP  ") and "the action space is a Dict" in sb3
    assert "with several agents, train one agent or a team" in sb3
    pettingzoo = line_of(result.stdout, "pettingzoo parallel_api_test")
    if HAS_PETTINGZOO:
        assert pettingzoo.startswith("PASS  ") and "agents Red, Blue" in pettingzoo
    else:
        assert pettingzoo.startswith("SKIP  ") and "not installed" in pettingzoo
    assert "Passed Parallel API test" not in result.stdout  # PettingZoo's own print
    assert "\x1b" not in result.stdout
    assert re.search(r"^\d+ passed, 0 failed$", result.stdout.splitlines()[-1])


def test_a_served_pair_passes_with_compliance(serve: Serve) -> None:
    server = serve(PAIR)
    result = check(server.address, "--compliance")
    assert result.returncode == 0, result.stdout + result.stderr
    compliance = line_of(result.stdout, "compliance under hostile input")
    assert compliance.startswith("PASS  ") and " 0 failures" in compliance
    assert line_of(result.stdout, "seeded reset is reproducible").startswith("PASS  ")
    if HAS_PETTINGZOO:  # its own client, after the checks' client released control
        assert line_of(result.stdout, "pettingzoo parallel_api_test").startswith("PASS  ")


def test_a_served_pair_with_a_token_passes_every_check() -> None:
    """The token reaches every client of the checks: the environment's and PettingZoo's."""
    token = "pair-secret-0123456789"
    environ = _environ()
    with ServerProcess(PAIR, args=["--token", token]) as server:
        result = subprocess.run(
            [sys.executable, "-m", "rlenv", "check", server.address, "--token", token],
            capture_output=True,
            text=True,
            timeout=300,
            stdin=subprocess.DEVNULL,
            env={key: value for key, value in environ.items() if key != "RLENV_TOKEN"},
        )
    assert result.returncode == 0, result.stdout + result.stderr
    if HAS_PETTINGZOO:
        assert line_of(result.stdout, "pettingzoo parallel_api_test").startswith("PASS  ")


def test_agents_of_different_classes_pass() -> None:
    result = check(TAG)
    assert result.returncode == 0, result.stdout + result.stderr
    assert line_of(result.stdout, "seeded reset is reproducible").startswith("PASS  ")
    if HAS_PETTINGZOO:
        assert "agents Chaser, Runner1, Runner2" in line_of(
            result.stdout, "pettingzoo parallel_api_test"
        )


def test_a_served_tag_passes_with_compliance(serve: Serve) -> None:
    server = serve(TAG)
    result = check(server.address, "--compliance")
    assert result.returncode == 0, result.stdout + result.stderr
    assert " 0 failures" in line_of(result.stdout, "compliance under hostile input")


def test_observations_are_compared_member_by_member() -> None:
    """A Dict observation differing in one agent's member, a Tuple one that does not."""
    drifting = check("check_envs:DriftingPairEnvironment")
    assert drifting.returncode == 1
    reset = line_of(drifting.stdout, "seeded reset is reproducible")
    assert reset.startswith("FAIL  ") and "at ['Blue']: [" in reset, reset
    assert "ambiguous" not in drifting.stdout
    assert line_of(drifting.stdout, "a bad action is refused and changes nothing").startswith(
        "PASS  "
    )
    tuple_env = check("check_envs:TupleEnvironment")
    assert tuple_env.returncode == 0, tuple_env.stdout + tuple_env.stderr
    assert line_of(tuple_env.stdout, "seeded reset is reproducible").startswith("PASS  ")
    sb3 = line_of(tuple_env.stdout, "stable-baselines3 check_env")
    assert sb3.startswith("SKIP  ") and "the observation space is a Tuple" in sb3
    assert "several agents" not in sb3


def test_sb3_s_check_runs_where_sb3_can_train() -> None:
    result = check("examples.cartpole:CartPoleEnvironment")
    sb3 = line_of(result.stdout, "stable-baselines3 check_env")
    assert sb3.startswith("PASS  " if HAS_SB3 else "SKIP  "), sb3
    if not HAS_SB3:
        assert "not installed" in sb3


def _on_a_terminal(*args: str, **environ: str) -> str:
    """``rlenv check ARGS``'s standard output, written to a terminal (a pty)."""
    leader, follower = pty.openpty()
    try:
        process = subprocess.Popen(
            [sys.executable, "-m", "rlenv", "check", *args],
            stdout=follower,
            stderr=subprocess.DEVNULL,
            stdin=subprocess.DEVNULL,
            env=_environ(**environ),
        )
    finally:
        os.close(follower)
    chunks = []
    deadline = time.monotonic() + 300
    try:
        while time.monotonic() < deadline:
            if not select.select([leader], [], [], 1.0)[0]:
                continue
            try:
                data = os.read(leader, 65536)
            except OSError:  # the other end closed: the command ended
                break
            if not data:
                break
            chunks.append(data)
        assert process.wait(timeout=60) == 0
    finally:
        process.kill()
        process.wait()
        os.close(leader)
    return b"".join(chunks).decode()


def test_colour_codes_only_on_a_terminal_and_never_with_no_color() -> None:
    target = "check_envs:TupleEnvironment"  # gymnasium's checker warns about it, in colour
    piped = check(target).stdout
    assert "WARN: For Box action spaces" in line_of(piped, "gymnasium check_env")
    assert "\x1b" not in piped
    coloured = _on_a_terminal(target)
    assert "\x1b[32mPASS \x1b[0m connect" in coloured and "\x1b[33mSKIP " in coloured
    assert "WARN: For Box action spaces" in coloured  # its own colour codes removed
    assert coloured.count("\x1b") == 2 * coloured.count("\x1b[0m")
    plain = _on_a_terminal(target, NO_COLOR="1")
    assert "PASS  connect" in plain and "\x1b" not in plain


def test_observation_difference_names_the_member() -> None:
    """The one comparison of the checks: maps and tuples member by member, arrays by bits."""
    one = {"Red": np.array([1.0, 2.0], np.float32), "Blue": (3, np.zeros((2, 2)))}
    assert (
        observation_difference(one, {"Red": one["Red"].copy(), "Blue": (3, np.zeros((2, 2)))})
        is None
    )
    assert (
        observation_difference(one, {**one, "Blue": (4, np.zeros((2, 2)))}) == "['Blue'][0]: 3 != 4"
    )
    assert observation_difference(one, {"Red": one["Red"]}).startswith("the observation: keys")
    assert observation_difference(np.float32(np.nan), np.float32(np.nan)) is None
    assert observation_difference(np.zeros(2), -np.zeros(2)) is not None  # bits differ
    assert observation_difference(np.zeros(2, np.float32), np.zeros(2)) is not None  # dtype
