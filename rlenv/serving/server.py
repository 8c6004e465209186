"""Host an environment: build its instances, open its endpoint, run the loop."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path

from rlenv.environment import RLEnvironment
from rlenv.serving._endpoint import DEFAULT_HOST, Endpoint, Limits
from rlenv.serving._host import Host
from rlenv.serving.per_client import HostPerClient
from rlenv.serving.policy_driver import load_policies

__all__ = ["Server"]

logger = logging.getLogger(__name__)


class Server:
    """Environments in scene trees, listening for their clients.

    The server hosts ``instances`` independent copies of the environment (each its own tree
    and pymunk space) behind one socket: a plain request goes to the first, a ``batch`` carries
    one request per instance, and a ``steps`` request steps them all in columns (see
    :mod:`rlenv.serving._host`).

    Args:
        environment: the environment class, ``MODULE:CLASS``, or (for one instance) an
            environment object.
        host: address to bind; 127.0.0.1 unless the environment must be reachable from
            other machines.
        port: port to bind; 0 picks a free one (see :attr:`address`).
        lifeline: read end of a pipe whose write end the starting process holds; the server
            exits when that process is gone (see ``rlenv_client.ServerProcess``).
        token: the secret clients must present; required to bind a non-loopback address.
        limits: frame sizes and deadlines (see :class:`~rlenv.serving._endpoint.Limits`); the
            defaults if ``None``.
        instances: how many environment instances to host.
        record_dir: where clients may have the environment record videos (``None``: nowhere).
        real_time: start in real-time mode (ticks follow the wall clock).
        per_client: give every client connection environments of its own (``instances`` of
            them), built when it first asks and closed when it leaves
            (:mod:`rlenv.serving.per_client`); otherwise the first client to change the
            environment controls it and the others may observe.
        policies: what drives agents, by agent name: an ONNX policy file, or ``"heuristic"``
            for the agent's own :meth:`~rlenv.agent.RLAgent.heuristic` (``rlenv serve
            --policy``; see :mod:`rlenv.serving.policy_driver`). With every agent driven, the
            server plays episodes itself and clients may only observe. With ``per_client``,
            every client's environment has its driven agents, driven by the same loaded files
            (they keep no state between steps); not every agent may be driven then.
        max_episode_steps: steps after which a policy-driven episode is cut short.
        keep_episodes: how many finished episodes each instance keeps as recordings, for
            clients to fetch (the ``episodes`` part; ``rlenv serve --keep-episodes``), from the
            start; 0 keeps none; ``None`` (the default) keeps 8 once a client asks for them.

    Attributes:
        host: the instances and how requests reach them (with ``per_client``, the hosts of
            every client).
        endpoint: the sockets.
        address: the (host, port) the server listens on.

    Raises:
        InsecureBindError: a non-loopback ``host`` without a ``token``.
    """

    def __init__(
        self,
        environment: RLEnvironment | type[RLEnvironment] | str,
        host: str = DEFAULT_HOST,
        port: int = 0,
        lifeline: int | None = None,
        token: str | None = None,
        limits: Limits | None = None,
        instances: int = 1,
        record_dir: Path | None = None,
        real_time: bool = False,
        per_client: bool = False,
        policies: Mapping[str, str | Path] | None = None,
        max_episode_steps: int | None = None,
        keep_episodes: int | None = None,
    ) -> None:
        loaded = load_policies(policies or {})

        def build() -> Host:
            return Host(
                environment,
                instances,
                record_dir=record_dir,
                real_time=real_time,
                policies=loaded,
                max_episode_steps=max_episode_steps,
                keep_episodes=keep_episodes,
            )

        if per_client and not isinstance(environment, str | type):
            raise TypeError("a server per client needs the environment class, not an instance")
        self.host: Host | HostPerClient = HostPerClient(build) if per_client else build()
        self.endpoint = Endpoint(self.host.hello, limits or Limits(), token, per_client=per_client)
        self.address = self.endpoint.start_server(port, host)
        if lifeline is not None:
            self.endpoint.watch_lifeline(lifeline)

    def serve_forever(self) -> None:
        """Serve until interrupted.

        An exception raised by user code while a request is being served is answered with an
        ``environment_error`` reply and the server goes on; any other exception propagates.
        """
        self.host.serve_forever(self.endpoint)

    def close(self) -> None:
        """Close the endpoint (every client is disconnected) and the instances."""
        self.endpoint.close()
        self.host.close()

    def __enter__(self) -> Server:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
