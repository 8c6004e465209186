"""Env-steps/s against the number of servers, on a fake Ray cluster and on local servers.

``python benchmarks/ray_scale.py [--rounds R] [--steps N]`` (needs the ray extra: ``make
test-ray`` installs it). For each count of servers (each hosting ``INSTANCES`` CartPoles), a
``RemoteVectorEnv`` over a :class:`~rlenv_client.ray.RayServerPool` on a fake cluster (a head
with no CPUs and two worker nodes, all in this machine) and one over the same count of local
servers step in turns, on random actions, with autoreset; it prints the min and median
env-steps/s of each and the ratio of the medians. Both reach their servers over loopback TCP on
one machine, so the ratio is the cost of going through Ray (placement, addresses), not of a
network.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import ray
from ray.cluster_utils import Cluster

from rlenv_client import RemoteVectorEnv
from rlenv_client.ray import RayServerPool

CARTPOLE = "examples.cartpole:CartPoleEnvironment"
INSTANCES = 8
SERVERS = (1, 2, 4)


def rate(envs: RemoteVectorEnv, steps: int, actions: np.ndarray) -> float:
    """Env-steps per second of ``steps`` vector steps."""
    started = time.perf_counter()
    for index in range(steps):
        envs.step(actions[index % len(actions)])
    return steps * envs.num_envs / (time.perf_counter() - started)


def main() -> None:
    """Measure and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=5, help="timed rounds of each, in turns")
    parser.add_argument("--steps", type=int, default=200, help="vector steps per round")
    args = parser.parse_args()
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0})
    for _ in range(2):
        cluster.add_node(num_cpus=2)
    ray.init(address=cluster.address, log_to_driver=False)
    cluster.wait_for_nodes()
    print(
        f"{'servers':>8}{'envs':>6}{'Ray pool min':>14}{'median':>10}"
        f"{'local min':>12}{'median':>10}{'pool / local':>14}   (env-steps/s)"
    )
    try:
        for servers in SERVERS:
            count = servers * INSTANCES
            actions = np.random.default_rng(0).uniform(-1, 1, (64, count, 1)).astype(np.float32)
            with (
                RayServerPool(
                    CARTPOLE, servers, INSTANCES, cpus_per_server=0.5, progress=lambda _: None
                ) as pool,
                RemoteVectorEnv(pool=pool) as on_ray,
                RemoteVectorEnv(count, CARTPOLE, instances_per_server=INSTANCES) as local,
            ):
                rates: dict[str, list[float]] = {"pool": [], "local": []}
                for envs in (on_ray, local):
                    envs.reset(seed=0)
                    rate(envs, args.steps // 4, actions)  # warm-up
                for _ in range(args.rounds):
                    rates["pool"].append(rate(on_ray, args.steps, actions))
                    rates["local"].append(rate(local, args.steps, actions))
            pool_rates, local_rates = rates["pool"], rates["local"]
            print(
                f"{servers:>8}{count:>6}{min(pool_rates):>14,.0f}"
                f"{statistics.median(pool_rates):>10,.0f}{min(local_rates):>12,.0f}"
                f"{statistics.median(local_rates):>10,.0f}"
                f"{statistics.median(pool_rates) / statistics.median(local_rates):>14.2f}"
            )
    finally:
        ray.shutdown()
        cluster.shutdown()


if __name__ == "__main__":
    main()
