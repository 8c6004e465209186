"""What agents that come and go cost an environment whose agents are fixed: two checkouts in turns.

``python benchmarks/come_and_go_cost.py BASE_CHECKOUT [--rounds R] [--steps N]`` serves the
fixed examples with this checkout's code and with ``BASE_CHECKOUT``'s (a checkout from before
issue 42: ``git worktree add /tmp/base42 094d873``), both with this interpreter, and steps both
with this checkout's client, rounds in turns after a warm-up round each:

- a CartPole ``Client.step`` at repeat_action 4 (one episode for the whole run);
- a Tag ``Client.step`` (the chaser and both runners acting, repeat_action 4);
- a vector step: ``RemoteVectorEnv`` over two servers of 32 CartPoles, repeat_action 4,
  random actions, episodes ending and autoresetting.

Each prints steps/s and the servers' CPU per step (from ``/proc``), min and median for both,
and the ratios of this checkout to the base (min and median of the per-round ratios). Every
server runs from a folder of neither checkout, with ``PYTHONPATH`` naming its checkout's
``rlenv``, ``client`` and ``tools``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import numpy as np
from procfs import cpu_seconds
from versus import compare, compare_vectors, single
from versus import served as serve_with

from rlenv_client import Client

THIS = Path(__file__).resolve().parent.parent
CARTPOLE = "examples.cartpole:CartPoleEnvironment"
TAG = "examples.tag:TagEnvironment"


@contextmanager
def served(checkout: Path, target: str, *args: str) -> Iterator[tuple[str, int]]:
    """``rlenv serve target`` of ``checkout``'s code; its (address, pid)."""
    path = os.pathsep.join(str(checkout / part) for part in ("", "client", "tools"))
    env = {**os.environ, "PYTHONPATH": path}
    with serve_with(sys.executable, *args, target=target, env=env) as server:
        yield server


def tag(address: str, pid: int, steps: int) -> Callable[[], tuple[float, float]]:
    """A round of ``steps`` Tag Client.steps, every agent acting: (steps/s, server CPU µs)."""
    host, port = address.rsplit(":", 1)
    client = Client(host, int(port), timeout=30)
    client.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = [
        {name: rng.uniform(-1, 1, 2).astype(np.float32) for name in client.hello.agents}
        for _ in range(64)
    ]

    def round_() -> tuple[float, float]:
        cpu = cpu_seconds(pid)
        start = time.perf_counter()
        for step in range(steps):
            *_, terminated, truncated, _ = client.step(actions[step % 64], repeat_action=4)
            if terminated or truncated:
                client.reset()
        elapsed = time.perf_counter() - start
        return steps / elapsed, (cpu_seconds(pid) - cpu) / steps * 1e6

    return round_


def main() -> None:
    """Parse the arguments and measure."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("base", type=Path, help="a checkout from before issue 42")
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--steps", type=int, default=2000, help="single steps per round")
    arguments = parser.parse_args()
    base = arguments.base.resolve()
    for name, target, measure in (
        ("Client.step, CartPole, repeat 4", CARTPOLE, single),
        ("Client.step, Tag (3 agents acting), repeat 4", TAG, tag),
    ):
        with ExitStack() as stack:
            ours = stack.enter_context(served(THIS, target))
            theirs = stack.enter_context(served(base, target))
            compare(
                name,
                measure(*ours, arguments.steps),
                measure(*theirs, arguments.steps),
                arguments.rounds,
            )
    with ExitStack() as stack:
        ours_v = [stack.enter_context(served(THIS, CARTPOLE, "--instances", "32")) for _ in "ab"]
        theirs_v = [stack.enter_context(served(base, CARTPOLE, "--instances", "32")) for _ in "ab"]
        compare_vectors(ours_v, theirs_v, max(arguments.steps // 20, 20), arguments.rounds)


if __name__ == "__main__":
    main()
