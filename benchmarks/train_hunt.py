"""Training the hunter of Hunt with SB3's PPO, the prey played by their heuristic in the server.

``python benchmarks/train_hunt.py [--envs N] [--train-steps T] [--episodes E] [--json PATH]``
(the sb3 extra; torch on one thread).

``examples/hunt`` has one hunter (a decision every 4 ticks) and up to eight prey that appear
and are caught during an episode (a decision every 8 ticks). The servers drive every prey by
its heuristic (``--policy Prey1=heuristic`` ... ``Prey8=heuristic``), so the hunter is the one
agent the client acts for. The trainer here is :class:`HunterView`, a ``gymnasium.Env`` over
a :class:`~rlenv_client.Client`, in SB3's ``DummyVecEnv`` (one server per env): it was written
before ``SB3VecEnv(agents="Hunter")`` stepped games whose agents come and go (it does now),
and it keeps the figures below comparable.

PPO trains for ``T`` env-steps (hunter decisions); then its deterministic policy and the
scripted hunter (``Hunter.heuristic``, the client calling it) each play ``E`` episodes over the
same seeds (1000 on). Printed per hunter: the return and the prey caught per episode, mean,
min and median over the seeds.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable
from typing import Any

import gymnasium
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv

from rlenv.examples.hunt import HUNTER, PREY, TARGET, Hunter
from rlenv_client import Client
from rlenv_client.launcher import ServerProcess

PREY_BY_HEURISTIC = [argument for name in PREY for argument in ("--policy", f"{name}=heuristic")]
TICK_PENALTY = 0.005
_hunter = Hunter()


class HunterView(gymnasium.Env):
    """The hunter's own env: a hunt server whose prey it drives, and a :class:`Client` to it.

    An answer that holds only a prey that left (the server answers the step in which an agent
    left, driven or not) is stepped past with an empty action: the hunter is not due then.
    """

    def __init__(self) -> None:
        self.server = ServerProcess(TARGET, args=PREY_BY_HEURISTIC)
        self.client = Client(self.server.host, self.server.port, timeout=30)
        self.observation_space = self.client.observation_space[HUNTER]
        self.action_space = self.client.action_space[HUNTER]

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the hunt; the hunter's first observation."""
        observation, info = self.client.reset(seed=seed, options=options)
        return observation[HUNTER], info

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Step to the hunter's next decision; its observation, reward and ends."""
        observation, _, terminated, truncated, info = self.client.step({HUNTER: action})
        frames = info["frames"]
        while HUNTER not in observation and not (terminated or truncated):
            observation, _, terminated, truncated, info = self.client.step({})
            frames += info["frames"]
        outcome = info["agents"][HUNTER]
        info["caught"] = round(outcome["reward"] + TICK_PENALTY * frames)
        return (
            observation[HUNTER],
            float(outcome["reward"]),
            terminated or outcome["terminated"],
            truncated or outcome["truncated"],
            info,
        )

    def close(self) -> None:
        """Close the client and end the server."""
        self.client.close()
        self.server.close()


def play(
    env: HunterView, act: Callable[[np.ndarray], np.ndarray], seeds: range
) -> dict[str, list[float]]:
    """The return and the prey caught in one episode per seed, the hunter played by ``act``."""
    returns, caught = [], []
    for seed in seeds:
        observation, _ = env.reset(seed=seed)
        total, catches = 0.0, 0
        while True:
            observation, reward, terminated, truncated, info = env.step(act(observation))
            total += reward
            catches += info["caught"]
            if terminated or truncated:
                break
        returns.append(total)
        caught.append(float(catches))
    return {"return": returns, "caught": caught}


def summary(values: list[float]) -> dict[str, float]:
    """Mean, min and median."""
    return {
        "mean": statistics.mean(values),
        "min": min(values),
        "median": statistics.median(values),
    }


def main() -> None:
    """Train, evaluate both hunters over the same seeds, print (and write) the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", type=int, default=4)
    parser.add_argument("--train-steps", type=int, default=200_000)
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None, metavar="PATH")
    args = parser.parse_args()
    torch.set_num_threads(1)

    envs = DummyVecEnv([HunterView] * args.envs)
    try:
        model = PPO("MlpPolicy", envs, seed=args.seed, n_steps=512, batch_size=256, verbose=0)
        start = time.perf_counter()
        model.learn(total_timesteps=args.train_steps)
        seconds = time.perf_counter() - start
    finally:
        envs.close()
    print(f"PPO: {model.num_timesteps} hunter decisions in {seconds:.0f} s", flush=True)

    seeds = range(1000, 1000 + args.episodes)
    env = HunterView()
    try:
        played = {
            "PPO": play(env, lambda o: model.predict(o, deterministic=True)[0], seeds),
            "scripted": play(env, _hunter.heuristic, seeds),
        }
    finally:
        env.close()
    figures: dict[str, Any] = {
        "train_steps": model.num_timesteps,
        "train_seconds": seconds,
        "episodes": args.episodes,
    }
    for name, results in played.items():
        figures[name] = {kind: summary(values) for kind, values in results.items()}
        for kind, values in figures[name].items():
            print(
                f"{name:8s} {kind:6s} per episode: mean {values['mean']:6.2f}, "
                f"min {values['min']:6.2f}, median {values['median']:6.2f}"
            )
    if args.json:
        with open(args.json, "w") as out:
            json.dump(figures, out, indent=1)


if __name__ == "__main__":
    main()
