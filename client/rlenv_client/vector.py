"""RemoteVectorEnv: N environments stepped concurrently, as a ``gymnasium.vector.VectorEnv``.

Every step sends all N requests first and then gathers the N answers, so the servers simulate
in parallel while the trainer waits once. Each sub-environment is its own server process
(started concurrently), a running server given by address, or an in-process environment.

Autoreset follows gymnasium 1.x (:class:`gymnasium.vector.AutoresetMode`):

- ``NEXT_STEP`` (default): the step after a sub-environment terminated or was truncated resets
  it instead of stepping it; that step returns the reset observation, reward 0 and both flags
  false, and ignores the sub-environment's action.
- ``SAME_STEP``: a sub-environment that ends is reset within the same step; the returned
  observation is the reset one, and ``info["final_obs"]`` / ``info["final_info"]`` hold the
  last observation and info of the episode that ended.

``max_episode_steps`` truncates each sub-environment's episodes, as ``TimeLimit`` does. A lost
server that this vector started is restarted (``max_restarts`` each): its interrupted episode
ends as truncated with its last observation, reward 0 and ``info["server_restarted"]``, and the
autoreset that follows starts a fresh episode on the new server.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array, iterate

from rlenv_client.base import BaseClient
from rlenv_client.launcher import ServerProcess, with_server_story
from rlenv_client.session import LOST, Session, as_lost

__all__ = ["RemoteVectorEnv"]

logger = logging.getLogger(__name__)


class RemoteVectorEnv(VectorEnv):
    """``num_envs`` copies of one rlenv environment, stepped concurrently.

    Args:
        num_envs: how many sub-environments (ignored when ``addresses`` is given).
        target: the environment class as ``MODULE:CLASS``; one server is started per copy.
        addresses: ``HOST:PORT`` of running servers, one per sub-environment, instead.
        repeat_action: physics ticks per step; the servers' default if ``None``.
        max_episode_steps: truncate episodes after this many steps (``None``: never).
        autoreset_mode: ``NEXT_STEP`` or ``SAME_STEP``.
        in_process: run the copies inside this process instead of servers.
        render_mode: ``"rgb_array"`` to render every copy, or ``None``.
        timeout: seconds to wait for each answer.
        token: the secret of servers that require one (default ``$RLENV_TOKEN``).
        max_restarts: how many times each lost server that this vector started is replaced.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": ["rgb_array"]}

    def __init__(
        self, num_envs: int = 1, target: str | None = None, *,
        addresses: Sequence[str] | None = None, repeat_action: int | None = None,
        max_episode_steps: int | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        in_process: bool = False, render_mode: str | None = None, timeout: float = 30.0,
        token: str | None = None, max_restarts: int = 3,
    ) -> None:
        mode = AutoresetMode(autoreset_mode)
        if mode is AutoresetMode.DISABLED:
            raise ValueError("RemoteVectorEnv autoresets; use NEXT_STEP or SAME_STEP")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be 'rgb_array' or None, got {render_mode!r}")
        places: list[dict[str, Any]]
        if addresses is not None:
            places = [{"address": address, "token": token} for address in addresses]
        else:
            places = [{"target": target, "in_process": in_process}] * num_envs
        if not places:
            raise ValueError("a vector environment needs at least one sub-environment")
        self.sessions: list[Session] = []
        self._connect(places, timeout=timeout, max_restarts=max_restarts)
        hello = self.clients[0].hello
        for client in self.clients[1:]:
            if (client.action_space, client.observation_space) != (
                hello.action_space, hello.observation_space
            ):
                self.close()
                raise ValueError(
                    f"{client.address} has other spaces than {self.clients[0].address}"
                )
        self.num_envs = len(self.clients)
        self.single_action_space = hello.action_space
        self.single_observation_space = hello.observation_space
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.metadata = {**self.metadata, "autoreset_mode": mode,
                         "render_fps": hello.physics_ticks_per_second
                         / (repeat_action or hello.repeat_action)}
        self.render_mode = render_mode
        self.repeat_action = repeat_action
        self.max_episode_steps = max_episode_steps
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)
        self._steps = np.zeros(self.num_envs, dtype=np.int64)
        self._last_observations: list[Any] = [None] * self.num_envs

    @property
    def clients(self) -> list[BaseClient]:
        """The sub-environments' clients, in order (they change when a server is restarted)."""
        return [session.client for session in self.sessions]

    @property
    def servers(self) -> list[ServerProcess]:
        """The server processes this vector started."""
        return [session.server for session in self.sessions if session.server is not None]

    def reset(
        self, *, seed: int | Sequence[int | None] | None = None,
        options: Mapping[str, Any] | None = None,
    ) -> tuple[Any, dict[str, Any]]:
        """Reset every sub-environment; an int ``seed`` seeds them ``seed``, ``seed + 1`` ...

        Raises:
            ValueError: a list of seeds of the wrong length.
            ConnectionLost: a server went away (with how it exited, if it died).
        """
        try:
            return self._reset(seed, options)
        except LOST as error:
            raise with_server_story(as_lost(error), self.servers) from None

    def _reset(
        self, seed: int | Sequence[int | None] | None, options: Mapping[str, Any] | None
    ) -> tuple[Any, dict[str, Any]]:
        if seed is None or isinstance(seed, int):
            seeds: list[int | None] = [
                None if seed is None else seed + i for i in range(self.num_envs)
            ]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"{len(seeds)} seeds for {self.num_envs} environments")
        super().reset(seed=seed if isinstance(seed, int) else None)
        for client, env_seed in zip(self.clients, seeds, strict=True):
            client.send_reset(seed=env_seed, options=options)
        observations, infos = [], {}
        for index, client in enumerate(self.clients):
            observation, info = client.receive_reset()
            self._last_observations[index] = observation
            observations.append(observation)
            infos = self._add_info(infos, info, index)
        self._autoreset[:] = False
        self._steps[:] = 0
        return self._batch(observations), infos

    def step(
        self, actions: Any
    ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every sub-environment (resetting those that ended, per the autoreset mode).

        Raises:
            ConnectionLost: a server went away (with how it exited, if it died).
        """
        try:
            return self._step(actions)
        except LOST as error:
            raise with_server_story(as_lost(error), self.servers) from None

    def _step(
        self, actions: Any
    ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        resetting = self._autoreset.copy() if self._mode is AutoresetMode.NEXT_STEP else \
            np.zeros(self.num_envs, dtype=np.bool_)
        for index, (client, action) in enumerate(
            zip(self.clients, iterate(self.action_space, actions), strict=True)
        ):
            if resetting[index]:
                client.send_reset()
            else:
                client.send_step(action, self.repeat_action)
        observations: list[Any] = []
        env_infos: list[dict[str, Any]] = []
        rewards = np.zeros(self.num_envs, dtype=np.float64)
        terminations = np.zeros(self.num_envs, dtype=np.bool_)
        truncations = np.zeros(self.num_envs, dtype=np.bool_)
        for index, client in enumerate(self.clients):
            try:
                if resetting[index]:
                    observation, info = client.receive_reset()
                    self._steps[index] = 0
                else:
                    observation, reward, terminated, truncated, info = client.receive_step()
                    self._steps[index] += 1
                    if self.max_episode_steps is not None and \
                            self._steps[index] >= self.max_episode_steps:
                        truncated = True
                    rewards[index], terminations[index], truncations[index] = (
                        reward, terminated, truncated
                    )
            except LOST as error:
                if self._last_observations[index] is None:
                    raise
                reason = self.sessions[index].restart(error)
                observation, info = self._last_observations[index], {"server_restarted": reason}
                truncations[index] = True
            self._last_observations[index] = observation
            observations.append(observation)
            env_infos.append(info)
        ended = terminations | truncations
        infos: dict[str, Any] = {}
        if self._mode is AutoresetMode.SAME_STEP and ended.any():
            for index in np.flatnonzero(ended):
                infos = self._add_info(
                    infos, {"final_obs": observations[index], "final_info": env_infos[index]},
                    int(index),
                )
                self.clients[index].send_reset()
            for index in np.flatnonzero(ended):
                observations[index], env_infos[index] = self.clients[index].receive_reset()
                self._last_observations[index] = observations[index]
                self._steps[index] = 0
        for index, info in enumerate(env_infos):
            infos = self._add_info(infos, info, index)
        self._autoreset = ended
        return self._batch(observations), rewards, terminations, truncations, infos

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One frame per sub-environment (``rgb_array``)."""
        if self.render_mode is None:
            return None
        return tuple(client.render() for client in self.clients)

    def __enter__(self) -> RemoteVectorEnv:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close_extras(self, **kwargs: Any) -> None:
        """Disconnect every client and stop every server this environment started."""
        for session in self.sessions:
            session.close()

    # --- internals --------------------------------------------------------------------------

    @property
    def _mode(self) -> AutoresetMode:
        return self.metadata["autoreset_mode"]

    def _connect(self, places: list[dict[str, Any]], **options: Any) -> None:
        with ThreadPoolExecutor(max_workers=min(len(places), 16)) as pool:
            futures = [pool.submit(Session, **place, **options) for place in places]
            failure: BaseException | None = None
            for future in futures:
                try:
                    self.sessions.append(future.result())
                except BaseException as error:  # keep collecting, so that nothing leaks
                    failure = failure or error
        if failure is not None:
            self.close_extras()
            raise failure

    def _batch(self, observations: list[Any]) -> Any:
        out = create_empty_array(self.single_observation_space, self.num_envs)
        return concatenate(self.single_observation_space, observations, out)

