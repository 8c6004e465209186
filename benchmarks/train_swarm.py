"""Training the flock of Swarm with SB3's PPO, every member a sub-environment of one policy.

``python benchmarks/train_swarm.py [--envs K] [--train-steps T] [--episodes E] [--json PATH]``
(the sb3 extra; torch on one thread).

``examples/swarm`` (``rlenv/Swarm-v0``) is one group of 64 members heading for a nest. The
trainer is ``SB3VecEnv(K, TARGET, agents="Flock")``: each member of each of the K instances is
a sub-environment (``num_envs = 64 K``), all sharing one PPO policy; a member that left is
inactive (zeros) until its instance resets.

PPO trains for ``T`` member-steps (sub-environment steps); then its deterministic policy, the
scripted flock (``Flock.heuristic``: every member steered to the nest) and random actions each
play ``E`` episodes over the same seeds (1000 on), the client acting for the whole flock with
one ``(64, 2)`` array a step. Printed for each: the flock's return per episode (the members'
rewards summed), the members home and the steps per episode (150 at most: the sooner the flock
is home, the better), mean, min and median over the seeds.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO

from rlenv.examples.swarm import GROUP, MEMBERS, TARGET
from rlenv.examples.swarm.scene import steer
from rlenv_client import Client
from rlenv_client.launcher import ServerProcess
from rlenv_client.sb3 import SB3VecEnv

Flock = Callable[[np.ndarray], np.ndarray]
"""A flock's policy: the members' observations ``(64, 6)`` to their actions ``(64, 2)``."""


def play(flock: Flock, seeds: range) -> list[tuple[float, int, int]]:
    """``flock`` over one episode per seed on a server of its own: (return, home, steps)."""
    results = []
    with ServerProcess(TARGET) as server, Client(server.host, server.port, timeout=60) as client:
        for seed in seeds:
            observation, _ = client.reset(seed=seed)
            total, home, steps = 0.0, 0, 0
            while True:
                action = {GROUP: flock(observation[GROUP])}
                observation, reward, terminated, truncated, info = client.step(action)
                total += reward
                home += int(info["agents"][GROUP]["terminated"].sum())
                steps += 1
                if terminated or truncated:
                    break
            results.append((total, home, steps))
    return results


def summary(results: list[tuple[float, int, int]]) -> dict[str, float]:
    """Mean, min and median of the returns, of the members home and of the steps."""
    returns = [total for total, _, _ in results]
    home = [count for _, count, _ in results]
    steps = [count for _, _, count in results]
    return {
        "return_mean": statistics.fmean(returns),
        "return_min": min(returns),
        "return_median": statistics.median(returns),
        "home_mean": statistics.fmean(home),
        "home_min": min(home),
        "home_median": statistics.median(home),
        "steps_mean": statistics.fmean(steps),
        "steps_min": min(steps),
        "steps_median": statistics.median(steps),
    }


def main() -> None:
    """Train, then compare the trained flock with the scripted one and with random actions."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=2, help="instances of 64 members")
    parser.add_argument("--train-steps", type=int, default=1_000_000, help="member-steps")
    parser.add_argument("--episodes", type=int, default=10, help="seeds 1000 on")
    parser.add_argument("--json", metavar="PATH")
    args = parser.parse_args()
    torch.set_num_threads(1)
    envs = SB3VecEnv(args.envs, TARGET, agents=GROUP)
    try:
        model = PPO(
            "MlpPolicy",
            envs,
            n_steps=64,
            batch_size=1024,
            learning_rate=1e-3,
            seed=0,
            verbose=0,
        )
        started = time.perf_counter()
        model.learn(total_timesteps=args.train_steps)
        seconds = time.perf_counter() - started
    finally:
        envs.close()

    def trained(observations: np.ndarray) -> np.ndarray:
        return model.predict(observations, deterministic=True)[0].astype(np.float32)

    rng = np.random.default_rng(0)

    def random(observations: np.ndarray) -> np.ndarray:
        return rng.uniform(-1, 1, (MEMBERS, 2)).astype(np.float32)

    seeds = range(1000, 1000 + args.episodes)
    report: dict[str, Any] = {
        "train_steps": args.train_steps,
        "train_seconds": seconds,
        "envs": args.envs,
    }
    for name, flock in (("trained", trained), ("scripted", steer), ("random", random)):
        report[name] = summary(play(flock, seeds))
    print(
        f"PPO: {args.train_steps:,} member-steps in {seconds:.0f} s "
        f"({args.envs} x {MEMBERS} members)"
    )
    for name in ("trained", "scripted", "random"):
        figures = report[name]
        print(
            f"{name:>8}: return mean {figures['return_mean']:.2f} (min "
            f"{figures['return_min']:.2f}, median {figures['return_median']:.2f}); home "
            f"mean {figures['home_mean']:.1f} (min {figures['home_min']}, median "
            f"{figures['home_median']}); steps mean {figures['steps_mean']:.1f} (min "
            f"{figures['steps_min']}, median {figures['steps_median']})"
        )
    if args.json:
        with open(args.json, "w") as out:
            json.dump(report, out, indent=2)
            out.write("\n")


if __name__ == "__main__":
    main()
