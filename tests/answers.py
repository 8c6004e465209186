"""One episode played on a client (``Client`` or ``LocalClient``), every answer kept."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np


def play(
    client: Any, act: Callable[[dict[str, Any]], dict[str, Any]], seed: int, steps: int
) -> list[dict[str, Any]]:
    """Reset with ``seed``, then step ``act(observation)`` until the episode ends, ``steps`` at
    most: every answer (each step's observation as copies of its arrays)."""
    observation, info = client.reset(seed=seed)
    answers = [{"observation": observation, "agents": info["agents"], "frames": info["frames"]}]
    for _ in range(steps):
        observation, reward, terminated, truncated, info = client.step(act(observation))
        answers.append(
            {
                "observation": {name: np.array(value) for name, value in observation.items()},
                "agents": info["agents"],
                "reward": reward,
                "frames": info["frames"],
                "terminated": terminated,
                "truncated": truncated,
            }
        )
        if terminated or truncated:
            break
    return answers
