"""make_vec(64) of two whole checkouts, trainer and servers, in turns: throughput and CPU.

``python benchmarks/vector_versus.py OTHER_PYTHON [--pairs P] [--rounds R] [--seconds S]
[--action A] [--envs N]`` runs P pairs of processes, this checkout's interpreter and
``OTHER_PYTHON`` (the ``python`` of another checkout's virtual environment) in turns, the order
swapped every pair. Each process is a trainer: it makes ``gymnasium.make_vec(
"rlenv/CartPole-v0", num_envs=N)`` with its own rlenv (so its servers and its client are its
checkout's), steps it for R rounds of S seconds (random actions, or ``A`` for every env, as
the issue measures), and reports the medians of its rounds: env-steps/s, and the CPU per
env-step of its servers and of itself (from ``/proc``).

``versus.py`` serves two checkouts but steps both with this checkout's client; this contest
takes in the client's side too (the trainer shares a core with a server on a small machine, so
the trainer's CPU is paid by the servers as well). It prints each side's medians over the pairs
and the per-pair ratios of this checkout to the other (min and median).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

from procfs import cpu_seconds


def worker(envs: int, rounds: int, seconds: float, action: float | None) -> dict[str, float]:
    """One trainer's medians: env-steps/s, servers' and own CPU µs per env-step."""
    import gymnasium as gym
    import numpy as np

    import rlenv_client  # noqa: F401  (registers rlenv/CartPole-v0)

    made = gym.make_vec("rlenv/CartPole-v0", num_envs=envs)
    try:
        pids = [server.pid for server in made.unwrapped.servers]
        made.reset(seed=0)
        if action is None:
            made.action_space.seed(0)
            batches = [made.action_space.sample() for _ in range(64)]
        else:
            batches = [np.full(made.action_space.shape, action, made.action_space.dtype)]
        rates, servers, own = [], [], []
        for turn in range(rounds + 1):  # the first is a warm-up
            steps = 0
            servers_before = sum(cpu_seconds(pid) for pid in pids)
            own_before = time.process_time()
            start = time.perf_counter()
            while time.perf_counter() - start < seconds:
                for _ in range(10):
                    made.step(batches[steps % len(batches)])
                    steps += 1
            elapsed = time.perf_counter() - start
            env_steps = steps * envs
            if turn:
                rates.append(env_steps / elapsed)
                servers.append(
                    (sum(cpu_seconds(pid) for pid in pids) - servers_before) / env_steps * 1e6
                )
                own.append((time.process_time() - own_before) / env_steps * 1e6)
    finally:
        made.close()
    return {
        "rate": statistics.median(rates),
        "server": statistics.median(servers),
        "client": statistics.median(own),
    }


def measure(python: str, arguments: argparse.Namespace) -> dict[str, float]:
    """One trainer process run by ``python``, from a folder of no checkout's (so that each
    interpreter imports its own rlenv)."""
    output = subprocess.run(
        [
            python,
            os.path.abspath(__file__),
            "--worker",
            str(arguments.envs),
            str(arguments.rounds),
            str(arguments.seconds),
            "" if arguments.action is None else str(arguments.action),
        ],
        capture_output=True,
        text=True,
        check=True,
        cwd=tempfile.gettempdir(),
    ).stdout
    return json.loads(output.splitlines()[-1])


def main() -> None:
    """Parse the arguments and measure (or be one trainer, with ``--worker``)."""
    if sys.argv[1:2] == ["--worker"]:
        envs, rounds, seconds, action = sys.argv[2:6]
        print(
            json.dumps(
                worker(int(envs), int(rounds), float(seconds), float(action) if action else None)
            )
        )
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("other_python", help="the python of the other checkout's venv")
    parser.add_argument("--pairs", type=int, default=6)
    parser.add_argument("--rounds", type=int, default=3, help="timed rounds per process")
    parser.add_argument("--seconds", type=float, default=1.5, help="seconds per round")
    parser.add_argument(
        "--action",
        type=float,
        default=None,
        help="one fixed action for every env (the issue's 0.5: about 0.18 "
        "episode ends per env-step) instead of random ones",
    )
    parser.add_argument("--envs", type=int, default=64)
    arguments = parser.parse_args()
    other = arguments.other_python  # run from elsewhere: a relative path is made absolute
    sides = {"this": sys.executable, "other": os.path.abspath(other) if os.sep in other else other}
    results: dict[str, list[dict[str, float]]] = {"this": [], "other": []}
    for pair in range(arguments.pairs):
        for side in ("this", "other") if pair % 2 == 0 else ("other", "this"):
            results[side].append(measure(sides[side], arguments))
    actions = "random actions" if arguments.action is None else f"action {arguments.action}"
    print(
        f"make_vec({arguments.envs}), {actions}: {arguments.pairs} pairs of processes in "
        f"turns, {arguments.rounds} rounds of {arguments.seconds} s each (medians)"
    )
    print(f"{'':8}{'env-steps/s':>14}{'server us':>11}{'client us':>11}")
    for side, runs in results.items():
        print(
            f"{side:8}{statistics.median(r['rate'] for r in runs):>14,.0f}"
            f"{statistics.median(r['server'] for r in runs):>11.1f}"
            f"{statistics.median(r['client'] for r in runs):>11.1f}"
        )
    for name in ("rate", "server", "client"):
        ratios = [a[name] / b[name] for a, b in zip(results["this"], results["other"], strict=True)]
        print(f"this / other, {name}: min {min(ratios):.3f} median {statistics.median(ratios):.3f}")


if __name__ == "__main__":
    main()
