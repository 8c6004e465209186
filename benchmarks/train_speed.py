"""Training speed over rlenv's servers against the same environment in process.

``python benchmarks/train_speed.py [--rounds R] [--target TARGET]`` runs ``rlenv bench --train``
(``tools/rlenv_tools/training_speed.py``: SB3 PPO in two configurations and gymnasium's
SyncVectorEnv, each against the environment in process, rounds in turns) under the three
conditions issue 31 names, each in a process of its own:

- torch on one thread (``torch.set_num_threads(1)``, as ``OMP_NUM_THREADS=1``);
- torch's default threads;
- torch on one thread beside a CPU-bound process of something else.

Needs torch and stable-baselines3 (``make sb3``). Prints each condition's tables, and the
figures' medians side by side; ``--json PATH`` writes every row.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

CONDITIONS = {
    "torch 1 thread": ["--torch-threads", "1"],
    "torch's default threads": [],
    "1 thread, a CPU-bound neighbour": ["--torch-threads", "1", "--busy"],
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--target", default="rlenv/CartPole-v1")
    parser.add_argument("--json", help="write every row of every condition here")
    args = parser.parse_args()
    results: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as folder:
        for condition, options in CONDITIONS.items():
            path = Path(folder) / "rows.json"
            print(f"## {condition}\n", flush=True)
            subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "rlenv",
                    "bench",
                    "--train",
                    args.target,
                    "--rounds",
                    str(args.rounds),
                    "--native",
                    "CartPole-v1",
                    "--json",
                    str(path),
                    *options,
                ],
                check=True,
            )
            results[condition] = json.loads(path.read_text())
            print(flush=True)
    print("## the ratios side by side (median of the per-round ratios; min in brackets)\n")
    names = list(CONDITIONS)
    print("| figure | " + " | ".join(names) + " |")
    print("|---|" + "---:|" * len(names))
    first = results[names[0]]
    for index, row in enumerate(first):
        cells = [
            f"{results[name][index]['ratio']:.2f} ({results[name][index]['ratio_min']:.2f})"
            for name in names
        ]
        print(f"| {row['group']}: {row['name']} | " + " | ".join(cells) + " |")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
