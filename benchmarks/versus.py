"""Two revisions of rlenv's server, stepped by the same client in one run, rounds in turns.

``python benchmarks/versus.py OTHER_PYTHON [--rounds R] [--steps N]`` starts ``rlenv serve``
with this checkout's interpreter and with ``OTHER_PYTHON`` (the ``python`` of another checkout's
virtual environment, e.g. one made with ``git worktree add`` at an older commit), and measures,
alternating between the two after a warm-up round each:

- a CartPole ``Client.step`` at repeat_action 4 (one episode for the whole run);
- a vector step: ``RemoteVectorEnv`` over two servers of 32 instances each, repeat_action 4,
  random actions, episodes ending and autoresetting;
- the server's CPU time per step (from ``/proc``, both figures).

It prints each figure's min and median for both, and the ratios of this checkout to the other
(min of the per-round ratios, and their median). The client is always this checkout's; the
protocol must be the same major version on both sides.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import ExitStack, contextmanager

import numpy as np
from procfs import cpu_seconds

from rlenv_client import Client, RemoteVectorEnv
from rlenv_client.launcher import end_process

CARTPOLE = "examples.cartpole:CartPoleEnvironment"
ENDLESS = {"world": {"track_limit": 1e9}, "agent": {"angle_limit": 1e9}}


@contextmanager
def served(
    python: str, *args: str, target: str = CARTPOLE, env: Mapping[str, str] | None = None
) -> Iterator[tuple[str, int]]:
    """``rlenv serve target`` (CartPole) run by ``python`` in ``env``; its (address, pid)."""
    # From a folder of no checkout's: ``python -m`` puts the working directory first on the
    # path, which would run this checkout's rlenv with the other's interpreter.
    process = subprocess.Popen(
        [python, "-m", "rlenv", "serve", target, "--port", "0", *args],
        stdout=subprocess.PIPE,
        text=True,
        stdin=subprocess.DEVNULL,
        start_new_session=True,
        cwd=tempfile.gettempdir(),
        env=None if env is None else dict(env),
    )
    try:
        line = process.stdout.readline()  # type: ignore[union-attr]
        assert line.startswith("listening on "), line
        yield line.split()[-1], process.pid
    finally:
        end_process(process, 10.0)


def single(address: str, pid: int, steps: int) -> Callable[[], tuple[float, float]]:
    """A round of ``steps`` Client.steps: (steps/s, server CPU µs per step)."""
    host, port = address.rsplit(":", 1)
    client = Client(host, int(port), timeout=30)
    client.configure(**{"agent": ENDLESS["agent"], "world": ENDLESS["world"]})
    client.reset(seed=0)
    action = np.array([0.1], np.float32)

    def round_() -> tuple[float, float]:
        cpu = cpu_seconds(pid)
        start = time.perf_counter()
        for _ in range(steps):
            client.step(action, repeat_action=4)
        elapsed = time.perf_counter() - start
        return steps / elapsed, (cpu_seconds(pid) - cpu) / steps * 1e6

    return round_


def vector(addresses: list[str], pids: list[int], steps: int) -> Callable[[], tuple[float, float]]:
    """A round of ``steps`` vector steps over 64 CartPoles: (env-steps/s, server CPU µs each)."""
    envs = RemoteVectorEnv(addresses=addresses, repeat_action=4, max_episode_steps=500)
    envs.reset(seed=0)
    rng = np.random.default_rng(0)

    def round_() -> tuple[float, float]:
        cpu = sum(cpu_seconds(pid) for pid in pids)
        start = time.perf_counter()
        for _ in range(steps):
            envs.step(rng.uniform(-1, 1, (envs.num_envs, 1)).astype(np.float32))
        elapsed = time.perf_counter() - start
        env_steps = steps * envs.num_envs
        return env_steps / elapsed, (sum(cpu_seconds(pid) for pid in pids) - cpu) / env_steps * 1e6

    return round_


def compare(
    name: str,
    ours: Callable[[], tuple[float, float]],
    theirs: Callable[[], tuple[float, float]],
    rounds: int,
) -> None:
    """Rounds in turns after a warm-up each; print min, median and the ratios."""
    ours(), theirs()
    results: dict[str, list[tuple[float, float]]] = {"this": [], "other": []}
    for _ in range(rounds):
        results["this"].append(ours())
        results["other"].append(theirs())
    print(f"\n{name}")
    for side, values in results.items():
        speeds, cpus = [v[0] for v in values], [v[1] for v in values]
        print(
            f"  {side:5s}  {min(speeds):9.0f} min {statistics.median(speeds):9.0f} median /s;"
            f"  server CPU {min(cpus):6.1f} min {statistics.median(cpus):6.1f} median us"
        )
    ratios = [a[0] / b[0] for a, b in zip(results["this"], results["other"], strict=True)]
    cpu_ratios = [a[1] / b[1] for a, b in zip(results["this"], results["other"], strict=True)]
    print(
        f"  this / other: speed min {min(ratios):.2f} median {statistics.median(ratios):.2f};"
        f"  server CPU min {min(cpu_ratios):.2f} median {statistics.median(cpu_ratios):.2f}"
    )


def main() -> None:
    """Parse the arguments and measure."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("other_python", help="the python of the other checkout's venv")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=2000, help="single steps per round")
    arguments = parser.parse_args()
    with ExitStack() as stack:
        ours = stack.enter_context(served(sys.executable))
        theirs = stack.enter_context(served(arguments.other_python))
        compare(
            "Client.step, CartPole, repeat 4",
            single(*ours, arguments.steps),
            single(*theirs, arguments.steps),
            arguments.rounds,
        )
    with ExitStack() as stack:
        ours_v = [
            stack.enter_context(served(sys.executable, "--instances", "32")) for _ in range(2)
        ]
        theirs_v = [
            stack.enter_context(served(arguments.other_python, "--instances", "32"))
            for _ in range(2)
        ]
        compare_vectors(ours_v, theirs_v, max(arguments.steps // 20, 20), arguments.rounds)


def compare_vectors(
    ours: list[tuple[str, int]], theirs: list[tuple[str, int]], steps: int, rounds: int
) -> None:
    """The vector figure: two servers of 32 CartPoles a side, ``(address, pid)`` each."""
    compare(
        "vector step, 64 CartPoles in 2 servers, repeat 4",
        vector([a for a, _ in ours], [p for _, p in ours], steps),
        vector([a for a, _ in theirs], [p for _, p in theirs], steps),
        rounds,
    )


if __name__ == "__main__":
    main()
