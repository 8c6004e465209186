"""Demonstrations: episodes played by a person or a scripted controller, recorded for datasets.

Each episode is written as :class:`~rlenv_client.replay.RecordEpisodes` writes it (an
``episode-NNNN.rlenv`` file that ``rlenv replay`` re-runs bit for bit), numbered after the
directory's existing ones, so several sessions fill one dataset. A person plays from the
inspector's page (``rlenv inspect HOST:PORT --record-demonstrations DIR``, see
:mod:`rlenv_client.inspector.control`); a script with :func:`record`::

    from rlenv_client.demonstrations import record
    record("examples.cartpole:CartPoleEnvironment", my_controller, 10, "demos/", seed=0)
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from rlenv_client.env import RemoteEnv
from rlenv_client.replay import EpisodeFile, digest

__all__ = ["held_action", "idle_action", "next_episode_path", "record"]

_NAME = re.compile(r"episode-(\d+)\.rlenv")


def record(target_or_env: str | gymnasium.Env, controller: Callable[[Any], Any], episodes: int,
           directory: str | Path, seed: int | None = None) -> list[Path]:
    """Play ``episodes`` whole episodes with ``controller`` and record each into ``directory``.

    Args:
        target_or_env: ``MODULE:CLASS`` or a registered id (``rlenv/CartPole-v0``), started
            and closed here, or an rlenv gymnasium environment (left open).
        controller: ``controller(observation) -> action``, called before every step.
        episodes: how many episodes to play, each until it terminates or is truncated.
        directory: where the ``episode-NNNN.rlenv`` files go (created if missing).
        seed: the first episode's seed (the next ones get ``seed + 1``, ...); ``None``: the
            server's generator goes on.

    Returns:
        The files written, in order.
    """
    if isinstance(target_or_env, str):
        env = gymnasium.make(target_or_env) if target_or_env in gymnasium.registry \
            else RemoteEnv(target_or_env)
    else:
        env = target_or_env
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    remote = env.unwrapped
    written = []
    try:
        for episode in range(episodes):
            observation, _ = env.reset(seed=None if seed is None else seed + episode)
            seen = [digest(observation)]
            done = False
            while not done:
                observation, _, terminated, truncated, _ = env.step(controller(observation))
                seen.append(digest(observation))
                done = terminated or truncated
            path = next_episode_path(folder)
            EpisodeFile(remote.target, remote.client.snapshot(),  # type: ignore[attr-defined]
                        seen).save(path)
            written.append(path)
    finally:
        if env is not target_or_env:
            env.close()
    return written


def next_episode_path(directory: Path) -> Path:
    """``directory/episode-NNNN.rlenv``, numbered after the highest one there."""
    numbers = [int(match.group(1)) for path in directory.iterdir()
               if (match := _NAME.fullmatch(path.name))]
    return directory / f"episode-{max(numbers, default=0) + 1:04d}.rlenv"


def idle_action(space: spaces.Space) -> Any:
    """The action while no key is held: 0 (clipped into a ``Box``'s bounds), ``start``.

    ``Tuple`` and ``Dict`` spaces get their items' idle actions.

    Raises:
        ValueError: a space with no such action (a ``Text``, a ``Graph``...).
    """
    if isinstance(space, spaces.Discrete):
        return int(space.start)
    if isinstance(space, spaces.Box):
        return np.clip(np.zeros(space.shape), space.low, space.high).astype(space.dtype)
    if isinstance(space, spaces.MultiDiscrete):
        return np.array(space.start, dtype=space.dtype)
    if isinstance(space, spaces.MultiBinary):
        return np.zeros(space.shape, dtype=space.dtype)
    if isinstance(space, spaces.Tuple):
        return tuple(idle_action(item) for item in space.spaces)
    if isinstance(space, spaces.Dict):
        return {key: idle_action(item) for key, item in space.spaces.items()}
    raise ValueError(f"{space} has no idle action for demonstrations")


def held_action(space: spaces.Space, actions: Sequence[Any]) -> Any:
    """The action of the held keys' ``actions`` (oldest first), or the idle action.

    In a ``Box`` the keys add up (left and up: a diagonal), clipped into the bounds; in any
    other space the last pressed counts.
    """
    idle = idle_action(space)
    if not actions:
        return idle
    if isinstance(space, spaces.Box):
        total = idle + sum(np.asarray(action, space.dtype) - idle for action in actions)
        return np.clip(total, space.low, space.high).astype(space.dtype)
    return actions[-1]
