"""RLEnvWorld: everything in the environment but the agents (the seed's RLEnvWorld)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from rlenv.rl_node import RLNode

__all__ = ["MAX_LEVEL_EDITS", "RLEnvWorld"]

MAX_LEVEL_EDITS = 64
"""The most edits one ``edit_level`` request may ask for (``n_edits``)."""


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

    def check_options(self, options: Mapping[str, Any]) -> None:
        """Override to check a reset's options before anything changes (a level's data, say).

        The server calls it while it checks a request that starts an episode with options (a
        ``reset``, one in a ``batch`` or a ``steps`` request's ``reset_with``, a ``restore``),
        before any part of the request is applied: a refusal leaves the episode under way as
        it was, and watchers go on observing it. Check here what :meth:`reset` would refuse
        half way. What it builds to check may be kept for the :meth:`reset` that follows (the
        same ``options`` object comes to it).

        Args:
            options: the reset's options (never empty).

        Raises:
            ValueError: the options are refused: the client gets ``bad_request`` with the
                message (any other exception is an ``environment_error``; nothing changed).
        """

    def sample_initial_position(self) -> Any:
        """Draw the agent's initial state (use :attr:`np_random`); passed to ``agent.reset``."""
        return None

    def _edit_level(self, level: Any, rng: np.random.Generator, n_edits: int) -> Any:
        """Override to offer edits of levels (ACCEL): ``level`` with ``n_edits`` random changes.

        Clients ask for it with ``client.edit_level(level, seed, n_edits)`` (the protocol's
        ``edit_level`` part), from the controlling connection, with or without an episode; a
        level beyond the hello's limits never reaches it (its nodes, their depth). Build the edit
        from ``level`` (and settings such as a difficulty), never from the live tree, and change
        nothing of the environment. An environment that does not override it refuses every
        ``edit_level`` request with ``bad_request``.

        Args:
            level: the level's data, as a reset's ``options["level"]`` takes it, or an int seed
                (the level a reset with that seed builds). It comes from the network: check it.
            rng: every random choice comes from it (seeded by the request: the same seed gives
                the same edit).
            n_edits: how many changes to make, 1 to :data:`MAX_LEVEL_EDITS`.

        Returns:
            The edited level's data, which a reset's ``options["level"]`` takes: plain msgpack
            data (maps with str keys, lists, numbers, strings, bytes, booleans, nil, numpy
            arrays).

        Raises:
            ValueError: ``level`` is not a level this environment can edit (the client gets
                ``bad_request`` with the message); any other exception is an
                ``environment_error``, and the episode goes on.
        """
        raise NotImplementedError(f"{type(self).__name__} has no _edit_level")
