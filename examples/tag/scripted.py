"""Tag as one single-agent environment: the chaser, with the runners scripted inside the game.

This is the rewrite a game developer had to write before a trainer could train the chaser of
:class:`~examples.tag.TagEnvironment` alone: the same world, the same chaser, the same runners,
each runner moved by its heuristic once per step (on the observation it would be sent, just
before the chaser's action applies, as ``rlenv serve --policy Runner1=heuristic`` does). It is
no longer needed (``SB3VecEnv(n, examples.tag.TARGET, agents="Chaser")`` trains the chaser
straight from the multi-agent game); ``benchmarks/train_one_agent.py`` keeps it as the
baseline that training from the multi-agent environment is measured against.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rlenv import RLEnvironment

from ..seeker import HALF
from . import RUNNERS, Chaser, Runner, TagWorld

__all__ = ["TARGET", "ChaseEnvironment"]

TARGET = f"{__name__}:ChaseEnvironment"


class ChaseEnvironment(RLEnvironment):
    """The chaser is the only agent; the two runners are scripted by their heuristics."""

    render_view = (-HALF - 0.5, -HALF - 0.5, HALF + 0.5, HALF + 0.5)
    render_size = (400, 400)

    def __init__(self) -> None:
        super().__init__("Chase", repeat_action=4)
        self.chaser = Chaser()
        self.add_child(self.chaser)
        self.runners = [Runner(name) for name in RUNNERS]
        for runner in self.runners:
            self.add_child(runner)
        self.add_child(TagWorld())
        self.agents = [self.chaser]  # the runners are the game's, not the trainer's
        self.agent = self.chaser

    def _reset(self, options: Mapping[str, Any]) -> None:
        """The chaser's reset, then the runners' (placed after it, as in Tag)."""
        super()._reset(options)
        world = self.world
        assert world is not None
        for runner in self.runners:
            runner.reward, runner.terminated, runner.truncated = 0.0, False, False
            runner.reset(world.sample_initial_position())

    def _step(self, action: Any, frames: int | None = None) -> None:
        """Each running runner takes its heuristic's action, then the chaser's applies."""
        for runner in self.runners:
            if not runner.terminated:
                runner.set_action(runner.heuristic(runner.get_data({})))
        super()._step(action, frames)
