"""RLEnvWorld: everything in the environment but the agents (the seed's RLEnvWorld)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rlenv.rl_node import RLNode

__all__ = ["RLEnvWorld"]


class RLEnvWorld(RLNode):
    """Override to build, reset and describe the world the agent lives in."""

    def reset(self, options: Mapping[str, Any]) -> None:
        """Put the world in its initial state; ``options`` are the client's reset options."""

    def get_data(self, observation_request: Mapping[str, Any]) -> Any:
        """Return world data the client asked for (not part of the agent's observation)."""
        return {}

    def sample_initial_position(self) -> Any:
        """Draw the agent's initial state (use :attr:`np_random`); passed to ``agent.reset``."""
        return None
