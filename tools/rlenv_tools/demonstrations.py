"""Demonstrations: episodes played by a person or a scripted controller, recorded for datasets.

Each episode is written as :class:`~rlenv_client.replay.RecordEpisodes` writes it (an
``episode-NNNN.rlenv`` file that ``rlenv replay`` re-runs bit for bit), numbered after the
directory's existing ones, so several sessions fill one dataset. A person plays from the
inspector's page (``rlenv inspect HOST:PORT --record-demonstrations DIR``, see
:mod:`rlenv_tools.inspector._control`); a script with :func:`record`::

    from rlenv_tools.demonstrations import record
    record("examples.cartpole:CartPoleEnvironment", my_controller, 10, "demos/", seed=0)
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium

from rlenv_client.env import RemoteEnv
from rlenv_client.replay import EpisodeFile, digest, next_episode_path

__all__ = ["record"]


def record(
    target_or_env: str | gymnasium.Env,
    controller: Callable[[Any], Any],
    episodes: int,
    directory: str | Path,
    seed: int | None = None,
) -> list[Path]:
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
        env = (
            gymnasium.make(target_or_env)
            if target_or_env in gymnasium.registry
            else RemoteEnv(target_or_env)
        )
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
            EpisodeFile(
                remote.target,
                remote.client.snapshot(),  # type: ignore[attr-defined]
                seen,
            ).save(path)
            written.append(path)
    finally:
        if env is not target_or_env:
            env.close()
    return written
