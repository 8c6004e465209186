"""Plinko's and Maze's base world, :class:`rlenv.LevelWorld` (it lives in :mod:`rlenv.levels`).

Kept so that ``from examples.levels import LevelWorld`` goes on working.
"""

from __future__ import annotations

from rlenv.levels import LevelWorld

__all__ = ["LevelWorld"]
