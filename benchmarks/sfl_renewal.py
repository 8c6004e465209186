"""Does SFL's full buffer take new levels? Random actions on rlenv/Plinko-v0, 1 and 4 rollouts.

``python benchmarks/sfl_renewal.py [--steps S] [--envs N] [--rollouts 1 4] [--seed K]``

Plays ``--steps`` env-steps of uniformly random actions on ``rlenv/Plinko-v0`` (its default
difficulty) in a ``CurriculumVectorEnv`` configured as ``curriculum_experiment.py``'s SFL
(``score="learnability"``, ``LevelSampler(128, replay_prob=0.5, prioritization="topk", k=32,
staleness_coeff=0)``), once per value of ``rollouts_per_level``, and prints for each: the
episodes and replays played, the env-step at which the buffer filled, the levels offered to the
full buffer and how many entered it, and how many buffered levels end with a score above 0.
No training: the policy is random, so this measures the machinery, not a curriculum. 100,000
env-steps per value take about 35 s on the 2-core development machine.
"""

from __future__ import annotations

import argparse
from typing import Any

import gymnasium
import numpy as np

import rlenv_client  # noqa: F401  (registers rlenv/Plinko-v0)
from rlenv_client.curriculum import CurriculumVectorEnv, Level, LevelSampler

CAPACITY = 128
"""The buffer, as in curriculum_experiment.py."""


def run(rollouts: int, env_steps: int, num_envs: int, seed: int) -> dict[str, Any]:
    """One run; returns its counts."""
    sampler = LevelSampler(
        CAPACITY, replay_prob=0.5, prioritization="topk", k=32, staleness_coeff=0.0, seed=seed
    )
    counts = {"offered to the full buffer": 0, "entered it": 0}
    insert = sampler.insert

    def counting_insert(level: Level, score: float) -> int | None:
        full = len(sampler) == sampler.capacity
        level_id = insert(level, score)
        if full:
            counts["offered to the full buffer"] += 1
            counts["entered it"] += level_id is not None
        return level_id

    sampler.insert = counting_insert  # type: ignore[method-assign]
    envs = gymnasium.make_vec("rlenv/Plinko-v0", num_envs=num_envs)
    wrapper = CurriculumVectorEnv(envs, sampler, seed=seed, rollouts_per_level=rollouts)
    rng = np.random.default_rng(seed)
    episodes = replays = 0
    filled_at = None
    try:
        wrapper.reset()
        for step in range(env_steps // num_envs):
            actions = rng.uniform(-1, 1, (num_envs, 1)).astype(np.float32)
            _, _, terminated, truncated, info = wrapper.step(actions)
            episodes += int((terminated | truncated).sum())
            if "_replayed" in info:
                replays += int(info["replayed"][info["_replayed"]].sum())
            if filled_at is None and len(sampler) == sampler.capacity:
                filled_at = (step + 1) * num_envs
    finally:
        wrapper.close()
    learnable = sum(sampler.score(level_id) > 0 for level_id in sampler.weights())
    return {
        "rollouts_per_level": rollouts,
        "episodes": episodes,
        "replays": replays,
        "buffer full at env-step": filled_at,
        **counts,
        f"buffered levels scoring > 0 (of {CAPACITY})": learnable,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=100_000, help="env-steps per run")
    parser.add_argument("--envs", type=int, default=8, help="sub-environments")
    parser.add_argument("--rollouts", type=int, nargs="+", default=[1, 4])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    for rollouts in args.rollouts:
        result = run(rollouts, args.steps, args.envs, args.seed)
        print(", ".join(f"{key}: {value}" for key, value in result.items()), flush=True)


if __name__ == "__main__":
    main()
