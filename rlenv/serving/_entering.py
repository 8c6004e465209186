"""Entering: an instance's environment put in a tree of its own, with its agents and spaces.

The instance enters its environment once at the start, and again each time it rebuilds it from
its class after user code raised (:mod:`rlenv.serving._recovery`); a rebuilt environment must
have the spaces of the one it replaces, which clients hold.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from gymnasium import spaces

from rlenv.communication import Served
from rlenv.environment import RLEnvironment
from rlenv.node import check_initialised
from rlenv.serving._agents_in_play import roster_of
from rlenv.serving._roster import Roster
from rlenv.tree import SceneTree

__all__ = ["Entered", "enter"]


class Entered(NamedTuple):
    """An environment in its new tree: its agents and their joint spaces."""

    tree: SceneTree
    roster: Roster
    action_space: spaces.Space
    observation_space: spaces.Space


def enter(
    environment: RLEnvironment,
    served: Served,
    clock: Callable[[], float],
    replaced: tuple[spaces.Space, spaces.Space] | None = None,
) -> Entered:
    """Put ``environment`` in a new, paused tree on ``clock`` (its ``_ready`` runs).

    Its requests are served by ``served`` (the instance). An environment rebuilt to replace
    another must have the ``replaced`` one's spaces (action, observation).

    Raises:
        TypeError: the environment's ``__init__`` did not call ``super().__init__()``.
        RuntimeError: the environment has no agent, no world, or an agent without spaces,
            or (rebuilt) spaces other than those of the environment it replaces.
    """
    check_initialised(environment)
    environment.communication.bind(served)
    tree = SceneTree(environment.physics_ticks_per_second, clock=clock)
    tree.root.add_child(environment)
    tree.paused = True
    roster = roster_of(environment)
    action_space = roster.space("action_space")
    observation_space = roster.space("observation_space")
    if replaced is not None and (action_space, observation_space) != replaced:
        raise RuntimeError(
            f"the rebuilt {type(environment).__name__} has other spaces "
            "than the one it replaces; clients hold the first ones"
        )
    return Entered(tree, roster, action_space, observation_space)
