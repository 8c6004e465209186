"""A server per sub-env, a shared server, and ``make_vec``: ``python benchmarks/server_per_env.py``.

A trainer that builds its own ``gymnasium.vector.SyncVectorEnv`` of rlenv envs (CleanRL does:
``SyncVectorEnv([make_env(...) for i in range(num_envs)])``, each ``gym.make(env_id)``) steps
them one after another, a round trip each. Its ``gym.make`` envs share one ``rlenv serve
--per-client`` subprocess (``rlenv_client.sharing``); with ``share_server=False`` each starts a
server of its own. ``gymnasium.make_vec(env_id, num_envs=N)`` starts one server per core, each
hosting its share of the N sub-envs, and steps them all with one request per server.

For each N, three layouts are built, reset, stepped with the same random actions and closed,
their rounds taking turns (this machine's speed drifts; only same-run ratios mean anything):

- ``native``: ``SyncVectorEnv`` of N ``gym.make("CartPole-v1")``, the script before the change;
- ``gym.make``: ``SyncVectorEnv`` of N ``gym.make("rlenv/CartPole-v1")``: one shared server;
- ``per-env``: the same with ``share_server=False``: N servers;
- ``make_vec``: ``gym.make_vec("rlenv/CartPole-v1", num_envs=N)``: one server per core.

Figures: start-up (construction and the first seeded reset), env-steps per second, and the
memory of each server (RSS, and USS: the pages no other process shares, what one more server
really costs), min and median over the rounds.

Then where a server's start-up goes, in turns: a bare interpreter, the imports every server
needs (numpy, gymnasium, pymunk, msgpack), and ``python -m rlenv serve`` until it prints its
address, with Python's bytecode cache and without it (``PYTHONDONTWRITEBYTECODE=1``: every
server then compiles rlenv's modules again).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from procfs import memory_kib

import rlenv_client  # noqa: F401  (registers rlenv/CartPole-v1)
from rlenv.examples.classic_cartpole import TARGET
from rlenv_client.launcher import end_process

ENV_ID = "rlenv/CartPole-v1"


def native(num_envs: int) -> gym.vector.VectorEnv:
    return gym.vector.SyncVectorEnv([lambda: gym.make("CartPole-v1")] * num_envs)


def shared(num_envs: int) -> gym.vector.VectorEnv:
    return gym.vector.SyncVectorEnv([lambda: gym.make(ENV_ID)] * num_envs)


def per_env(num_envs: int) -> gym.vector.VectorEnv:
    return gym.vector.SyncVectorEnv([lambda: gym.make(ENV_ID, share_server=False)] * num_envs)


def make_vec(num_envs: int) -> gym.vector.VectorEnv:
    return gym.make_vec(ENV_ID, num_envs=num_envs)


LAYOUTS: dict[str, Callable[[int], gym.vector.VectorEnv]] = {
    "native": native,
    "gym.make": shared,
    "per-env": per_env,
    "make_vec": make_vec,
}


def server_pids(envs: gym.vector.VectorEnv) -> list[int]:
    """The pids of the servers behind ``envs`` (none for native envs)."""
    if isinstance(envs, gym.vector.SyncVectorEnv):
        servers = [getattr(env.unwrapped, "server", None) for env in envs.envs]
    else:
        servers = list(envs.unwrapped.servers)
    return sorted({server.pid for server in servers if server is not None})


def one_round(layout: str, num_envs: int, actions: np.ndarray) -> dict[str, Any]:
    """Build, reset, step and close ``layout`` once; its figures."""
    start = time.perf_counter()
    envs = LAYOUTS[layout](num_envs)
    try:
        envs.reset(seed=0)
        started = time.perf_counter() - start
        pids = server_pids(envs)
        memory = [memory_kib(pid) for pid in pids]
        start = time.perf_counter()
        for action in actions:
            envs.step(action)
        rate = actions.size / (time.perf_counter() - start)
    finally:
        envs.close()
    return {
        "start": started,
        "rate": rate,
        "servers": len(pids),
        "rss": [rss for rss, _ in memory],
        "uss": [uss for _, uss in memory],
    }


def environment_variables(bytecode: bool) -> dict[str, str]:
    """This process's environment, with or without Python's bytecode cache."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    if not bytecode:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


def run_python(args: list[str], bytecode: bool = True) -> float:
    """Seconds until ``python ARGS`` exits."""
    start = time.perf_counter()
    subprocess.run([sys.executable, *args], check=True, env=environment_variables(bytecode))
    return time.perf_counter() - start


def serve_until_listening(bytecode: bool) -> float:
    """Seconds from starting ``python -m rlenv serve`` to its ``listening on`` line."""
    start = time.perf_counter()
    process = subprocess.Popen(
        [sys.executable, "-m", "rlenv", "serve", TARGET, "--port", "0"],
        stdout=subprocess.PIPE,
        text=True,
        env=environment_variables(bytecode),
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        assert line.startswith("listening on "), line
        return time.perf_counter() - start
    finally:
        end_process(process, None)


STARTUP_PHASES: dict[str, Callable[[], float]] = {
    "python -c pass": lambda: run_python(["-c", "pass"]),
    "import numpy, gymnasium, pymunk, msgpack": lambda: run_python(
        ["-c", "import numpy, gymnasium, pymunk, msgpack"]
    ),
    "rlenv serve until listening": lambda: serve_until_listening(True),
    "the same, PYTHONDONTWRITEBYTECODE=1": lambda: serve_until_listening(False),
}


def spread(values: list[float], scale: float = 1.0, digits: int = 0) -> str:
    return f"{min(values) * scale:,.{digits}f} / {statistics.median(values) * scale:,.{digits}f}"


def ratios(results: dict[str, list[dict[str, Any]]], key: str, of: str, over: str) -> str:
    """Min / median over the rounds of ``of``'s figure over ``over``'s, round by round."""
    values = [a[key] / b[key] for a, b in zip(results[of], results[over], strict=True)]
    return spread(values, digits=2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument(
        "--env-steps", type=int, default=8000, help="environment steps per round (default 8000)"
    )
    parser.add_argument("--num-envs", type=int, nargs="+", default=[4, 16])
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(
        f"{os.cpu_count()} cores; PYTHONDONTWRITEBYTECODE="
        f"{os.environ.get('PYTHONDONTWRITEBYTECODE', '(unset)')} here (servers inherit it)"
    )
    for num_envs in args.num_envs:
        actions = rng.integers(0, 2, (args.env_steps // num_envs, num_envs))
        results: dict[str, list[dict[str, Any]]] = {layout: [] for layout in LAYOUTS}
        for layout in LAYOUTS:  # warm-up: caches, first compilation
            one_round(layout, num_envs, actions[:50])
        for _ in range(args.rounds):
            for layout in LAYOUTS:
                results[layout].append(one_round(layout, num_envs, actions))
        print(f"\nnum_envs={num_envs}, {args.rounds} rounds in turns, min / median")
        print(
            f"{'layout':10} {'servers':>7} {'start-up (ms)':>15} {'env-steps/s':>17} "
            f"{'RSS/server (MiB)':>17} {'USS/server (MiB)':>17}"
        )
        for layout, rounds in results.items():
            servers = rounds[0]["servers"]
            rss = [statistics.mean(r["rss"]) / 1024 for r in rounds] if servers else [0.0]
            uss = [statistics.mean(r["uss"]) / 1024 for r in rounds] if servers else [0.0]
            print(
                f"{layout:10} {servers:>7} {spread([r['start'] for r in rounds], 1000):>15} "
                f"{spread([r['rate'] for r in rounds]):>17} {spread(rss, digits=1):>17} "
                f"{spread(uss, digits=1):>17}"
            )

        print(
            f"gym.make (shared) against per-env, per round: start-up "
            f"{ratios(results, 'start', 'gym.make', 'per-env')}x, env-steps/s "
            f"{ratios(results, 'rate', 'gym.make', 'per-env')}x"
        )
        print(
            f"per-env against make_vec, per round: start-up "
            f"{ratios(results, 'start', 'per-env', 'make_vec')}x, env-steps/s "
            f"{ratios(results, 'rate', 'per-env', 'make_vec')}x"
        )
        print(
            f"against native CartPole-v1: gym.make env-steps/s "
            f"{ratios(results, 'rate', 'gym.make', 'native')}x, per-env "
            f"{ratios(results, 'rate', 'per-env', 'native')}x, make_vec "
            f"{ratios(results, 'rate', 'make_vec', 'native')}x"
        )
    print(f"\nwhere a server's start-up goes ({args.rounds} rounds in turns, ms, min / median)")
    timings: dict[str, list[float]] = {phase: [] for phase in STARTUP_PHASES}
    for _ in range(args.rounds):
        for phase, measure in STARTUP_PHASES.items():
            timings[phase].append(measure())
    for phase, values in timings.items():
        print(f"  {phase:42} {spread(values, 1000)}")


if __name__ == "__main__":
    main()
