"""The torch module :func:`rlenv_tools.policies.export_onnx` exports: a policy's actions.

Needs torch (imported here, so import this module only where torch is wanted).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium import spaces

__all__ = ["Actor"]


class Actor(torch.nn.Module):
    """A batch of observations to their deterministic actions, post-processed in the graph.

    Args:
        policy: a Stable-Baselines3 policy (``sb3``), or a module whose ``forward`` gives
            actions (``Box``) or logits (``Discrete``).
        action_space: the action space (``Box`` or ``Discrete``).
        sb3: ``policy`` is Stable-Baselines3's: its ``_predict(observation, deterministic=True)``
            is the action before ``predict`` unscales (a squashing policy, as SAC's) or clips it.
    """

    def __init__(self, policy: Any, action_space: spaces.Box | spaces.Discrete, sb3: bool) -> None:
        super().__init__()
        self.policy, self.sb3 = policy, sb3
        self.discrete = isinstance(action_space, spaces.Discrete)
        self.start = int(action_space.start) if self.discrete else 0  # type: ignore[union-attr]
        self.squash = sb3 and bool(getattr(policy, "squash_output", False))
        self.dtype = np.dtype(action_space.dtype)
        self.torch_dtype = torch.from_numpy(np.zeros(0, self.dtype)).dtype
        if not isinstance(action_space, spaces.Discrete):  # not self.discrete: a Box
            self.register_buffer("low", torch.as_tensor(action_space.low, dtype=torch.float32))
            self.register_buffer("high", torch.as_tensor(action_space.high, dtype=torch.float32))
        if sb3:
            policy.set_training_mode(False)
        else:
            policy.eval()

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        """The actions of a batch of observations, in the action space's dtype."""
        if self.sb3:
            actions = self.policy._predict(observation, deterministic=True)
        else:
            actions = self.policy(observation)
            if self.discrete:
                actions = torch.argmax(actions, dim=-1) + self.start
        if not self.discrete:
            if self.squash:  # SB3's unscale_action: [-1, 1] onto [low, high]
                actions = self.low + 0.5 * (actions + 1.0) * (self.high - self.low)
            else:
                actions = torch.maximum(torch.minimum(actions, self.high), self.low)
        return actions.to(self.torch_dtype)

    def reference(self, observations: np.ndarray) -> np.ndarray:
        """The torch policy's own actions (SB3's ``predict(deterministic=True)``), in numpy."""
        if self.sb3:
            actions, _ = self.policy.predict(observations, deterministic=True)
            return np.asarray(actions)
        with torch.no_grad():
            out = self.policy(torch.as_tensor(observations)).numpy()
        if self.discrete:
            return (np.argmax(out, axis=-1) + self.start).astype(self.dtype)
        return np.clip(out, self.low.numpy(), self.high.numpy()).astype(self.dtype)
