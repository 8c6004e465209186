"""Servers on Ray, on one node: a pool, vectors over it, faults, leases (``make test-ray``)."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable, Iterator
from typing import Any

import gymnasium
import numpy as np
import pytest

ray = pytest.importorskip("ray")

from conftest import wait_until  # noqa: E402
from ray_pools import alive, server_pids  # noqa: E402

from rlenv_client import RemoteVectorEnv  # noqa: E402
from rlenv_client.ray import RayServerPool, ServerLost  # noqa: E402

pytestmark = pytest.mark.ray

CARTPOLE = "examples.cartpole:CartPoleEnvironment"


@pytest.fixture(scope="module", autouse=True)
def cluster() -> Iterator[None]:
    """A single-node Ray for this module (2 CPUs, no dashboard)."""
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        yield
    finally:
        ray.shutdown()


@pytest.fixture
def pool() -> Iterator[RayServerPool]:
    """Two servers of two CartPoles; afterwards, none of its server processes may be left."""
    with RayServerPool(
        CARTPOLE, servers=2, instances_per_server=2, cpus_per_server=0.5, progress=lambda _: None
    ) as servers:
        yield servers
        pids = server_pids(servers)
    wait_until(lambda: not any(alive(pid) for pid in pids), "a closed pool left servers")


def pushes(steps: int, envs: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1, 1, (steps, envs, 1)).astype(np.float32)


def trajectory(envs: Any, actions: np.ndarray) -> list[tuple[bytes, ...]]:
    observations, _ = envs.reset(seed=3)
    rows = [(observations.tobytes(),)]
    for action in actions:
        observations, rewards, terminated, truncated, _ = envs.step(action)
        rows.append(
            (observations.tobytes(), rewards.tobytes(), terminated.tobytes(), truncated.tobytes())
        )
    return rows


def test_a_vector_over_a_pool_steps_as_local_servers_do(pool: RayServerPool) -> None:
    host = ray.util.get_node_ip_address()
    addresses = pool.addresses()
    assert [address.rpartition(":")[0] for address in addresses] == [host, host]  # its node's
    assert all(node is not None for node in pool.nodes)
    actions = pushes(40, 4)
    with RemoteVectorEnv(pool=pool) as remote:
        assert remote.num_envs == 4
        on_ray = trajectory(remote, actions)
    with RemoteVectorEnv(4, CARTPOLE, instances_per_server=2) as local:
        assert trajectory(local, actions) == on_ray


def test_make_vec_over_a_pool(pool: RayServerPool) -> None:
    envs = gymnasium.make_vec("rlenv/CartPole-v0", num_envs=4, pool=pool)
    try:
        envs.reset(seed=0)
        assert envs.step(np.zeros((4, 1), np.float32))[0].shape == (4, 5)
    finally:
        envs.close()
    with pytest.raises(ValueError, match="num_envs=3, but the servers given host 4"):
        RemoteVectorEnv(3, pool=pool)


def test_the_pools_servers_require_its_token(pool: RayServerPool) -> None:
    from rlenv_client import Client, RemoteError

    host, _, port = pool.address(0).rpartition(":")
    with pytest.raises(RemoteError) as refused:
        Client(host, int(port), token="guess")
    assert refused.value.code == "unauthorized"
    with Client(host, int(port), token=pool.token) as client:
        assert client.hello.instances == 2


def lost_and_back(pool: RayServerPool, kill: Callable[[], int]) -> None:
    """Kill server 1 (by ``kill``, which returns a pid that dies) mid-episode: exactly its two
    sub-environments end as truncated, and stepping goes on."""
    with RemoteVectorEnv(pool=pool) as envs:
        envs.reset(seed=0)
        still = np.zeros((4, 1), np.float32)
        for _ in range(3):
            envs.step(still)
        before = pool.address(1)
        dying = kill()
        wait_until(lambda: not alive(dying), "the killed process lived on")
        _, rewards, terminated, truncated, info = envs.step(still)
        assert truncated.tolist() == [False, False, True, True]
        assert not terminated.any() and rewards.tolist()[2:] == [0.0, 0.0]
        assert "server lost" in info["server_restarted"][2]
        assert info["_server_restarted"].tolist() == [False, False, True, True]
        assert pool.address(1) != before  # found again, on a new port
        _, _, _, truncated, info = envs.step(still)  # the autoreset, then on as usual
        assert not truncated.any() and info["frames"].tolist() == [4, 4, 0, 0]
        assert envs.step(still)[4]["frames"].tolist() == [4, 4, 4, 4]


def test_a_killed_server_process_is_restarted_by_its_actor(pool: RayServerPool) -> None:
    def kill() -> int:
        pid = ray.get(pool.actor(1).server_pid.remote())
        os.kill(pid, signal.SIGKILL)
        return pid

    lost_and_back(pool, kill)


def test_a_killed_actor_is_restarted_by_ray(pool: RayServerPool) -> None:
    def kill() -> int:
        pid = ray.get(pool.actor(1).server_pid.remote())  # dies with its actor (lifeline)
        ray.kill(pool.actor(1), no_restart=False)
        return pid

    lost_and_back(pool, kill)


def test_past_the_restart_budget_the_error_names_the_server(pool: RayServerPool) -> None:
    with RemoteVectorEnv(pool=pool, max_restarts=1) as envs:
        envs.reset(seed=0)
        still = np.zeros((4, 1), np.float32)
        for _ in range(2):
            pid = ray.get(pool.actor(0).server_pid.remote())
            os.kill(pid, signal.SIGKILL)
            wait_until(lambda pid=pid: not alive(pid), "the killed server lived on")
            if envs.sessions[0].restarts == 0:
                assert envs.step(still)[3].tolist() == [True, True, False, False]
                continue
            with pytest.raises(
                ServerLost,
                match=r"server 0 of pool examples\.cartpole:"
                r"CartPoleEnvironment on node \w+ lost .* after "
                r"1 restarts; max_restarts is 1",
            ):
                envs.step(still)


def test_a_named_pool_is_leased_out_and_given_back() -> None:
    with RayServerPool(
        CARTPOLE,
        servers=2,
        instances_per_server=1,
        cpus_per_server=0.5,
        name="leased",
        progress=lambda _: None,
    ) as pool:
        pids = server_pids(pool)
        first = RayServerPool.lease("leased", servers=1)
        with (
            RayServerPool.lease("leased", servers=1) as second,
            RemoteVectorEnv(pool=second) as envs,
        ):
            assert envs.num_envs == 1 and envs.reset(seed=0)[0].shape == (1, 5)
            with pytest.raises(ValueError, match="1 servers asked, 0 of 2 free"):
                RayServerPool.lease("leased", servers=1)
        third = RayServerPool.lease("leased", servers=1)  # the second was given back
        assert first.address(0) != third.address(0)
        first.release()
        third.release()
    wait_until(lambda: not any(alive(pid) for pid in pids), "a closed pool left servers")
    with pytest.raises(ValueError, match="no rlenv pool called 'leased'"):
        RayServerPool.lease("leased", servers=1)
