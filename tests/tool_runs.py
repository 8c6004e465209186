"""What the tools' tests share: ``rlenv ARGS`` in a subprocess, ``rlenv check``'s report, and
one recorded episode with what its client saw."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rlenv_client.env import RemoteEnv
from rlenv_client.replay import RecordEpisodes

ROOT = Path(__file__).parent.parent


def rlenv(*args: str, timeout: float = 400) -> subprocess.CompletedProcess[str]:
    """``rlenv ARGS`` in a subprocess, from the checkout's root (its tests package importable)."""
    return subprocess.run(
        [sys.executable, "-m", "rlenv", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        stdin=subprocess.DEVNULL,
        cwd=ROOT,
        env={
            **os.environ,
            "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
        },
    )


def assert_replays_bit_for_bit(path: Path) -> None:
    """``rlenv replay PATH --trust-target`` finds every observation, reward and flag identical."""
    result = rlenv("replay", str(path), "--trust-target")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "every observation identical, every reward and flag too" in result.stdout


def report_lines(output: str) -> dict[str, str]:
    """``rlenv check``'s report: each check's name to its status (PASS, FAIL, SKIP)."""
    lines = {}
    for line in output.splitlines():
        status, _, rest = line.partition("  ")
        if status in ("PASS", "FAIL", "SKIP"):
            lines[rest.strip().split("  ")[0]] = status
    return lines


@dataclass
class Seen:
    """What the recording client saw: each answer's observation and ``info["agents"]``."""

    observations: list[dict[str, Any]] = field(default_factory=list)
    agents: list[dict[str, Any]] = field(default_factory=list)
    actions: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class Recorded:
    """A recording's file and what its client saw."""

    path: Path
    seen: Seen


def answered(observation: Any, info: dict[str, Any]) -> Any:
    """The answer's agents of RemoteEnv's observation (its slots of the others are zeros; the
    agents the server drives are not in it)."""
    if "due" not in info:
        return observation
    return {name: observation[name] for name in info["agents"] if name in observation}


def record_one(
    target: str,
    directory: Path,
    policy: Callable[[Any], Any],
    steps: int | None,
    seed: int,
    server_args: Sequence[str] = (),
) -> Seen:
    """Record one episode of ``target`` played by ``policy``, at most ``steps`` steps if given
    (a client's time limit), on a server started with ``server_args`` (say, agents it drives)."""
    env = RecordEpisodes(
        RemoteEnv(
            target,
            max_restarts=0,
            share_server=False,
            max_episode_steps=steps,
            server_args=server_args,
        ),
        directory,
    )
    seen = Seen()
    try:
        observation, info = env.reset(seed=seed)
        seen.observations.append(answered(observation, info))
        seen.agents.append(info.get("agents", {}))
        while True:
            action = policy(answered(observation, info))
            observation, _, terminated, truncated, info = env.step(action)
            seen.actions.append(action)
            seen.observations.append(answered(observation, info))
            seen.agents.append(info.get("agents", {}))
            if terminated or truncated:
                return seen
    finally:
        env.close()
