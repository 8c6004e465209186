"""Client: drive one rlenv environment over TCP.

A blocking socket pumps bytes into a sans-IO :class:`rlenv.protocol.Connection`; everything about
the protocol is decided there. Every failure surfaces as a typed error: :class:`RemoteError`
(the server refused a request, with its code and message), :class:`RequestTimeout` (no answer
within the deadline; the connection is closed so that a late answer can never be taken for the
answer to a later request) and :class:`ConnectionLost`.
"""

from __future__ import annotations

import socket
from collections.abc import Mapping
from itertools import count
from typing import Any

from gymnasium import spaces

from rlenv.errors import (
    ConnectionLost,
    ProtocolError,
    RemoteError,
    RequestTimeout,
)
from rlenv.protocol import (
    CONNECTION_CLOSED,
    NEED_DATA,
    Connection,
    ErrorReply,
    Hello,
    Message,
    Request,
    Response,
    Role,
)
from rlenv.spaces import from_wire

__all__ = ["Client", "StepResult"]

StepResult = tuple[Any, float, bool, bool, dict[str, Any]]
"""``(observation, reward, terminated, truncated, info)``, as gymnasium's ``step`` returns."""

_READ_SIZE = 64 * 1024
_AGENT_ONLY: Mapping[str, Any] = {"agent": {}}
_AGENT_AND_WORLD: Mapping[str, Any] = {"agent": {}, "world": {}}


class Client:
    """A connection to one environment server.

    Args:
        host: the server's address.
        port: the server's port.
        timeout: seconds to wait for connecting and for each answer.
        world_data: also ask for the world's data on reset and step; it is returned as
            ``info["world"]``.

    Raises:
        ConnectionLost: the server cannot be reached, or closed the connection at once.
        RequestTimeout: the server did not say hello within ``timeout``.
        RemoteError: the server refused the connection (e.g. ``busy``).
        ProtocolVersionError: the server speaks another major protocol version.

    Attributes:
        hello: everything the server said on connecting.
        action_space: the agent's action space, as the server declared it.
        observation_space: the agent's observation space, as the server declared it.
    """

    def __init__(
        self, host: str = "127.0.0.1", port: int = 0, *, timeout: float = 30.0,
        world_data: bool = False,
    ) -> None:
        self.address = f"{host}:{port}"
        self.timeout = timeout
        self._observation_request = _AGENT_AND_WORLD if world_data else _AGENT_ONLY
        self._ids = count(1)
        self._connection = Connection(Role.CLIENT)
        try:
            self._sock: socket.socket | None = socket.create_connection((host, port), timeout)
        except TimeoutError:
            raise RequestTimeout(f"connecting to {self.address} took longer than {timeout}s")\
                from None
        except OSError as error:
            raise ConnectionLost(f"cannot connect to {self.address}: {error}") from None
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        try:
            message = self._receive()
        except BaseException:
            self.close()
            raise
        if isinstance(message, ErrorReply):
            self.close()
            raise RemoteError(message.code, message.message, message.fatal)
        if not isinstance(message, Hello):
            self.close()
            raise ConnectionLost(f"{self.address} did not start with a hello")
        self.hello = message
        self.action_space: spaces.Space = message.action_space
        self.observation_space: spaces.Space = message.observation_space

    # --- the API ----------------------------------------------------------------------------

    def configure(
        self, *, agent: Mapping[str, Any] | None = None, world: Mapping[str, Any] | None = None,
        **environment: Any,
    ) -> None:
        """Configure the environment (keywords), the agent and the world.

        Example: ``client.configure(repeat_action=7, agent={"max_force": 20.0})``.

        Raises:
            RemoteError: ``invalid_config`` naming the key the server refused; nothing was
                applied.
        """
        config: dict[str, Any] = {}
        if environment:
            config["environment"] = environment
        if agent is not None:
            config["agent"] = dict(agent)
        if world is not None:
            config["world"] = dict(world)
        self._request(config=config)

    def reset(
        self, *, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Start an episode; the same seed gives the same episode.

        Returns:
            ``(observation, info)``.
        """
        reset: dict[str, Any] = {}
        if seed is not None:
            reset["seed"] = seed
        if options is not None:
            reset["options"] = dict(options)
        response = self._request(reset=reset, observation=self._observation_request)
        return self._observation(response), self._info(response)

    def step(self, action: Any, repeat_action: int | None = None) -> StepResult:
        """Run ``action`` for ``repeat_action`` physics ticks (default: the server's setting).

        Returns:
            ``(observation, reward, terminated, truncated, info)``; ``info["frames"]`` is the
            number of ticks that ran (fewer than asked only if the episode ended).

        Raises:
            RemoteError: ``invalid_action`` (shape, dtype, bounds, NaN) or ``reset_required``;
                the environment is unchanged and the client can go on.
        """
        response = self._request(
            action=action, observation=self._observation_request, repeat_action=repeat_action
        )
        return (
            self._observation(response),
            response.reward,
            response.terminated,
            response.truncated,
            self._info(response),
        )

    def observe(self) -> dict[str, Any]:
        """The current observation without stepping: ``{"agent": ..., "world": ...}``."""
        response = self._request(observation=_AGENT_AND_WORLD)
        return {"agent": self._observation(response), "world": self._part(response, "world")}

    def close(self) -> None:
        """Close the connection; safe to repeat."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    @property
    def closed(self) -> bool:
        """Whether the connection is closed."""
        return self._sock is None

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self.closed else "open"
        return f"<Client {self.hello.environment!r} at {self.address}, {state}>"

    # --- internals --------------------------------------------------------------------------

    def _request(self, **parts: Any) -> Response:
        sock = self._sock
        if sock is None:
            raise ConnectionLost(f"the connection to {self.address} is closed")
        data = self._connection.send(Request(id=next(self._ids), **parts))
        try:
            sock.sendall(data)
        except OSError as error:
            self.close()
            raise ConnectionLost(f"sending to {self.address} failed: {error}") from None
        message = self._receive()
        if isinstance(message, ErrorReply):
            if message.fatal:
                self.close()
            raise RemoteError(message.code, message.message, message.fatal)
        if not isinstance(message, Response):
            self.close()
            raise ConnectionLost(f"{self.address} broke the protocol: {message!r:.80}")
        return message

    def _receive(self) -> Message:
        connection = self._connection
        while True:
            try:
                message = connection.next_message()
            except ProtocolError as error:
                self.close()
                raise ConnectionLost(f"{self.address} broke the protocol: {error}") from None
            if message is NEED_DATA:
                connection.receive_data(self._recv())
                continue
            if message is CONNECTION_CLOSED:
                self.close()
                raise ConnectionLost(f"{self.address} closed the connection")
            return message  # type: ignore[return-value]

    def _recv(self) -> bytes:
        sock = self._sock
        if sock is None:
            raise ConnectionLost(f"the connection to {self.address} is closed")
        try:
            return sock.recv(_READ_SIZE)
        except TimeoutError:
            self.close()
            raise RequestTimeout(
                f"{self.address} did not answer within {self.timeout}s; connection closed"
            ) from None
        except OSError as error:
            self.close()
            raise ConnectionLost(f"receiving from {self.address} failed: {error}") from None

    def _observation(self, response: Response) -> Any:
        return from_wire(self.observation_space, self._part(response, "agent"))

    def _part(self, response: Response, part: str) -> Any:
        if response.observation is None or part not in response.observation:
            self.close()
            raise ConnectionLost(f"{self.address} broke the protocol: no {part!r} observation")
        return response.observation[part]

    def _info(self, response: Response) -> dict[str, Any]:
        info = dict(response.info)
        info["frames"] = response.frames
        if response.observation is not None and "world" in response.observation:
            info["world"] = response.observation["world"]
        return info
