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
much of a trainer's time the environment costs, not how fast two equal simulations run. A third
model trains on the hand-written CartPole server (``examples.handwritten``: the same pymunk
work, a raw msgpack client in a ``gymnasium.Env``): the floor of any environment served over a
socket on the same machine, so that rlenv's ratio can be read against it. A fourth trains on
``rlenv/CartPole-v1``, gymnasium's interface served by rlenv (a discrete action, one pymunk tick
per step): like for like with CartPole-v1 but for the physics engine and the socket. rlenv's
environments step through a shared-memory lane (the default on one machine); a fifth model
trains on ``rlenv/CartPole-v0`` on the socket alone (``shared_memory=False``), to show what the
lane gives.
Threads: torch's default (``torch.set_num_threads`` is not called); on a 2-core machine, run
with ``OMP_NUM_THREADS=1`` too, since torch's spinning threads take the servers' core.
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import gymnasium as gym
import numpy as np

import rlenv_client  # noqa: F401  (registers rlenv/CartPole-v0)
from rlenv.examples.cartpole import CartPoleAgent
from rlenv_tools._bench import HandWrittenServer

ON_SOCKET = "rlenv/CartPole-v0 on the socket"
ENVIRONMENTS = (
    "rlenv/CartPole-v0",
    "CartPole-v1",
    "handwritten/CartPole-v0",
    "rlenv/CartPole-v1",
    ON_SOCKET,
)
MADE_AS = {ON_SOCKET: ("rlenv/CartPole-v0", {"shared_memory": False})}
"""How an environment of :data:`ENVIRONMENTS` is made, when not by its name alone."""


class HandWrittenCartPole(gym.Env):
    """The hand-written CartPole server (``python -m examples.handwritten``) as a gymnasium env,
    behind the raw client ``rlenv bench`` measures it with."""

    action_space = CartPoleAgent.action_space
    observation_space = CartPoleAgent.observation_space

    def __init__(self) -> None:
        self.server = HandWrittenServer()

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        reply = self.server.call({"reset": {} if seed is None else {"seed": seed}})
        return np.frombuffer(reply["observation"], np.float32).copy(), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        return self.server.step(np.asarray(action, np.float32))

    def close(self) -> None:
        self.server.close()


gym.register("handwritten/CartPole-v0", entry_point=HandWrittenCartPole, max_episode_steps=500)


def make_model(name: str) -> Any:
    """A PPO model with default hyperparameters on one environment of :data:`ENVIRONMENTS`."""
    from stable_baselines3 import PPO

    env_id, kwargs = MADE_AS.get(name, (name, {}))
    return PPO("MlpPolicy", gym.make(env_id, **kwargs), seed=0, verbose=0)


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
    ours, native, floor, like, socket = (rates[env_id] for env_id in ENVIRONMENTS)
    lines = [
        f"SB3 PPO, default hyperparameters, 1 env, learn({steps}) per round, "
        f"{len(ours)} rounds in turns",
        f"{'environment':<32}{'min steps/s':>14}{'median steps/s':>17}",
    ]
    for env_id in ENVIRONMENTS:
        lines.append(
            f"{env_id:<32}{min(rates[env_id]):>14,.0f}{statistics.median(rates[env_id]):>17,.0f}"
        )
    for name, mine, base in (
        ("rlenv / gymnasium", ours, native),
        ("hand-written / gymnasium", floor, native),
        ("rlenv / hand-written", ours, floor),
        ("rlenv/CartPole-v1 / gymnasium", like, native),
        ("rlenv on the socket / gymnasium", socket, native),
        ("rlenv through shared memory / on the socket", ours, socket),
    ):
        per_round = [a / b for a, b in zip(mine, base, strict=True)]
        lines.append(
            f"ratio {name}: of the medians "
            f"{statistics.median(mine) / statistics.median(base):.3f}; per round min "
            f"{min(per_round):.3f}, median {statistics.median(per_round):.3f}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5, help="timed rounds (after a warm-up)")
    parser.add_argument(
        "--steps",
        type=int,
        default=4096,
        help="timesteps per round, rounded up to whole rollout cycles",
    )
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
