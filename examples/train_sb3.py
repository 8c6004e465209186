"""Train Stable-Baselines3's PPO on an rlenv id, exactly as SB3 users train any gymnasium id.

    pip install 'rlenv[sb3]'      # on a machine without CUDA, install a CPU torch first
    python -m examples.train_sb3 [--timesteps 40000] [--envs 4]
    python -m examples.train_sb3 --env rlenv/SeekerPixels-v0 --policy CnnPolicy   # from pixels

The environments come from ``gymnasium.make(ENV)`` through SB3's own ``make_vec_env``: each one
is a server subprocess, created and ended by rlenv. Prints the mean return of the untrained and
the trained policy over the same evaluation seeds.
"""

from __future__ import annotations

import argparse
import logging

import gymnasium as gym
import numpy as np

import rlenv_client

ENV_ID = "rlenv/CartPole-v0"


def evaluate(model: object, episodes: int, seed: int = 10_000, env_id: str = ENV_ID) -> float:
    """Mean return of ``model``'s deterministic policy over ``episodes`` seeded episodes."""
    env = gym.make(env_id)
    returns = []
    try:
        for episode in range(episodes):
            observation, _ = env.reset(seed=seed + episode)
            total, done = 0.0, False
            while not done:
                action, _ = model.predict(observation, deterministic=True)  # type: ignore[attr-defined]
                observation, reward, terminated, truncated, _ = env.step(action)
                total += float(reward)
                done = terminated or truncated
            returns.append(total)
    finally:
        env.close()
    return float(np.mean(returns))


def main() -> None:
    """Train, then print the returns before and after."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--timesteps", type=int, default=40_000)
    parser.add_argument("--envs", type=int, default=4)
    parser.add_argument("--episodes", type=int, default=5, help="evaluation episodes")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--env", default=ENV_ID, help=f"gymnasium id (default {ENV_ID})")
    parser.add_argument("--policy", default="MlpPolicy", help="SB3 policy, e.g. CnnPolicy")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    gym.register_envs(rlenv_client)

    envs = make_vec_env(args.env, n_envs=args.envs, seed=args.seed)
    try:
        model = PPO(args.policy, envs, seed=args.seed, verbose=0, n_steps=256, batch_size=64)
        before = evaluate(model, args.episodes, env_id=args.env)
        print(f"untrained policy: mean return {before:.0f}", flush=True)
        model.learn(total_timesteps=args.timesteps, progress_bar=False)
        after = evaluate(model, args.episodes, env_id=args.env)
        print(f"after {args.timesteps} steps of PPO: mean return {after:.0f}", flush=True)
    finally:
        envs.close()


if __name__ == "__main__":
    main()
