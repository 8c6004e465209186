"""RLEnvWorld: everything in the environment but the agents (the seed's RLEnvWorld)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rlenv.rl_node import RLNode

__all__ = ["RLEnvWorld"]


class RLEnvWorld(RLNode):
    """Override to build, reset and describe the world the agent lives in.

    Build the physics (a :class:`~rlenv.scene2d.physics.PhysicsWorld` and its bodies) in
    ``__init__``, ``_ready`` or the first :meth:`reset`; an environment that must give the same
    episode for the same seed starts its physics afresh in every :meth:`reset`
    (:meth:`~rlenv.scene2d.physics.PhysicsWorld.restart`).
    """

    def reset(self, options: Mapping[str, Any]) -> None:
        """Put the world in its initial state, at the start of every episode.

        The default ``RLEnvironment._reset`` calls it before the agents' ``reset``.

        Args:
            options: the client's reset options (``reset(options=...)``), ``{}`` if none.
        """

    def get_data(self, observation_request: Mapping[str, Any]) -> Any:
        """Return world data the client asked for (not part of the agent's observation).

        Clients get it as ``info["world"]`` (``Client(world_data=True)``) or from ``observe()``;
        it must be msgpack-able (numbers, strings, lists, maps, numpy arrays).

        Args:
            observation_request: what the client asked for, ``{}`` by default.
        """
        return {}

    def sample_initial_position(self) -> Any:
        """Draw the agent's initial state (use :attr:`np_random`); passed to ``agent.reset``."""
        return None
