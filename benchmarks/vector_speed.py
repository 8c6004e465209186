"""Vector throughput with CPU per env-step, each vector beside its baselines, rounds in turns.

``python benchmarks/vector_speed.py [--rounds R] [--seconds S] [--action A]`` steps, one after
another in every round (after a warm-up round each), for ``S`` seconds each:

- ``gymnasium.make_vec("rlenv/CartPole-v0", num_envs=N)`` as a user gets it (one server per
  core, repeat_action 4, random actions or the fixed action ``A``, episodes ending and
  autoresetting: a fixed 0.5 ends about 0.18 episodes per env-step, as the issue measured,
  random actions about 0.12), through
  shared-memory lanes (the default) and on sockets alone (``shared_memory=False``), for N = 64
  and N = 8;
- gymnasium's ``AsyncVectorEnv`` of 8 ``CartPole-v1`` (random actions);
- the floor: hand-written servers (``python -m examples.handwritten 32``, as many as make_vec
  starts) stepped in columns by a raw client, doing the same work as ``make_vec(64)`` (with
  the same actions).

It prints, for each, env-steps/s (min and median over the rounds), the CPU time per env-step
of the servers (or workers) and of this process (from ``/proc``, medians), and the ratios the
issue asks for: make_vec against AsyncVectorEnv(8) and against the floor, and lanes against
sockets (min and median of the per-round ratios).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import gymnasium as gym
import numpy as np
from procfs import cpu_seconds

import rlenv_client  # noqa: F401  (registers rlenv/CartPole-v0)
from rlenv_client.vector_servers import default_layout
from rlenv_tools._bench import HandWrittenVector, random_steps, random_steps_of


@dataclass
class Subject:
    """One vector to measure: ``step(n)`` runs n vector steps of ``envs`` env-steps each."""

    name: str
    step: Callable[[int], None]
    envs: int
    pids: list[int]
    rates: list[float] = field(default_factory=list)
    server_cpu: list[float] = field(default_factory=list)
    client_cpu: list[float] = field(default_factory=list)

    def round(self, seconds: float) -> None:
        """Step for about ``seconds``; note env-steps/s and CPU us per env-step."""
        steps = 0
        servers = [cpu_seconds(pid) for pid in self.pids]
        client = time.process_time()
        start = time.perf_counter()
        while time.perf_counter() - start < seconds:
            self.step(10)
            steps += 10
        elapsed = time.perf_counter() - start
        env_steps = steps * self.envs
        self.rates.append(env_steps / elapsed)
        used = sum(
            cpu_seconds(pid) - before for pid, before in zip(self.pids, servers, strict=True)
        )
        self.server_cpu.append(used / env_steps * 1e6)
        self.client_cpu.append((time.process_time() - client) / env_steps * 1e6)


def steps_of(
    step: Callable[[Any], object], envs: Any, action: float | None
) -> Callable[[int], None]:
    """``run(n)``: ``n`` calls of ``step``, with random actions or ``action`` for every env."""
    if action is None:
        return random_steps_of(step, envs)
    actions = np.full(envs.action_space.shape, action, envs.action_space.dtype)

    def run(n: int) -> None:
        for _ in range(n):
            step(actions)

    return run


def _made(
    stack: ExitStack, envs: int, action: float | None, **kwargs: Any
) -> tuple[Callable[[int], None], list[int]]:
    made = gym.make_vec("rlenv/CartPole-v0", num_envs=envs, **kwargs)
    stack.callback(made.close)
    made.reset(seed=0)
    return steps_of(made.step, made, action), [server.pid for server in made.unwrapped.servers]


def subjects(stack: ExitStack, action: float | None = None) -> list[Subject]:
    """Everything to measure, started (the rlenv vectors and the floor step with ``action``)."""
    measured = []
    for envs in (64, 8):
        for lanes in (True, False):
            step, pids = _made(stack, envs, action, shared_memory=lanes)
            how = "lanes" if lanes else "sockets"
            measured.append(Subject(f"make_vec({envs}), {how}", step, envs, pids))
    async_envs = gym.vector.AsyncVectorEnv([lambda: gym.make("CartPole-v1")] * 8)
    stack.callback(async_envs.close)
    measured.append(
        Subject(
            "AsyncVectorEnv(8) CartPole-v1",
            random_steps(async_envs),
            8,
            [process.pid for process in async_envs.processes],
        )
    )
    layout = default_layout(64)
    floor = HandWrittenVector(len(layout), layout[0])
    stack.callback(floor.close)
    actions = SimpleNamespace(
        action_space=gym.vector.utils.batch_space(gym.spaces.Box(-1, 1, (1,), np.float32), 64)
    )  # all random_steps_of asks of a vector
    measured.append(
        Subject(
            f"hand-written {len(layout)} x {layout[0]}",
            steps_of(floor.step, actions, action),
            64,
            [server.process.pid for server in floor.servers],
        )
    )
    return measured


def ratio_line(name: str, mine: Subject, base: Subject) -> str:
    """The ratio of two subjects' rates: of the medians, and min and median per round."""
    per_round = [a / b for a, b in zip(mine.rates, base.rates, strict=True)]
    return (
        f"{name:<44} {statistics.median(mine.rates) / statistics.median(base.rates):6.2f}"
        f"   per round min {min(per_round):.2f}, median {statistics.median(per_round):.2f}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7, help="timed rounds (after a warm-up)")
    parser.add_argument("--seconds", type=float, default=2.0, help="seconds per subject a round")
    parser.add_argument(
        "--action",
        type=float,
        default=None,
        help="one fixed action for the rlenv vectors and the floor (the issue's "
        "0.5) instead of random ones",
    )
    args = parser.parse_args(argv)
    with ExitStack() as stack:
        measured = subjects(stack, args.action)
        for subject in measured:
            subject.round(args.seconds / 2)  # warm-up
            subject.rates.clear()
            subject.server_cpu.clear()
            subject.client_cpu.clear()
        for _ in range(args.rounds):
            for subject in measured:
                subject.round(args.seconds)
    actions = "random actions" if args.action is None else f"action {args.action}"
    print(
        f"{args.rounds} rounds of {args.seconds} s in turns, {actions}; CPU per env-step from /proc"
    )
    print(f"{'':<34}{'env-steps/s min':>16}{'median':>10}{'server us':>11}{'client us':>11}")
    for subject in measured:
        print(
            f"{subject.name:<34}{min(subject.rates):>16,.0f}"
            f"{statistics.median(subject.rates):>10,.0f}"
            f"{statistics.median(subject.server_cpu):>11.1f}"
            f"{statistics.median(subject.client_cpu):>11.1f}"
        )
    by_name = {subject.name: subject for subject in measured}
    async_8 = by_name["AsyncVectorEnv(8) CartPole-v1"]
    floor = measured[-1]
    for envs in (64, 8):
        lanes, sockets = by_name[f"make_vec({envs}), lanes"], by_name[f"make_vec({envs}), sockets"]
        print(ratio_line(f"make_vec({envs}) lanes / AsyncVectorEnv(8)", lanes, async_8))
        print(ratio_line(f"make_vec({envs}) lanes / sockets", lanes, sockets))
    print(
        ratio_line("make_vec(64) lanes / hand-written floor", by_name["make_vec(64), lanes"], floor)
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
