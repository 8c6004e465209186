"""RemoteEnv: any rlenv environment as a ``gymnasium.Env``, a thin adaptor over a client.

The spaces come from the server's hello, never from code on this side. The environment is
reached in one of three ways:

- ``RemoteEnv("examples.cartpole:CartPoleEnvironment")`` starts a server subprocess on a free
  port and ends its whole process group on :meth:`~RemoteEnv.close` (or at exit);
- ``RemoteEnv(address="127.0.0.1:7000")`` attaches to a running server;
- ``RemoteEnv("examples.cartpole:CartPoleEnvironment", in_process=True)`` runs the environment
  in this process with no socket (debugging, and the baseline for remote figures).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeVar

import gymnasium
import numpy as np

from rlenv.errors import ConnectionLost
from rlenv_client.base import BaseClient, StepResult
from rlenv_client.client import Client
from rlenv_client.display import Display, display_available
from rlenv_client.launcher import ServerProcess, with_server_story

__all__ = ["RemoteEnv", "connect", "parse_address"]

logger = logging.getLogger(__name__)

T = TypeVar("T")


def parse_address(address: str) -> tuple[str, int]:
    """Split ``"host:port"``.

    Raises:
        ValueError: ``address`` is not of that form.
    """
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"expected an address of the form HOST:PORT, got {address!r}")
    return host, int(port)


def connect(
    target: str | None = None, *, address: str | None = None, in_process: bool = False,
    timeout: float = 30.0, server_args: Sequence[str] = (), startup_timeout: float = 60.0,
    token: str | None = None,
) -> tuple[BaseClient, ServerProcess | None]:
    """Reach an environment the way :class:`RemoteEnv` does.

    An ``address`` wins over a ``target``, so that a registered id (whose target is fixed) can
    attach to a running server: ``gymnasium.make("rlenv/CartPole-v0", address="host:port")``.

    Returns:
        The client, and the server process it started (``None`` when it started none).

    Raises:
        ValueError: neither ``target`` nor ``address``, or ``in_process`` with an address.
    """
    if address is not None:
        if in_process:
            raise ValueError("in_process=True needs a target, not an address")
        return Client(*parse_address(address), timeout=timeout, token=token), None
    if target is None:
        raise ValueError("give target='MODULE:CLASS' or address='HOST:PORT'")
    if in_process:
        from rlenv_client.local import LocalClient

        return LocalClient(target), None
    server = ServerProcess(target, startup_timeout=startup_timeout, args=server_args)
    try:
        return Client(server.host, server.port, timeout=timeout), server
    except BaseException:
        server.close()
        raise


class RemoteEnv(gymnasium.Env):
    """A gymnasium environment whose simulation runs in an rlenv server.

    ``metadata["render_modes"]`` lists ``"human"`` only where a display is available.

    Args:
        target: the environment class as ``MODULE:CLASS``; a server is started for it.
        address: ``HOST:PORT`` of a running server, instead of ``target``.
        repeat_action: physics ticks each :meth:`step` runs; the server's default if ``None``.
        render_mode: ``"rgb_array"`` (frames as arrays), ``"human"`` (a window; needs a
            display) or ``None``.
        in_process: run the environment inside this process instead of a server.
        timeout: seconds to wait for each answer before :class:`RequestTimeout`.
        server_args: extra arguments for ``rlenv serve``.
        render_size: (width, height) of rendered frames; the environment's default if ``None``.
        token: the secret of a server that requires one (default ``$RLENV_TOKEN``).

    Raises:
        ServerStartError: the server could not start (its output is in the message).
        RuntimeError: ``render_mode="human"`` without a display.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array", "human"], "render_fps": 15}

    def __init__(
        self, target: str | None = None, *, address: str | None = None,
        repeat_action: int | None = None, render_mode: str | None = None,
        in_process: bool = False, timeout: float = 30.0, server_args: Sequence[str] = (),
        render_size: tuple[int, int] | None = None, token: str | None = None,
    ) -> None:
        self.metadata = {"render_modes": ["rgb_array"], "render_fps": 15}
        if display_available():
            self.metadata["render_modes"].append("human")
        if render_mode is not None and render_mode not in ("rgb_array", "human"):
            raise ValueError(f"render_mode must be 'rgb_array', 'human' or None, got "
                             f"{render_mode!r}")
        if render_mode == "human" and not display_available():
            raise RuntimeError("render_mode='human' needs a display, and none is available "
                               "(DISPLAY is not set); use render_mode='rgb_array' instead")
        self.client, self.server = connect(target, address=address, in_process=in_process,
                                           timeout=timeout, server_args=server_args, token=token)
        hello = self.client.hello
        self.action_space = hello.action_space
        self.observation_space = hello.observation_space
        self.repeat_action = repeat_action
        ticks = repeat_action or hello.repeat_action
        self.metadata["render_fps"] = hello.physics_ticks_per_second / ticks
        self.render_mode = render_mode
        self.render_size = render_size
        self._display: Display | None = None
        logger.info("connected to %s at %s", hello.environment, self.client.address)

    def reset(
        self, *, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Start an episode; ``seed`` makes it reproducible, on any server."""
        super().reset(seed=seed)
        observation, info = self._call(self.client.reset, seed=seed, options=options)
        if self.render_mode == "human":
            self.render()
        return observation, info

    def step(self, action: Any) -> StepResult:
        """Run ``action`` for ``repeat_action`` physics ticks; ``info["frames"]`` says how many."""
        result = self._call(self.client.step, action, self.repeat_action)
        if self.render_mode == "human":
            self.render()
        return result

    def render(self) -> np.ndarray | None:
        """The current frame (``rgb_array``), or show it in the window (``human``)."""
        if self.render_mode is None:
            gymnasium.logger.warn("render() was called with render_mode=None; nothing to draw")
            return None
        width, height = self.render_size or (None, None)
        frame = self._call(self.client.render, width, height)
        if self.render_mode == "rgb_array":
            return frame
        if self._display is None:
            self._display = Display(f"rlenv: {self.client.hello.environment}")
        self._display.show(frame)
        return None

    def close(self) -> None:
        """Disconnect and stop the server this environment started; safe to repeat."""
        if self._display is not None:
            self._display.close()
            self._display = None
        self.client.close()
        if self.server is not None:
            self.server.close()

    def _call(self, method: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        """Call a client method; a lost connection to a server that died says how it died."""
        try:
            return method(*args, **kwargs)
        except ConnectionLost as error:
            raise with_server_story(error, [self.server] if self.server else []) from None

    def __repr__(self) -> str:
        return f"<RemoteEnv {self.client.hello.environment} at {self.client.address}>"
