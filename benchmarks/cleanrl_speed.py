"""CleanRL's ``ppo.py``, unmodified: its SPS on rlenv/CartPole-v1 against native CartPole-v1.

``python benchmarks/cleanrl_speed.py PATH/TO/ppo.py [--rounds R] [--steps N] [--envs 4 8]
[--threads 1|default]``

Each round runs ppo.py once per number of environments on ``CartPole-v1`` and then on
``rlenv_client:rlenv/CartPole-v1`` (gymnasium's ``SyncVectorEnv`` of ``gym.make`` envs, which
share one ``--per-client`` server), each in a fresh process and a scratch folder, and reads the
last ``SPS:`` line it prints. Prints every run and, per number of environments, the median and
minimum of the per-round ratios rlenv / native. ``--threads 1`` runs the children with
``OMP_NUM_THREADS=1``; ``default`` leaves torch its own threads.

Needs torch, tyro and tensorboard beside rlenv (``make cleanrl`` sets up such a venv).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ENV_IDS = {"native": "CartPole-v1", "rlenv": "rlenv_client:rlenv/CartPole-v1"}


def sps(ppo: Path, env_id: str, envs: int, steps: int, threads: str) -> float:
    """One run of ppo.py; the SPS of its last line."""
    environment = dict(os.environ)
    if threads != "default":
        environment["OMP_NUM_THREADS"] = threads
    with tempfile.TemporaryDirectory() as folder:
        result = subprocess.run(
            [
                sys.executable,
                str(ppo.resolve()),
                "--env-id",
                env_id,
                "--num-envs",
                str(envs),
                "--total-timesteps",
                str(steps),
                "--seed",
                "1",
            ],
            cwd=folder,
            env=environment,
            capture_output=True,
            text=True,
            check=False,
        )
    lines = [line for line in result.stdout.splitlines() if line.startswith("SPS:")]
    if result.returncode != 0 or not lines:
        raise RuntimeError(
            f"ppo.py on {env_id} failed:\n{result.stdout[-2000:]}{result.stderr[-2000:]}"
        )
    return float(lines[-1].split()[1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("ppo", type=Path, help="CleanRL's cleanrl/ppo.py")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=40960, help="--total-timesteps of a run")
    parser.add_argument("--envs", type=int, nargs="+", default=[4, 8])
    parser.add_argument("--threads", default="1", help="OMP_NUM_THREADS, or 'default'")
    args = parser.parse_args()
    ratios: dict[int, list[float]] = {envs: [] for envs in args.envs}
    for round_number in range(1, args.rounds + 1):
        for envs in args.envs:
            native = sps(args.ppo, ENV_IDS["native"], envs, args.steps, args.threads)
            served = sps(args.ppo, ENV_IDS["rlenv"], envs, args.steps, args.threads)
            ratios[envs].append(served / native)
            print(
                f"round {round_number}, {envs} envs: native {native:,.0f} SPS, rlenv "
                f"{served:,.0f} SPS, ratio {served / native:.2f}",
                flush=True,
            )
    print(
        f"\nppo.py, threads {args.threads}: rlenv/CartPole-v1 against CartPole-v1 "
        "(median of the per-round ratios, min)"
    )
    for envs, values in ratios.items():
        print(f"  {envs} envs: {statistics.median(values):.2f} (min {min(values):.2f})")


if __name__ == "__main__":
    main()
