"""CleanRL's ``ppo.py``, unmodified, on CartPole-v1 and rlenv/CartPole-v1: learning curves.

``python benchmarks/cleanrl_curves.py PATH/TO/ppo.py [--seeds 1 2] [-- PPO ARGS...]``

Needs torch, tyro and tensorboard beside rlenv (``make cleanrl`` sets up such a venv). ppo.py
is not part of rlenv: fetch ``cleanrl/ppo.py`` from vwxyzjn/cleanrl yourself.

Under gymnasium 1.x, ppo.py logs no episodic return: it reads ``infos["final_info"]``, which
1.x vectors no longer fill by default (cleanrl#499, #534), so the curves are recorded here
instead. Each run is a child process that replaces ``gymnasium.wrappers.RecordEpisodeStatistics``
(which ppo.py wraps every sub-env in) with a subclass that also writes every finished episode
(environment steps so far in this process, return, length) to a CSV file, then runs ppo.py
with ``runpy`` as ``__main__``: the script's file and its arguments are unchanged. The runs take
turns: for each seed, native CartPole-v1 first, then ``rlenv_client:rlenv/CartPole-v1`` with
the same arguments.

The children run with ``OMP_NUM_THREADS=1`` unless it is set: torch's default thread pool
(one thread per core) spins between operations, and on a 2-core machine that starved the
servers (ppo.py on rlenv/CartPole-v1 ran at 70-110 steps/s instead of ~1,700; native
CartPole-v1 ran faster with one thread too).

Prints, for each run, its wall time and ppo.py's last SPS line, then the mean episodic return
per tenth of the run's environment steps, native and rlenv side by side.
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ENV_IDS = {"native": "CartPole-v1", "rlenv": "rlenv_client:rlenv/CartPole-v1"}
BUCKETS = 10

_CHILD = """
import csv, runpy, sys
import gymnasium

episodes = csv.writer(open(sys.argv[1], "w", newline=""))
ppo = sys.argv[2]


class LoggedEpisodeStatistics(gymnasium.wrappers.RecordEpisodeStatistics):
    steps = 0  # environment steps of every sub-env in this process

    def step(self, action):
        result = super().step(action)
        LoggedEpisodeStatistics.steps += 1
        if result[2] or result[3]:
            episode = result[4]["episode"]
            episodes.writerow((LoggedEpisodeStatistics.steps, float(episode["r"]),
                               int(episode["l"])))
        return result


gymnasium.wrappers.RecordEpisodeStatistics = LoggedEpisodeStatistics
sys.argv = [ppo, *sys.argv[3:]]
runpy.run_path(ppo, run_name="__main__")
"""


def run(
    ppo: Path, env_id: str, seed: int, ppo_args: list[str], workdir: Path
) -> tuple[list[tuple[int, float, int]], float, str]:
    """One ppo.py run: its episodes, wall time and last SPS line."""
    episodes = workdir / f"{env_id.replace('/', '-').replace(':', '-')}-{seed}.csv"
    start = time.perf_counter()
    result = subprocess.run(
        [
            sys.executable,
            "-c",
            _CHILD,
            str(episodes),
            str(ppo.resolve()),
            "--env-id",
            env_id,
            "--seed",
            str(seed),
            *ppo_args,
        ],
        cwd=workdir,
        capture_output=True,
        text=True,
        env={**os.environ, "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")},
    )
    seconds = time.perf_counter() - start
    if result.returncode != 0:
        raise SystemExit(f"ppo.py on {env_id} failed ({result.returncode}):\n{result.stderr}")
    sps = [line for line in result.stdout.splitlines() if line.startswith("SPS:")]
    with open(episodes, newline="") as file:
        rows = [(int(steps), float(ret), int(length)) for steps, ret, length in csv.reader(file)]
    return rows, seconds, sps[-1] if sps else "no SPS line"


def curve(rows: list[tuple[int, float, int]], total: int) -> list[float | None]:
    """The mean return of the episodes that ended in each tenth of ``total`` steps."""
    buckets: list[list[float]] = [[] for _ in range(BUCKETS)]
    for steps, ret, _ in rows:
        buckets[min(BUCKETS - 1, (steps - 1) * BUCKETS // total)].append(ret)
    return [statistics.mean(bucket) if bucket else None for bucket in buckets]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("ppo", type=Path, help="CleanRL's cleanrl/ppo.py")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--total-timesteps", type=int, default=500_000)
    parser.add_argument("ppo_args", nargs="*", help="more ppo.py arguments, after --")
    args = parser.parse_args()
    ppo_args = ["--total-timesteps", str(args.total_timesteps), *args.ppo_args]
    curves: dict[str, list[list[float | None]]] = {name: [] for name in ENV_IDS}
    with tempfile.TemporaryDirectory(prefix="cleanrl-curves-") as directory:
        for seed in args.seeds:
            for name, env_id in ENV_IDS.items():
                rows, seconds, sps = run(args.ppo, env_id, seed, ppo_args, Path(directory))
                total = max(steps for steps, *_ in rows) if rows else 1
                curves[name].append(curve(rows, args.total_timesteps))
                last = [ret for steps, ret, _ in rows if steps > total * 0.9]
                print(
                    f"seed {seed} {name:6} {env_id}: ran to the end in {seconds:.0f} s "
                    f"({sps}), {len(rows)} episodes, mean return of the last tenth "
                    f"{statistics.mean(last) if last else float('nan'):.0f}",
                    flush=True,
                )
    print(
        f"\nmean episodic return per tenth of {args.total_timesteps:,} steps "
        f"(seeds {' '.join(map(str, args.seeds))})"
    )
    print(f"{'steps up to':>12} {'native':>8} {'rlenv':>8}")
    for bucket in range(BUCKETS):
        cells = []
        for name in ENV_IDS:
            values = [each[bucket] for each in curves[name] if each[bucket] is not None]
            cells.append(f"{statistics.mean(values):8.1f}" if values else f"{'-':>8}")
        print(f"{(bucket + 1) * args.total_timesteps // BUCKETS:>12,} {' '.join(cells)}")


if __name__ == "__main__":
    main()
