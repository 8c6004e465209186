"""The spaces of the examples' agents that the policy tests export and serve policies for."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

CARTPOLE = "examples.cartpole:CartPoleEnvironment"
PAIR = "examples.pair:PairEnvironment"
CARTPOLE_OBSERVATION = gym.spaces.Box(
    np.array(
        [-4.8, -5.8, -np.pi, -np.finfo(np.float32).max, -np.finfo(np.float32).max], np.float32
    ),
    np.array([4.8, 5.8, np.pi, np.finfo(np.float32).max, np.finfo(np.float32).max], np.float32),
)
PAIR_OBSERVATION = gym.spaces.Box(
    np.array([-5, -5, -50, -50, -10, -10, -10, -10], np.float32),
    np.array([5, 5, 50, 50, 10, 10, 10, 10], np.float32),
)
STEERING = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
PUSHING = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
