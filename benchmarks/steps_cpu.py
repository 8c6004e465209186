"""The CPU a column step costs per env-step, in process: two revisions in one run, in turns.

``python benchmarks/steps_cpu.py OTHER_PYTHON [--rounds R] [--requests N] [--instances K]
[--action A]`` runs, alternately with this checkout's interpreter and with ``OTHER_PYTHON`` (the
``python`` of another checkout's virtual environment), a process that holds K CartPoles in a
``LocalClient`` (the host a server runs, without the socket and the codec) and sends N ``steps``
requests at repeat_action 4 (random actions, or ``A`` for every instance, episodes ending and
resetting as a vector's do, a 500-step limit), then prints the process's CPU time per env-step.
Each process makes the same requests. A fixed action of 0.5 ends about 0.18 episodes per
env-step, random ones about 0.12: the share of resets differs.

It prints the figure's min and median for both, and the ratios of this checkout to the other
(min and median of the per-round ratios): the server's share of a vector step, without the
transport (see ``versus.py`` for the servers over TCP).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

CARTPOLE = "examples.cartpole:CartPoleEnvironment"


def worker(instances: int, requests: int, action: float | None = None) -> float:
    """CPU µs per env-step of ``requests`` column steps of ``instances`` CartPoles.

    Random actions, or ``action`` for every instance at every step."""
    from rlenv_client import LocalClient

    client = LocalClient(CARTPOLE, instances=instances)
    client.send_batch([client.reset_request(seed=i) for i in range(instances)])
    client.receive_batch()
    rng = np.random.default_rng(0)
    reset = np.zeros(instances, bool)
    steps = np.zeros(instances, int)

    def step() -> None:
        nonlocal reset
        actions = (
            rng.uniform(-1, 1, (instances, 1))
            if action is None
            else np.full((instances, 1), action)
        )
        client.send_steps(actions.astype(np.float32), reset, 4)
        answer = client.receive_steps()
        steps[:] += 1
        ended = answer.terminated | answer.truncated | (steps >= 500)
        steps[ended] = 0
        reset = ended

    for _ in range(requests // 5):  # warm-up
        step()
    start = time.process_time()
    for _ in range(requests):
        step()
    return (time.process_time() - start) / (requests * instances) * 1e6


def measure(python: str, instances: int, requests: int, action: float | None) -> float:
    """One round in a new process run by ``python``."""
    # From a folder of no checkout's, so that each interpreter imports its own rlenv.
    output = subprocess.run(
        [
            python,
            __file__,
            "--worker",
            str(instances),
            str(requests),
            "" if action is None else str(action),
        ],
        capture_output=True,
        text=True,
        check=True,
        cwd=tempfile.gettempdir(),
    ).stdout
    return float(output)


def main() -> None:
    """Parse the arguments and measure (or be a round's process, with ``--worker``)."""
    if sys.argv[1:2] == ["--worker"]:
        action = float(sys.argv[4]) if len(sys.argv) > 4 and sys.argv[4] else None
        print(worker(int(sys.argv[2]), int(sys.argv[3]), action))
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("other_python", help="the python of the other checkout's venv")
    parser.add_argument("--rounds", type=int, default=8)
    parser.add_argument("--requests", type=int, default=1000)
    parser.add_argument("--instances", type=int, default=32)
    parser.add_argument(
        "--action",
        type=float,
        default=None,
        help="one fixed action for every step (as the issue measures: about "
        "0.18 episode ends per env-step) instead of random ones",
    )
    arguments = parser.parse_args()
    sides = {"this": sys.executable, "other": arguments.other_python}
    results: dict[str, list[float]] = {"this": [], "other": []}
    for turn in range(arguments.rounds):
        for side in ("this", "other") if turn % 2 == 0 else ("other", "this"):
            results[side].append(
                measure(sides[side], arguments.instances, arguments.requests, arguments.action)
            )
    actions = "random actions" if arguments.action is None else f"action {arguments.action}"
    print(
        f"steps of {arguments.instances} CartPoles in process, repeat 4, {actions}: "
        "CPU us per env-step"
    )
    for side, values in results.items():
        print(f"  {side:5s}  {min(values):6.1f} min {statistics.median(values):6.1f} median")
    ratios = [a / b for a, b in zip(results["this"], results["other"], strict=True)]
    print(f"  this / other: min {min(ratios):.2f} median {statistics.median(ratios):.2f}")


if __name__ == "__main__":
    main()
