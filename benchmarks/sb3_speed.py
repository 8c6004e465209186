"""SB3 PPO training speed, rlenv's CartPole against gymnasium's: ``python benchmarks/sb3_speed.py``.

Optional: needs torch and stable-baselines3 (``make sb3`` installs them). Two PPO models with
Stable-Baselines3's default hyperparameters and one environment each, one on
``gym.make("rlenv/CartPole-v0")`` (a server subprocess, stepped over a socket) and one on
``gym.make("CartPole-v1")`` (in this process), are built outside the timed region. Each round
times ``model.learn(steps, reset_num_timesteps=False)`` (whole rollout + train cycles of
``n_steps``, 2048 by default) on each in turn, after one warm-up round each, so that both are
measured under the same conditions however the machine's speed drifts. Prints the steps per
second of each (min and median over the rounds), the ratio of the medians and the min and
median of the per-round ratios.

The work differs by design: rlenv's CartPole has a continuous action (a Gaussian policy) and
runs 4 pymunk ticks per step, CartPole-v1 a discrete one and one Euler step. The figure says how
much of a trainer's time the environment costs, not how fast two equal simulations run.
Threads: torch's default (``torch.set_num_threads`` is not called).
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import gymnasium as gym

import rlenv_client  # noqa: F401  (registers rlenv/CartPole-v0)

ENVIRONMENTS = ("rlenv/CartPole-v0", "CartPole-v1")


def make_model(env_id: str) -> Any:
    """A PPO model with default hyperparameters on one ``gym.make(env_id)``."""
    from stable_baselines3 import PPO

    return PPO("MlpPolicy", gym.make(env_id), seed=0, verbose=0)


def learn_rate(model: Any, steps: int) -> float:
    """Environment steps per second of one ``model.learn(steps)`` that goes on training."""
    before = model.num_timesteps
    start = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    return (model.num_timesteps - before) / (time.perf_counter() - start)


def measure(rounds: int, steps: int) -> tuple[dict[str, list[float]], int]:
    """Steps per second of each environment, per round, the rounds taken in turns; the
    timesteps of a round (``steps`` rounded up to whole rollout cycles)."""
    models = {env_id: make_model(env_id) for env_id in ENVIRONMENTS}
    try:
        cycle = max(model.n_steps for model in models.values())
        steps = -(-steps // cycle) * cycle  # whole rollout + train cycles
        for model in models.values():  # warm-up
            learn_rate(model, steps)
        rates: dict[str, list[float]] = {env_id: [] for env_id in ENVIRONMENTS}
        for _ in range(rounds):
            for env_id, model in models.items():
                rates[env_id].append(learn_rate(model, steps))
        return rates, steps
    finally:
        for model in models.values():
            model.get_env().close()


def report(rates: dict[str, list[float]], steps: int) -> str:
    """The table: min and median steps/s of each environment, and the ratios."""
    ours, theirs = (rates[env_id] for env_id in ENVIRONMENTS)
    lines = [f"SB3 PPO, default hyperparameters, 1 env, learn({steps}) per round, "
             f"{len(ours)} rounds in turns",
             f"{'environment':<22}{'min steps/s':>14}{'median steps/s':>17}"]
    for env_id in ENVIRONMENTS:
        lines.append(f"{env_id:<22}{min(rates[env_id]):>14,.0f}"
                     f"{statistics.median(rates[env_id]):>17,.0f}")
    per_round = [mine / base for mine, base in zip(ours, theirs, strict=True)]
    lines.append(f"ratio rlenv / gymnasium: of the medians "
                 f"{statistics.median(ours) / statistics.median(theirs):.3f}; per round min "
                 f"{min(per_round):.3f}, median {statistics.median(per_round):.3f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5, help="timed rounds (after a warm-up)")
    parser.add_argument("--steps", type=int, default=4096,
                        help="timesteps per round, rounded up to whole rollout cycles")
    args = parser.parse_args(argv)
    try:
        import stable_baselines3  # noqa: F401
        import torch
    except ImportError as error:
        parser.exit(2, f"sb3_speed.py needs torch and stable-baselines3 (make sb3): {error}\n")
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads", flush=True)
    rates, steps = measure(args.rounds, args.steps)
    print(report(rates, steps))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
