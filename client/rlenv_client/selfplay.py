"""Self-play: some agents play a frozen copy of the learner's policy, refreshed every N steps.

A :class:`FrozenPolicy` is a callable for ``others``
(:class:`~rlenv_client.agent_vector.AgentVectorEnv`, :class:`~rlenv_client.sb3.SB3VecEnv`): it
acts for its agents with a copy of the learner's policy taken at its last
:meth:`~FrozenPolicy.refresh`, so that the opponents stay fixed while the learner improves
against them, then catch up. With Stable-Baselines3,
:class:`~rlenv_client.sb3.SelfPlayCallback` refreshes it every N steps::

    from stable_baselines3 import PPO

    from rlenv_client.sb3 import SB3VecEnv, SelfPlayCallback
    from rlenv_client.selfplay import FrozenPolicy

    frozen = FrozenPolicy()
    envs = SB3VecEnv(4, "examples.tag:TagEnvironment", agents="Runner1",
                     others={"Runner2": frozen})          # the Chaser: its heuristic
    model = PPO("MlpPolicy", envs)
    model.learn(100_000, callback=SelfPlayCallback(frozen, every=10_000))

The agents that play the copy must have the learner's spaces (the same class, say). The copy
runs in the trainer's process, between steps.
"""

from __future__ import annotations

import copy
from typing import Any

__all__ = ["FrozenPolicy"]


class FrozenPolicy:
    """A frozen copy of a policy, called on one agent's observation: ``frozen(obs) -> action``.

    Args:
        deterministic: act with the policy's most likely action (for a policy with
            ``predict(observation, deterministic=...)``, as SB3's); else sample, as the learner
            does.

    Attributes:
        policy: the copy (``None`` until the first :meth:`refresh`).
        refreshed_at: the learner's step count at each refresh, as given to :meth:`refresh`.
    """

    def __init__(self, deterministic: bool = False) -> None:
        self.deterministic = deterministic
        self.policy: Any = None
        self.refreshed_at: list[int] = []

    def refresh(self, policy: Any, steps: int = 0) -> None:
        """Take a new copy of ``policy`` (deep: training the original leaves it be).

        Args:
            policy: an object with ``predict(observation, deterministic=...)`` returning
                ``(action, state)`` (SB3's policies), or a callable ``policy(observation)``.
            steps: the learner's step count, kept in :attr:`refreshed_at`.
        """
        frozen = copy.deepcopy(policy)
        if hasattr(frozen, "set_training_mode"):  # SB3: dropout and batch norm as in predict
            frozen.set_training_mode(False)
        self.policy = frozen
        self.refreshed_at.append(int(steps))

    def __call__(self, observation: Any) -> Any:
        """The copy's action for ``observation``.

        Raises:
            RuntimeError: no copy was taken yet.
        """
        policy = self.policy
        if policy is None:
            raise RuntimeError(
                "FrozenPolicy has no copy yet: call refresh(policy) first (an "
                "SB3 SelfPlayCallback does at the start of training)"
            )
        if hasattr(policy, "predict"):
            return policy.predict(observation, deterministic=self.deterministic)[0]
        return policy(observation)
