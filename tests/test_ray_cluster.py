"""Servers on a fake Ray cluster of three nodes in this machine (``make test-ray``).

A head with no CPUs and two worker nodes: the pool spreads its servers over the workers, a
killed server actor and a removed node are survived, and nothing is left afterwards.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

ray = pytest.importorskip("ray")
cluster_utils = pytest.importorskip("ray.cluster_utils")

from conftest import wait_until  # noqa: E402
from ray_pools import alive, server_pids  # noqa: E402

from rlenv_client import RemoteVectorEnv  # noqa: E402
from rlenv_client.ray import RayServerPool  # noqa: E402

pytestmark = pytest.mark.ray

CARTPOLE = "examples.cartpole:CartPoleEnvironment"
STILL = np.zeros((16, 1), np.float32)


@pytest.fixture(scope="module")
def cluster() -> Iterator[Any]:
    """A head (0 CPUs) and two workers of 4 CPUs each, all in this machine."""
    fake = cluster_utils.Cluster(initialize_head=True, head_node_args={"num_cpus": 0})
    workers = [fake.add_node(num_cpus=4, resources={f"worker{index}": 1}) for index in range(2)]
    try:
        ray.init(address=fake.address, log_to_driver=False)
        fake.wait_for_nodes()
        yield fake, workers
    finally:
        ray.shutdown()
        fake.shutdown()


def node_ids(fake: Any) -> set[str]:
    return {
        node["NodeID"]
        for node in ray.nodes()
        if node["Alive"] and node["Resources"].get("CPU", 0) > 0
    }


def test_sixteen_cartpoles_in_four_servers_spread_over_two_nodes_survive_faults(
    cluster: tuple[Any, list[Any]],
) -> None:
    fake, workers = cluster
    with RayServerPool(
        CARTPOLE, servers=4, instances_per_server=4, progress=lambda _: None
    ) as pool:
        pids = server_pids(pool)
        assert len(set(pool.nodes)) == 2 and set(pool.nodes) == node_ids(fake)
        assert sorted(pool.nodes.count(node) for node in set(pool.nodes)) == [2, 2]
        with RemoteVectorEnv(pool=pool) as envs:
            assert envs.num_envs == 16
            envs.reset(seed=0)
            for _ in range(3):
                envs.step(STILL)

            # A server actor killed mid-episode: exactly its four sub-environments end.
            dying = ray.get(pool.actor(2).server_pid.remote())
            ray.kill(pool.actor(2), no_restart=False)
            wait_until(lambda: not alive(dying), "the killed actor's server lived on")
            _, _, terminated, truncated, info = envs.step(STILL)
            assert np.flatnonzero(truncated).tolist() == [8, 9, 10, 11]
            assert not terminated.any()
            assert "server lost" in info["server_restarted"][8]
            assert envs.step(STILL)[4]["frames"].tolist() == [4] * 8 + [0] * 4 + [4] * 4

            # A whole node removed: its servers come back on the other one.
            lost = [index for index, node in enumerate(pool.nodes) if node == workers[0].node_id]
            doomed = [pids[index] if index != 2 else server_pids(pool)[2] for index in lost]
            fake.remove_node(workers[0])
            wait_until(
                lambda: not any(alive(pid) for pid in doomed),
                "the removed node's servers lived on",
                seconds=60,
            )
            _, _, _, truncated, info = envs.step(STILL)
            expected = [env for index in lost for env in range(4 * index, 4 * index + 4)]
            assert np.flatnonzero(truncated).tolist() == expected
            assert set(pool.nodes) == {workers[1].node_id}
            envs.step(STILL)
            assert envs.step(STILL)[4]["frames"].tolist() == [4] * 16
        pids = server_pids(pool)
    wait_until(lambda: not any(alive(pid) for pid in pids), "a closed pool left servers")
