"""Training the chaser of Tag with SB3 straight from the multi-agent env, against a rewrite.

``python benchmarks/train_one_agent.py [--instances N] [--rounds R] [--round-steps S]
[--train-steps T] [--episodes E] [--json PATH]`` (the sb3 extra; torch on one thread).

**Rate.** ``examples/tag`` has one chaser and two runners. ``SB3VecEnv(N, tag, agents="Chaser")``
trains the chaser from it, the runners driven by their heuristics inside the servers
(``--policy Runner1=heuristic``). Its baseline is the rewrite a user had to write before:
``examples/tag/scripted.py``, the same game as one single-agent env whose runners are scripted
by the same heuristics (``tests/test_agent_vector.py`` checks that both give the chaser
bit-identical observations, rewards and ends). A third figure drives the runners by the same
heuristics called in the trainer (``others={"Runner1": callable, ...}``). All three lay their
servers out as ``SB3VecEnv`` does by default (one server per core but the trainer's). In each
round every variant, in turns (the
order rotating from round to round), runs PPO for ``S`` env-steps (``learn``, collection and
updates, construction excluded) and then steps ``S`` env-steps of random actions without
learning; the script prints the min and median env-steps/s of each and the ratio of medians
to the rewrite's.

**Learning.** PPO then trains the chaser from the multi-agent env for ``T`` env-steps; its
deterministic policy and a random chaser each play ``E`` episodes (seeds 1000 on, the same for
both, runners by their heuristics, 300 steps at most): the mean return and tags per episode.
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

from rlenv.examples.tag import CHASER, RUNNERS, Runner
from rlenv.examples.tag import TARGET as TAG
from rlenv.examples.tag.scripted import TARGET as SCRIPTED
from rlenv_client.sb3 import SB3VecEnv

MAX_STEPS = 300
_runner = Runner("Runner")


def run_away(observation: np.ndarray) -> np.ndarray:
    """The runners' heuristic, called in the trainer."""
    return _runner.heuristic(observation)


def _variants(instances: int) -> dict[str, Callable[[], SB3VecEnv]]:
    def make(target: str, **options: Any) -> Callable[[], SB3VecEnv]:
        return lambda: SB3VecEnv(instances, target, max_episode_steps=MAX_STEPS, **options)

    return {
        "rewrite (scripted runners)": make(SCRIPTED),
        "multi-agent, runners served (heuristic)": make(TAG, agents=CHASER),
        "multi-agent, runners called in the trainer": make(
            TAG, agents=CHASER, others=dict.fromkeys(RUNNERS, run_away)
        ),
    }


def _rates(make: Callable[[], SB3VecEnv], steps: int, seed: int) -> tuple[float, float]:
    """Env-steps/s of PPO learning ``steps`` steps, then of ``steps`` random steps."""
    envs = make()
    try:
        model = PPO("MlpPolicy", envs, seed=seed, n_steps=256, batch_size=256, verbose=0)
        start = time.perf_counter()
        model.learn(total_timesteps=steps)
        learning = model.num_timesteps / (time.perf_counter() - start)
        envs.reset()
        rng = np.random.default_rng(seed)
        rounds = max(1, steps // envs.num_envs)
        start = time.perf_counter()
        for _ in range(rounds):
            envs.step_async(rng.uniform(-1, 1, (envs.num_envs, 2)).astype(np.float32))
            envs.step_wait()
        stepping = rounds * envs.num_envs / (time.perf_counter() - start)
        return learning, stepping
    finally:
        envs.close()


def _play(
    envs: SB3VecEnv, act: Callable[[np.ndarray], np.ndarray], episodes: int, seed: int
) -> tuple[float, float]:
    """Mean return and tags per episode of the chaser played by ``act``, episode by episode."""
    returns, tags = [], []
    for episode in range(episodes):
        envs.seed(seed + episode)
        observations = envs.reset()
        total, caught = 0.0, 0
        while True:
            envs.step_async(act(observations))
            observations, rewards, dones, _ = envs.step_wait()
            total += float(rewards[0])
            caught += int(rewards[0] > 5)
            if dones[0]:
                break
        returns.append(total)
        tags.append(caught)
    return statistics.mean(returns), statistics.mean(tags)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--instances", type=int, default=4)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--round-steps", type=int, default=4096)
    parser.add_argument("--train-steps", type=int, default=150_000)
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--json", default=None, metavar="PATH")
    args = parser.parse_args()
    torch.set_num_threads(1)

    variants = _variants(args.instances)
    names = list(variants)
    learning: dict[str, list[float]] = {name: [] for name in names}
    stepping: dict[str, list[float]] = {name: [] for name in names}
    for round_number in range(args.rounds):
        order = names[round_number % len(names) :] + names[: round_number % len(names)]
        for name in order:
            learned, stepped = _rates(variants[name], args.round_steps, round_number)
            learning[name].append(learned)
            stepping[name].append(stepped)
            print(
                f"round {round_number + 1}: {name}: PPO {learned:7.0f}, stepping "
                f"{stepped:7.0f} env-steps/s",
                flush=True,
            )

    figures: list[dict[str, Any]] = []
    print(f"\n{args.instances} instances, {args.rounds} rounds of {args.round_steps} env-steps")
    for kind, rates in (("PPO learning", learning), ("stepping (random actions)", stepping)):
        print(f"{kind}: env-steps/s, min / median, ratio of medians to the rewrite's")
        for name in names:
            baseline = names[0]
            ratio = statistics.median(rates[name]) / statistics.median(rates[baseline])
            print(
                f"  {name:45s} {min(rates[name]):7.0f} / {statistics.median(rates[name]):7.0f}"
                f"   x{ratio:.2f} of '{baseline}'"
            )
            figures.append(
                {
                    "name": f"{kind}: {name}",
                    "min": min(rates[name]),
                    "median": statistics.median(rates[name]),
                    "unit": "env-steps/s",
                    "baseline_name": baseline,
                    "ratio": ratio,
                }
            )

    envs = SB3VecEnv(args.instances, TAG, agents=CHASER, max_episode_steps=MAX_STEPS)
    try:
        model = PPO("MlpPolicy", envs, seed=0, n_steps=256, batch_size=256, verbose=0)
        start = time.perf_counter()
        model.learn(total_timesteps=args.train_steps)
        seconds = time.perf_counter() - start
    finally:
        envs.close()
    evaluation = SB3VecEnv(1, TAG, agents=CHASER, max_episode_steps=MAX_STEPS)
    try:
        rng = np.random.default_rng(0)
        trained = _play(
            evaluation, lambda obs: model.predict(obs, deterministic=True)[0], args.episodes, 1000
        )
        random = _play(
            evaluation,
            lambda obs: rng.uniform(-1, 1, (1, 2)).astype(np.float32),
            args.episodes,
            1000,
        )
    finally:
        evaluation.close()
    print(
        f"\nthe chaser trained from the multi-agent env for {args.train_steps} env-steps "
        f"({seconds:.0f} s), {args.episodes} episodes each:"
    )
    print(f"  trained: return {trained[0]:7.2f}, tags per episode {trained[1]:.2f} of 2")
    print(f"  random:  return {random[0]:7.2f}, tags per episode {random[1]:.2f} of 2")
    figures.append(
        {
            "name": "trained chaser: mean return",
            "value": trained[0],
            "baseline_name": "random chaser",
            "baseline": random[0],
            "tags": trained[1],
            "baseline_tags": random[1],
            "train_steps": args.train_steps,
            "episodes": args.episodes,
        }
    )
    if args.json:
        with open(args.json, "w") as file:
            json.dump(figures, file, indent=1)


if __name__ == "__main__":
    main()
