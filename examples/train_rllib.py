"""Train RLlib's PPO (new API stack) on rlenv's CartPole until its mean return reaches a goal.

    pip install 'ray[rllib]' torch        # on a machine without CUDA, a CPU torch first
    python -m examples.train_rllib [--goal 400] [--max-iterations 40] [--env-runners 1]

Each EnvRunner samples from a :class:`~rlenv_client.vector.RemoteVectorEnv` built by
:mod:`rlenv_client.rllib` (``--envs`` sub-environments, in servers the EnvRunner starts and
ends). Episodes last at most 500 steps (the registered ``max_episode_steps``) and earn up to 4
per step (one per physics tick, 4 ticks per step), so returns go up to 2000. Prints the mean
return of the last 100 episodes after every iteration and stops when it reaches ``--goal``, or
after ``--max-iterations`` (exit status 1). PPO keeps RLlib's defaults (4000 steps an
iteration); seeded, so a run repeats the same returns. On the 2-core development machine: 423
after 9 iterations (36k steps), 65-90 s of training; ``--env-runners 0`` (sampling in this
process): 493 after 8 iterations (32k steps), 58 s.

Ray starts with ``address="local"``: a plain ``ray.init()`` joins the cluster named in
``/tmp/ray/ray_current_cluster`` (left by ``ray start`` or ``ray.cluster_utils.Cluster``), and
hangs (over 90 s here) when that cluster is gone.
"""

from __future__ import annotations

import argparse
import logging
import time

ENV_ID = "rlenv/CartPole-v0"


def main() -> int:
    """Train, printing progress; exit status 0 when the goal was reached."""
    import ray
    import torch
    from ray.rllib.algorithms.ppo import PPOConfig

    from rlenv_client.rllib import config_for

    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--env", default=ENV_ID, help=f"rlenv id or MODULE:CLASS ({ENV_ID})")
    parser.add_argument("--goal", type=float, default=400.0, help="mean return to reach")
    parser.add_argument("--max-iterations", type=int, default=40)
    parser.add_argument(
        "--env-runners", type=int, default=1, help="EnvRunner actors (0: sample in this process)"
    )
    parser.add_argument("--envs", type=int, default=8, help="sub-environments per EnvRunner")
    parser.add_argument("--servers", type=int, default=1, help="servers per EnvRunner")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    # One torch thread in this process (the learner, and the sampler with --env-runners 0): on
    # a small machine, threads that spin while servers or other processes want the cores made
    # iterations up to 8x slower here. Ray already gives its EnvRunner actors one thread each.
    torch.set_num_threads(1)

    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        config = config_for(
            PPOConfig(),
            args.env,
            num_env_runners=args.env_runners,
            num_envs_per_env_runner=args.envs,
            instances_per_server=-(-args.envs // args.servers),
        ).debugging(seed=args.seed)
        algo = config.build_algo()
        start = time.perf_counter()
        mean_return, steps = float("nan"), 0
        try:
            for iteration in range(1, args.max_iterations + 1):
                result = algo.train()
                mean_return = float(result["env_runners"].get("episode_return_mean", "nan"))
                steps = int(result.get("num_env_steps_sampled_lifetime", 0))
                print(
                    f"iteration {iteration:3d}  {steps:7d} steps  "
                    f"{time.perf_counter() - start:6.1f} s  mean return {mean_return:7.1f}",
                    flush=True,
                )
                if mean_return >= args.goal:
                    break
        finally:
            algo.stop()
    finally:
        ray.shutdown()
    reached = mean_return >= args.goal
    print(
        f"{'reached' if reached else 'did not reach'} the goal of {args.goal:.0f}: mean return "
        f"{mean_return:.1f} after {steps} steps in {time.perf_counter() - start:.1f} s",
        flush=True,
    )
    return 0 if reached else 1


if __name__ == "__main__":
    raise SystemExit(main())
