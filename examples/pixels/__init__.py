"""Pixels: a dot on an 84x84 screen, observed as an RGB image (a transport benchmark and demo).

The agent moves a 3x3 dot with a discrete action; the observation is the whole screen as an
``(84, 84, 3)`` uint8 array, the size of an Atari frame, so that shipping images is measured
rather than drawing them.

## Action Space
``Discrete(5)``: stay, up, down, left, right (one pixel per tick).

## Observation Space
``Box(0, 255, (84, 84, 3), uint8)``: black screen, white dot.

## Rewards
+1 per tick the dot spends in the centre quarter of the screen.

## Episode End
Never ends by itself (use a time limit).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv import RLAgent, RLEnvironment, RLEnvWorld

__all__ = ["TARGET", "PixelsEnvironment"]

TARGET = f"{__name__}:PixelsEnvironment"
SIZE = 84
_MOVES = ((0, 0), (-1, 0), (1, 0), (0, -1), (0, 1))


class Screen(RLEnvWorld):
    """The screen the dot lives on."""

    def sample_initial_position(self) -> tuple[int, int]:
        """A random position for the dot."""
        row, column = self.np_random.integers(1, SIZE - 1, size=2)
        return int(row), int(column)


class Dot(RLAgent):
    """Moves one pixel per tick in the chosen direction and sees the whole screen."""

    action_space = spaces.Discrete(len(_MOVES))
    observation_space = spaces.Box(0, 255, (SIZE, SIZE, 3), np.uint8)

    def __init__(self) -> None:
        super().__init__("Agent")
        self.row = self.column = SIZE // 2
        self.move = _MOVES[0]

    def reset(self, arguments: tuple[int, int]) -> None:
        """Put the dot at the sampled position."""
        self.row, self.column = arguments
        self.move = _MOVES[0]

    def set_action(self, action: Any) -> None:
        """Choose the direction for the ticks of this action."""
        self.move = _MOVES[int(action)]

    def _physics_process(self, delta: float) -> None:
        self.row = min(max(self.row + self.move[0], 1), SIZE - 2)
        self.column = min(max(self.column + self.move[1], 1), SIZE - 2)

    def _after_physics_tick(self, delta: float) -> None:
        if SIZE // 4 <= self.row < 3 * SIZE // 4 and SIZE // 4 <= self.column < 3 * SIZE // 4:
            self.add_reward(1.0)

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """The screen, with the dot drawn on it."""
        screen = np.zeros((SIZE, SIZE, 3), dtype=np.uint8)
        screen[self.row - 1 : self.row + 2, self.column - 1 : self.column + 2] = 255
        return screen


class PixelsEnvironment(RLEnvironment):
    """A dot on a screen, observed as pixels."""

    def __init__(self) -> None:
        super().__init__("Pixels", repeat_action=1)
        self.dot = Dot()
        self.add_child(self.dot)
        self.add_child(Screen())

    def _draw(self) -> dict[str, Any]:
        """The screen and the dot as a draw list (there is no pymunk space to describe)."""

        def square(row: float, column: float, half: float) -> list[float]:
            y, x = SIZE - row, column  # rows grow downwards, y upwards
            return [x - half, y - half, x + half, y - half, x + half, y + half, x - half, y + half]

        return {
            "view": [0, 0, SIZE, SIZE],
            "shapes": [
                ["polygon", 0x000000, 0.0, square(SIZE / 2, SIZE / 2, SIZE / 2)],
                ["polygon", 0xFFFFFF, 0.0, square(self.dot.row + 0.5, self.dot.column + 0.5, 1.5)],
            ],
        }
