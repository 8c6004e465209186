"""A dm_env_rpc server (its gRPC ``Environment`` service) for any rlenv target.

dm_env_rpc (DeepMind's agent-environment protocol) is a stream of requests, each answered in
order: ``CreateWorld``, ``JoinWorld``, ``Step``, ``Reset``, ``ResetWorld``, ``LeaveWorld``,
``DestroyWorld``. Here a world is one rlenv environment, reached through
:class:`~rlenv_client.client.Client` like any other client: for ``MODULE:CLASS`` or a
registered id (``rlenv/CartPole-v1``) each world gets an ``rlenv serve`` subprocess of its
own; for ``HOST:PORT`` each world is a connection to that running server. One stream at a time
joins a world, and drives it.

A step while no episode runs starts one (its actions are ignored, as dm_env_rpc says) and
answers ``RUNNING``; a step that ends it answers ``TERMINATED`` (``terminated``, discount 0) or
``INTERRUPTED`` (``truncated``, or a registered id's time limit, as gymnasium's ``TimeLimit``
cuts it; discount 1). The next step starts the next episode. Seeds: ``CreateWorld``'s,
``ResetWorld``'s and ``Reset``'s ``seed`` setting seeds the next episode; later ones continue
from it, as gymnasium's ``reset(seed=None)`` does.

Every refusal is an error response (google.rpc's ``Status``) on the stream, which goes on
serving: an unknown world or uid, a setting not understood, an action that does not fit its
spec, the environment's own error.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable, Iterator, Mapping
from concurrent import futures
from dataclasses import dataclass
from typing import Any

import grpc
import numpy as np
from dm_env_rpc.v1 import dm_env_rpc_pb2, dm_env_rpc_pb2_grpc, tensor_utils
from google.rpc import code_pb2, status_pb2

from rlenv.protocol.errors import ConnectionLost, RequestTimeout, RlenvError
from rlenv_client._addresses import parse_address
from rlenv_client.client import Client
from rlenv_client.launcher import ServerProcess
from rlenv_client.registration import ENVIRONMENTS
from rlenv_tools._dm_env_rpc_specs import ActionRefused, Specs

__all__ = ["EnvironmentService", "Refused", "Target", "serve"]

_States = dm_env_rpc_pb2.EnvironmentStateType
_STARTUP_TIMEOUT = 60.0  # seconds a world's server may take to start


class Refused(Exception):
    """A request refused: a google.rpc code and a message for the agent."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class Target:
    """What the command serves: ``MODULE:CLASS``, a registered id or ``HOST:PORT``.

    Attributes:
        name: as the command line gave it.
        serve: the ``MODULE:CLASS`` an ``rlenv serve`` subprocess runs, or ``None`` for a
            running server.
        max_episode_steps: a registered id's time limit (steps), if any.
    """

    name: str
    serve: str | None
    max_episode_steps: int | None = None

    @classmethod
    def parse(cls, name: str) -> Target:
        """The target ``name`` names."""
        registered = ENVIRONMENTS.get(name)
        if registered is not None:
            return cls(name, registered.target, registered.max_episode_steps)
        host, _, port = name.rpartition(":")
        return cls(name, None if host and port.isdigit() else name)

    def open(self, timeout: float) -> tuple[Client, ServerProcess | None]:
        """A client of a new environment, and its server subprocess (``None``: a running one)."""
        if self.serve is None:
            return Client(*parse_address(self.name), timeout=timeout), None
        process = ServerProcess(self.serve, startup_timeout=_STARTUP_TIMEOUT)
        try:
            return Client(process.host, process.port, timeout=timeout), process
        except BaseException:
            process.close()
            raise


class World:
    """One environment and its episode, as dm_env_rpc sees it."""

    def __init__(self, name: str, target: Target, timeout: float, seed: int | None) -> None:
        self.name = name
        self.client, self._process = target.open(timeout)
        try:
            hello = self.client.hello
            self.specs = Specs(hello.action_space, hello.observation_space, hello.agents)
        except BaseException:
            self.close()
            raise
        self._max_steps = target.max_episode_steps
        self.lock = threading.Lock()
        self.joined_by: object | None = None
        self.destroyed = False  # set under the lock: no stream joins it any more
        self._seed = seed
        self._running = False
        self._steps = 0
        self._last_actions: dict[int, Any] = {}

    def restart(self, seed: int | None) -> None:
        """End the episode: the next step starts one, seeded by ``seed`` (``None``: continue)."""
        self._running = False
        if seed is not None:
            self._seed = seed

    def step(self, request: dm_env_rpc_pb2.StepRequest) -> dm_env_rpc_pb2.StepResponse:
        """Answer a step: start an episode, or act in the running one (see the module)."""
        requested = self.specs.check_requested(request.requested_observations)
        if not self._running:
            observation, info = self.client.reset(seed=self._seed)
            self._seed = None
            self._running, self._steps, self._last_actions = True, 0, {}
            reward, discount, state = 0.0, 1.0, _States.RUNNING
        else:
            action = self.specs.action(request.actions, self._last_actions)
            observation, reward, terminated, truncated, info = self.client.step(action)
            self._steps += 1
            truncated = truncated or self._steps == self._max_steps
            state = (
                _States.TERMINATED
                if terminated
                else _States.INTERRUPTED
                if truncated
                else _States.RUNNING
            )
            discount = 0.0 if terminated else 1.0
            self._running = state == _States.RUNNING
        scalars = {"reward": float(reward), "discount": discount}
        for agent, ends in info.get("agents", {}).items():
            scalars[f"rewards.{agent}"] = float(ends.get("reward", 0.0))
        for agent in self.specs.agents:
            scalars.setdefault(f"rewards.{agent}", 0.0)
        return dm_env_rpc_pb2.StepResponse(
            state=state,
            observations=self.specs.observation_tensors(requested, observation, scalars),
        )

    def close(self) -> None:
        """Close the client and end the server subprocess, if any."""
        try:
            self.client.close()
        finally:
            if self._process is not None:
                self._process.close()


class EnvironmentService(dm_env_rpc_pb2_grpc.EnvironmentServicer):
    """dm_env_rpc's ``Environment`` service over worlds of one target.

    Args:
        target: what each world serves.
        timeout: seconds an environment may take to answer a request.
        max_worlds: worlds at once (then ``CreateWorld`` is refused: RESOURCE_EXHAUSTED).
    """

    def __init__(self, target: Target, *, timeout: float = 30.0, max_worlds: int = 8) -> None:
        self.target = target
        self.timeout = timeout
        self.max_worlds = max_worlds
        self._worlds: dict[str, World | None] = {}  # None: reserved while it starts
        self._lock = threading.Lock()
        self._names = (f"world-{n}" for n in itertools.count(1))

    def Process(  # noqa: N802  (the service's method, as dm_env_rpc's .proto names it)
        self,
        request_iterator: Iterator[dm_env_rpc_pb2.EnvironmentRequest],
        context: grpc.ServicerContext,
    ) -> Iterator[dm_env_rpc_pb2.EnvironmentResponse]:
        """Answer one stream's requests in order; its world is left when it ends."""
        stream = _Stream(self)
        try:
            for request in request_iterator:
                yield stream.answer(request)
        finally:
            stream.leave()

    def create(self, settings: Mapping[str, dm_env_rpc_pb2.Tensor]) -> str:
        """A new world's name (its settings: ``seed``)."""
        seed = _seed(_only(settings, {"seed"}, "CreateWorld"))
        with self._lock:
            if len(self._worlds) >= self.max_worlds:
                raise Refused(
                    code_pb2.RESOURCE_EXHAUSTED,
                    f"{self.max_worlds} worlds exist already (--max-worlds): destroy one first",
                )
            name = next(self._names)
            self._worlds[name] = None
        try:
            world = World(name, self.target, self.timeout, seed)
        except BaseException:
            with self._lock:
                del self._worlds[name]
            raise
        with self._lock:
            self._worlds[name] = world
        return name

    def world(self, name: str) -> World:
        """The world called ``name``.

        Raises:
            Refused: NOT_FOUND, naming the worlds there are.
        """
        with self._lock:
            world = self._worlds.get(name)
            if world is None:
                there = sorted(n for n, w in self._worlds.items() if w is not None)
                raise Refused(code_pb2.NOT_FOUND, f"no world {name!r:.80}: the worlds are {there}")
            return world

    def destroy(self, name: str) -> None:
        """Destroy a world no stream has joined."""
        world = self.world(name)
        with world.lock:
            if world.joined_by is not None:
                raise Refused(
                    code_pb2.FAILED_PRECONDITION,
                    f"world {name!r} is joined: its connection leaves it first",
                )
            with self._lock:
                del self._worlds[name]
            world.destroyed = True
        world.close()

    def close(self) -> None:
        """Destroy every world."""
        with self._lock:
            worlds, self._worlds = list(self._worlds.values()), {}
        for world in worlds:
            if world is not None:
                world.close()


class _Stream:
    """One connection's requests: which world it has joined, each request's answer."""

    def __init__(self, service: EnvironmentService) -> None:
        self.service = service
        self.joined: World | None = None
        self._handlers: dict[str, Callable[[Any], Any]] = {
            "create_world": self._create_world,
            "join_world": self._join_world,
            "step": self._step,
            "reset": self._reset,
            "reset_world": self._reset_world,
            "leave_world": self._leave_world,
            "destroy_world": self._destroy_world,
        }

    def answer(self, request: dm_env_rpc_pb2.EnvironmentRequest) -> Any:
        """The response to ``request``: its payload's answer, or an error."""
        kind = request.WhichOneof("payload")
        handler = self._handlers.get(kind or "")
        try:
            if handler is None:
                raise Refused(code_pb2.UNIMPLEMENTED, f"this server answers no {kind} request")
            return dm_env_rpc_pb2.EnvironmentResponse(**{kind: handler(getattr(request, kind))})
        except Refused as refused:
            return _error(refused.code, str(refused))
        except (ActionRefused, ValueError) as error:
            return _error(code_pb2.INVALID_ARGUMENT, str(error))
        except (ConnectionLost, RequestTimeout, OSError) as error:
            return _error(code_pb2.UNAVAILABLE, f"the environment cannot be reached: {error}")
        except RlenvError as error:  # the environment's own error, or its server's refusal
            return _error(code_pb2.INTERNAL, f"the environment failed: {error}")

    def leave(self) -> None:
        """Leave the joined world, if any."""
        world, self.joined = self.joined, None
        if world is not None:
            with world.lock:
                world.joined_by = None

    def _create_world(self, request: Any) -> Any:
        return dm_env_rpc_pb2.CreateWorldResponse(world_name=self.service.create(request.settings))

    def _join_world(self, request: Any) -> Any:
        _only(request.settings, set(), "JoinWorld")
        if self.joined is not None:
            raise Refused(
                code_pb2.FAILED_PRECONDITION,
                f"this connection has joined {self.joined.name!r} already: leave it first",
            )
        world = self.service.world(request.world_name)
        with world.lock:
            if world.destroyed:
                raise Refused(code_pb2.NOT_FOUND, f"world {world.name!r} was destroyed")
            if world.joined_by is not None:
                raise Refused(
                    code_pb2.FAILED_PRECONDITION,
                    f"world {world.name!r} is joined by another connection",
                )
            world.joined_by = self
            world.restart(None)
        self.joined = world
        return dm_env_rpc_pb2.JoinWorldResponse(specs=world.specs.proto)

    def _step(self, request: Any) -> Any:
        world = self._world("Step")
        with world.lock:
            return world.step(request)

    def _reset(self, request: Any) -> Any:
        world = self._world("Reset")
        seed = _seed(_only(request.settings, {"seed"}, "Reset"))
        with world.lock:
            world.restart(seed)
        return dm_env_rpc_pb2.ResetResponse(specs=world.specs.proto)

    def _reset_world(self, request: Any) -> Any:
        seed = _seed(_only(request.settings, {"seed"}, "ResetWorld"))
        world = self.service.world(request.world_name)
        with world.lock:
            world.restart(seed)
        return dm_env_rpc_pb2.ResetWorldResponse()

    def _leave_world(self, request: Any) -> Any:
        self.leave()
        return dm_env_rpc_pb2.LeaveWorldResponse()

    def _destroy_world(self, request: Any) -> Any:
        self.service.destroy(request.world_name)
        return dm_env_rpc_pb2.DestroyWorldResponse()

    def _world(self, kind: str) -> World:
        if self.joined is None:
            raise Refused(code_pb2.FAILED_PRECONDITION, f"{kind} before JoinWorld: join a world")
        return self.joined


def serve(
    target: str,
    *,
    port: int = 0,
    timeout: float = 30.0,
    max_worlds: int = 8,
    max_connections: int = 16,
    ready: Callable[[str], None] | None = None,
) -> None:
    """Serve dm_env_rpc on 127.0.0.1:``port`` until interrupted.

    gRPC's local credentials (``grpc.local_channel_credentials()``, what
    ``dm_env_rpc.v1.connection.create_secure_channel_and_connect`` uses) admit clients on this
    machine only.

    Args:
        target: ``MODULE:CLASS``, a registered id or ``HOST:PORT`` (see the module).
        port: the port (0: any free one).
        timeout: seconds an environment may take to answer a request.
        max_worlds: worlds at once.
        max_connections: streams at once (more are refused by gRPC: RESOURCE_EXHAUSTED).
        ready: called with ``HOST:PORT`` once the server listens.

    Raises:
        ValueError: the target's spaces cannot travel as dm_env_rpc's tensors.
        OSError: the port cannot be bound.
    """
    service = EnvironmentService(Target.parse(target), timeout=timeout, max_worlds=max_worlds)
    World("check", service.target, timeout, None).close()  # the target fails here, not later
    server = grpc.server(
        futures.ThreadPoolExecutor(max_workers=max_connections),
        maximum_concurrent_rpcs=max_connections,
    )
    dm_env_rpc_pb2_grpc.add_EnvironmentServicer_to_server(service, server)
    bound = server.add_secure_port(
        f"127.0.0.1:{port}", grpc.local_server_credentials(grpc.LocalConnectionType.LOCAL_TCP)
    )
    if bound == 0:
        raise OSError(f"cannot listen on 127.0.0.1:{port}")
    server.start()
    try:
        if ready is not None:
            ready(f"127.0.0.1:{bound}")
        server.wait_for_termination()
    finally:
        server.stop(grace=None)
        service.close()


def _only(
    settings: Mapping[str, dm_env_rpc_pb2.Tensor], known: set[str], kind: str
) -> dict[str, Any]:
    """``settings`` unpacked, refusing any name not in ``known``."""
    unknown = sorted(set(settings) - known)
    if unknown:
        raise Refused(
            code_pb2.INVALID_ARGUMENT,
            f"{kind} has no setting {unknown[0]!r:.80}: its settings are {sorted(known)}",
        )
    for name, tensor in settings.items():
        if tensor.shape:  # every setting is a scalar (and a shape would broadcast one element)
            raise Refused(code_pb2.INVALID_ARGUMENT, f"{kind}'s setting {name!r} must be a scalar")
    try:
        return {name: tensor_utils.unpack_tensor(tensor) for name, tensor in settings.items()}
    except (ValueError, TypeError) as error:
        raise Refused(code_pb2.INVALID_ARGUMENT, f"{kind}'s settings: {error}") from None


def _seed(settings: Mapping[str, Any]) -> int | None:
    """The ``seed`` setting: a non-negative integer scalar, or ``None``."""
    if "seed" not in settings:
        return None
    seed = settings["seed"]
    if not isinstance(seed, int | np.integer) or isinstance(seed, bool) or seed < 0:
        raise Refused(
            code_pb2.INVALID_ARGUMENT, f"seed must be a non-negative integer, not {seed!r:.80}"
        )
    return int(seed)


def _error(code: int, message: str) -> dm_env_rpc_pb2.EnvironmentResponse:
    return dm_env_rpc_pb2.EnvironmentResponse(error=status_pb2.Status(code=code, message=message))
