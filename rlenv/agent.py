"""RLAgent: what the agent can do and see, and how it is rewarded (the seed's RLAgent)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from gymnasium import spaces

from rlenv.rl_node import RLNode

__all__ = ["RLAgent"]


class RLAgent(RLNode):
    """Override to define what the agent can do and see, and how it is rewarded.

    Set :attr:`action_space` and :attr:`observation_space` (gymnasium spaces) as class attributes
    or in ``__init__``. Apply the action in ``_physics_process`` (before the physics steps) and
    report the outcome of each tick in ``_after_physics_tick`` (after it stepped) with
    :meth:`add_reward`, :meth:`set_terminated` and :meth:`set_truncated` (bevy_rl's
    ``set_reward`` / ``set_terminated``); signal handlers may report too. The environment sums
    the rewards of the ticks, answers the client, and stops the action early when the episode
    ends.

    Attributes:
        reward: reward accumulated since the last answer to the client.
        terminated: the episode reached a terminal state of the task.
        truncated: the episode was cut short by something outside the task (a time limit).
    """

    action_space: spaces.Space
    observation_space: spaces.Space

    def __init__(self, name: str | None = None) -> None:
        super().__init__(name)
        self.reward = 0.0
        self.terminated = False
        self.truncated = False

    def set_action(self, action: Any) -> None:
        """Receive the client's action, already checked against :attr:`action_space`."""
        raise NotImplementedError(f"{type(self).__name__} must implement set_action")

    def reset(self, arguments: Any) -> None:
        """Put the agent in its initial state.

        ``arguments`` is what the environment's ``_reset`` passes: by default the world's
        ``sample_initial_position()``.
        """

    def get_data(self, observation_request: Mapping[str, Any]) -> Any:
        """Return the observation, a member of :attr:`observation_space`."""
        raise NotImplementedError(f"{type(self).__name__} must implement get_data")

    def _after_physics_tick(self, delta: float) -> None:
        """Called at the end of every physics tick of an action, after the physics stepped.

        Read the new state here, add rewards and set terminated or truncated.
        """

    def add_reward(self, reward: float) -> None:
        """Add ``reward`` to the reward of the current step."""
        self.reward += reward

    def set_reward(self, reward: float) -> None:
        """Replace the reward of the current step with ``reward``."""
        self.reward = reward

    def set_terminated(self, terminated: bool = True) -> None:
        """Mark the episode as ended by the task (the pole fell, the goal was reached)."""
        self.terminated = terminated

    def set_truncated(self, truncated: bool = True) -> None:
        """Mark the episode as cut short for a reason outside the task (a time limit)."""
        self.truncated = truncated
