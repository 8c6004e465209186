r"""Environment servers on a Ray cluster: placed, named and restarted by Ray, stepped over TCP.

Ray places processes on a cluster's machines and restarts them; rlenv steps over its own TCP
(a step through a Ray actor call costs about a millisecond, a direct round trip a tenth of
that). So a :class:`RayServerPool` starts one Ray actor per server, spread over the cluster's
nodes by a placement group, and each actor owns one ``rlenv serve`` subprocess bound to its
node's address (never ``0.0.0.0``) with a token the pool generates. Clients ask the pool for a
server's address and connect to it directly::

    import ray
    from rlenv_client import RemoteVectorEnv
    from rlenv_client.ray import RayServerPool

    ray.init()                                    # or ray.init(address="auto") on a cluster
    with RayServerPool("examples.cartpole:CartPoleEnvironment", servers=4,
                       instances_per_server=4) as pool, \
            RemoteVectorEnv(pool=pool) as envs:   # 16 CartPoles, stepped in columns
        observations, infos = envs.reset(seed=0)
        ...

``gymnasium.make_vec("rlenv/CartPole-v0", num_envs=16, pool=pool)`` builds the same vector.

**Faults.** A server lost mid-episode (its process, its actor, or its whole node) comes back
through Ray: the actor restarts its server, or Ray restarts the actor (``max_restarts``), on
another node if its own is gone. Nothing caches an address: the vector asks the pool again, so
it finds the server wherever it came back, with a new port. The interrupted episodes end as
truncated with ``info["server_restarted"]``, as for local servers; nothing is sent twice. Past
the restart budget, :class:`ServerLost` names the server and its node.

**Sharing a pool.** A pool given a ``name`` can be leased from any process of the cluster (an
RLlib EnvRunner, say): ``RayServerPool.lease(name, servers=2)`` returns a :class:`PoolLease`
holding two of its servers until it is released; ``RemoteVectorEnv(pool=lease)`` steps them.

**Security.** Ray's own ports run whatever code reaches them: on a cluster, enable Ray's token
authentication (``RAY_AUTH_MODE=token``, the default since Ray 2.52 for local clusters). Every
rlenv server of a pool requires the pool's token, which travels in the actor's arguments and
never on a command line.
"""

from __future__ import annotations

import logging
import os
import secrets
import time
from collections.abc import Callable, Sequence
from typing import Any, cast

import ray
from ray.util.placement_group import placement_group, remove_placement_group
from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

from rlenv_client.launcher import ServerProcess
from rlenv_client.session import ServerLost

__all__ = ["PoolLease", "RayServerPool", "ServerLost"]

logger = logging.getLogger(__name__)

_REGISTRY = "rlenv-pool:{}"  # the name of a named pool's registry actor


@ray.remote
class ServerActor:
    """One ``rlenv serve`` subprocess on this actor's node, tied to the actor's life.

    The server exits when the actor's process does (its lifeline), so Ray's restart of the
    actor is the server's restart too.
    """

    def __init__(
        self,
        target: str,
        instances: int,
        token: str,
        server_args: Sequence[str],
        startup_timeout: float,
    ) -> None:
        self._start_args = (target, instances, token, tuple(server_args), startup_timeout)
        self._server = self._start()

    def _start(self) -> ServerProcess:
        target, instances, token, server_args, startup_timeout = self._start_args
        return ServerProcess(
            target,
            host=ray.util.get_node_ip_address(),
            startup_timeout=startup_timeout,
            args=["--instances", str(instances), *server_args],
            env={"RLENV_TOKEN": token},
        )

    def address(self) -> tuple[str, str]:
        """``HOST:PORT`` of the server, started anew if it died; and this node's id."""
        if not self._server.is_alive():
            self._server.close(timeout=1.0)
            self._server = self._start()
        return self._server.address, ray.get_runtime_context().get_node_id()

    def server_pid(self) -> int:
        """The server's process id (tests kill it)."""
        return self._server.pid

    def actor_pid(self) -> int:
        """This actor's process id (tests kill it)."""
        return os.getpid()

    def close(self) -> None:
        """Stop the server."""
        self._server.close(timeout=2.0)


@ray.remote(num_cpus=0)
class _Registry:
    """A named pool's servers, and which of them are leased."""

    def __init__(self, actors: list[Any], token: str, instances: int) -> None:
        self._actors = actors
        self._token = token
        self._instances = instances
        self._free = list(range(len(actors)))

    def lease(self, servers: int) -> tuple[list[int], list[Any], str, int]:
        if servers > len(self._free):
            raise ValueError(
                f"{servers} servers asked, {len(self._free)} of {len(self._actors)} free"
            )
        taken, self._free = self._free[:servers], self._free[servers:]
        return taken, [self._actors[index] for index in taken], self._token, self._instances

    def release(self, indices: list[int]) -> None:
        self._free = sorted(set(self._free) | set(indices))


class _Servers:
    """What pools and leases share: server actors, their token, and where each one is."""

    def __init__(
        self, actors: list[Any], token: str, instances_per_server: int, labels: list[str]
    ) -> None:
        self._actors = actors
        self.token = token
        self.instances_per_server = instances_per_server
        self._labels = labels
        self._nodes: dict[int, str] = {}  # the node each server was last seen on

    @property
    def servers(self) -> int:
        """How many servers."""
        return len(self._actors)

    def address(self, index: int, timeout: float = 120.0) -> str:
        """``HOST:PORT`` of server ``index``, asked of its actor now (never cached).

        Waits while Ray restarts the actor (on another node if its own is gone).

        Raises:
            ServerLost: the actor is gone for good (its restarts are spent) or did not answer
                within ``timeout``.
        """
        try:
            address, node = ray.get(self._actors[index].address.remote(), timeout=timeout)
        except (ray.exceptions.RayActorError, ray.exceptions.GetTimeoutError) as error:
            raise ServerLost(f"{self.describe(index)} is lost: {error}") from None
        self._nodes[index] = node
        return address

    def addresses(self, timeout: float = 120.0) -> list[str]:
        """Every server's ``HOST:PORT``, in order."""
        return [self.address(index, timeout) for index in range(self.servers)]

    def describe(self, index: int) -> str:
        """Which server ``index`` is, and the node it was last seen on."""
        node = self._nodes.get(index)
        where = f" on node {node[:12]}" if node else ""
        return f"server {index} of {self._labels[index]}{where}"

    def actor(self, index: int) -> Any:
        """The Ray actor that owns server ``index``."""
        return self._actors[index]


class RayServerPool(_Servers):
    """``servers`` environment servers on the Ray cluster, each hosting ``instances_per_server``.

    Ray must be initialised (``ray.init``); see the module docstring.

    Args:
        target: the environment class, ``MODULE:CLASS`` (importable on every node).
        servers: how many servers.
        instances_per_server: instances each server hosts (stepped in columns).
        cpus_per_server: CPUs each server reserves, so that Ray never puts more servers on a
            node than it has cores for.
        strategy: the placement group's strategy: ``SPREAD`` (default: over as many nodes as
            possible), ``STRICT_SPREAD``, ``PACK`` or ``STRICT_PACK``.
        max_restarts: how many times Ray restarts each server's actor.
        server_args: more ``rlenv serve`` arguments.
        name: makes the pool leasable from other processes (:meth:`lease`).
        startup_timeout: seconds for the servers to come up.
        progress: told how many servers are up while they come up (default: logged at INFO).

    Raises:
        TimeoutError: the cluster could not place or start the servers in time (everything
            started is stopped again).
    """

    def __init__(
        self,
        target: str,
        servers: int,
        instances_per_server: int = 1,
        *,
        cpus_per_server: float = 1.0,
        strategy: str = "SPREAD",
        max_restarts: int = 3,
        server_args: Sequence[str] = (),
        name: str | None = None,
        startup_timeout: float = 120.0,
        progress: Callable[[str], None] | None = None,
    ) -> None:
        if servers < 1 or instances_per_server < 1:
            raise ValueError("a pool needs at least one server of at least one instance")
        self.target = target
        self.name = name
        tell = progress or logger.info
        token = secrets.token_urlsafe(24)
        self._group = placement_group([{"CPU": cpus_per_server}] * servers, strategy=strategy)
        self._registry: Any = None
        actors: list[Any] = []
        super().__init__(actors, token, instances_per_server, [f"pool {name or target}"] * servers)
        deadline = time.monotonic() + startup_timeout
        try:
            tell(f"rlenv: placing {servers} servers of {target} on the Ray cluster")
            ray.get(self._group.ready(), timeout=startup_timeout)
            for index in range(servers):
                # @ray.remote made the class an actor class (mypy sees the class as written).
                actors.append(
                    cast(Any, ServerActor)
                    .options(
                        num_cpus=cpus_per_server,
                        max_restarts=max_restarts,
                        max_task_retries=-1,
                        scheduling_strategy=PlacementGroupSchedulingStrategy(
                            self._group, placement_group_bundle_index=index
                        ),
                    )
                    .remote(target, instances_per_server, token, server_args, startup_timeout)
                )
            pending = {actor.address.remote(): index for index, actor in enumerate(actors)}
            while pending:
                left = deadline - time.monotonic()
                done, _ = ray.wait(list(pending), timeout=max(left, 0))
                if not done:
                    raise TimeoutError(
                        f"{len(pending)} of {servers} servers of {target} were "
                        f"not up after {startup_timeout} s"
                    )
                for ref in done:
                    _, self._nodes[pending.pop(ref)] = ray.get(ref)
                tell(
                    f"rlenv: {servers - len(pending)} of {servers} servers up on "
                    f"{len(set(self._nodes.values()))} nodes"
                )
            if name is not None:
                self._registry = (
                    cast(Any, _Registry)
                    .options(name=_REGISTRY.format(name))
                    .remote(actors, token, instances_per_server)
                )
        except BaseException:
            self.close()
            raise

    @property
    def nodes(self) -> list[str | None]:
        """The node id each server was last seen on."""
        return [self._nodes.get(index) for index in range(self.servers)]

    @classmethod
    def lease(cls, name: str, servers: int) -> PoolLease:
        """Take ``servers`` servers of the pool called ``name``, from any process of the cluster.

        Raises:
            ValueError: no such pool, or not that many servers free.
        """
        try:
            registry = ray.get_actor(_REGISTRY.format(name))
        except ValueError:
            raise ValueError(f"no rlenv pool called {name!r} on this Ray cluster") from None
        try:
            indices, actors, token, instances = ray.get(registry.lease.remote(servers))
        except ray.exceptions.RayTaskError as error:
            raise ValueError(f"pool {name!r}: {error.cause}") from None
        return PoolLease(registry, name, indices, actors, token, instances)

    def close(self) -> None:
        """Stop every server and actor, on every node, and free their resources."""
        actors, self._actors = self._actors, []
        if actors:
            ray.wait(
                [actor.close.remote() for actor in actors], num_returns=len(actors), timeout=10
            )
        for actor in [*actors, self._registry]:
            if actor is not None:
                ray.kill(actor, no_restart=True)
        self._registry = None
        remove_placement_group(self._group)

    def __enter__(self) -> RayServerPool:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class PoolLease(_Servers):
    """Servers leased from a named :class:`RayServerPool`, until :meth:`release`."""

    def __init__(
        self,
        registry: Any,
        name: str,
        indices: list[int],
        actors: list[Any],
        token: str,
        instances_per_server: int,
    ) -> None:
        super().__init__(
            actors,
            token,
            instances_per_server,
            [f"pool {name} (its server {index})" for index in indices],
        )
        self._registry = registry
        self._indices = indices

    def release(self) -> None:
        """Give the servers back to the pool."""
        if self._indices:
            ray.get(self._registry.release.remote(self._indices))
            self._indices = []

    def __enter__(self) -> PoolLease:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.release()
