"""Environments for the tests of level edits (``rlenv serve level_edit_envs:...``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from examples.plinko import PlinkoAgent, PlinkoWorld
from rlenv import RLEnvironment


class FragileWorld(PlinkoWorld):
    """Plinko's world, whose edits fail on purpose for some levels (named by a string)."""

    def _edit_level(self, level: Any, rng: np.random.Generator, n_edits: int) -> Any:
        """Refuse ``"refuse"``, raise on ``"crash"``, return what cannot travel for
        ``"untravelled"``; edit anything else as Plinko does."""
        if level == "refuse":
            raise ValueError("this world edits no such level")
        if level == "crash":
            raise RuntimeError("the editor broke")
        if level == "untravelled":
            return {1: "a map key that is not a str"}
        return super()._edit_level(level, rng, n_edits)


class FragilePlinko(RLEnvironment):
    """Plinko with a :class:`FragileWorld`."""

    reset_options = ("level",)

    def __init__(self) -> None:
        super().__init__("FragilePlinko", repeat_action=4)
        self.add_child(PlinkoAgent())
        self.add_child(FragileWorld())
