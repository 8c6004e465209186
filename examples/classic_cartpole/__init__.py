"""Gymnasium's CartPole-v1, on rlenv's pymunk CartPole scene: change one line of a script.

The same cart, pole, track and joints as :mod:`examples.cartpole`, with gymnasium's interface
and constants, so that a script written for ``CartPole-v1`` (CleanRL's ``ppo.py``, say) trains
on ``rlenv/CartPole-v1`` unchanged and draws a comparable learning curve::

    ClassicCartPole (ClassicCartPoleEnvironment)   50 physics ticks per second, one per step
    |___PhysicsFramesTimer
    |___Agent (ClassicCartPoleAgent)               pushes left or right with 10 N
    |___World (ClassicCartPoleWorld)               the CartPole world without damping, g = 9.8

The physics is pymunk's rigid bodies and joints rather than gymnasium's closed-form Euler
update, so trajectories agree closely at first and drift apart over many steps; a policy's
returns are comparable, its transitions are not bit-identical to gymnasium's.

## Action Space
``Discrete(2)``: 0 pushes the cart to the left (-x), 1 to the right (+x), with ``max_force``
(10 N) for the step.

## Observation Space
``Box((4,), float32)``, as gymnasium's CartPole-v1:

| index | observation                          | min     | max    |
|-------|--------------------------------------|---------|--------|
| 0     | cart position x (m)                  | -4.8    | 4.8    |
| 1     | cart velocity (m/s)                  | -inf    | inf    |
| 2     | pole angle (rad, + leans to +x)      | -0.419  | 0.419  |
| 3     | pole angular velocity (rad/s)        | -inf    | inf    |

## Rewards
+1 for every step, the step on which the pole falls included (so a return is an episode's
length), as gymnasium's CartPole-v1.

## Episode End
Terminated when the pole leans more than 12 degrees or the cart's centre leaves the track
(``|x| > 2.4``). Truncated after 500 steps by the time limit of the gymnasium id
``rlenv/CartPole-v1`` (``max_episode_steps=500``), as gymnasium's.

## Physics
pymunk at 50 ticks per second (gymnasium's ``tau`` of 0.02 s) with one tick per step; gravity
(0, -9.8) m/s²; no damping; a 1 kg cart, a 1 m pole of 0.1 kg hinged at its end.

## Starting State
Cart position and velocity, pole angle and angular velocity each uniform in [-0.05, 0.05],
drawn from the episode's seeded generator; ``reset(options={"low": ..., "high": ...})`` changes
the bounds, as gymnasium's CartPole does.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv import RLEnvironment

from ..cartpole import POLE_LENGTH, CartPoleAgent, CartPoleWorld

__all__ = [
    "TARGET",
    "ClassicCartPoleAgent",
    "ClassicCartPoleEnvironment",
    "ClassicCartPoleWorld",
    "heuristic",
    "main",
]

TARGET = f"{__name__}:ClassicCartPoleEnvironment"
"""What ``rlenv serve`` takes to serve this environment."""

ANGLE_LIMIT = math.radians(12.0)
TRACK_LIMIT = 2.4
_BOUND = 0.05


def heuristic(observation: np.ndarray) -> int:
    """The classic hand-written policy: push towards where the pole is falling."""
    return int(observation[2] + 0.5 * observation[3] > 0.0)


class ClassicCartPoleWorld(CartPoleWorld):
    """The CartPole world with gymnasium's constants: no damping, gravity 9.8 m/s²."""

    def __init__(self, name: str = "World") -> None:
        super().__init__(name)
        self.damping = 1.0
        self.gravity = (0.0, -9.8)
        self._bounds = (-_BOUND, _BOUND)

    def reset(self, options: Mapping[str, Any]) -> None:
        """Start the physics afresh; ``options`` may set ``low`` and ``high``, as gymnasium's.

        Raises:
            ValueError: ``low`` is above ``high``, or either is not a number.
        """
        low, high = options.get("low", -_BOUND), options.get("high", _BOUND)
        if (
            not all(
                isinstance(bound, int | float) and not isinstance(bound, bool)
                for bound in (low, high)
            )
            or not low <= high
        ):
            raise ValueError(
                f"reset options low and high must be numbers with low <= high, "
                f"got low={low!r}, high={high!r}"
            )
        self._bounds = (float(low), float(high))
        super().reset(options)

    def sample_initial_position(self) -> np.ndarray:
        """Cart x, cart velocity, pole angle and pole angular velocity, each in [low, high]."""
        low, high = self._bounds
        return self.np_random.uniform(low, high, size=4)


class ClassicCartPoleAgent(CartPoleAgent):
    """Pushes the cart left or right; +1 per step, the last one included."""

    action_space = spaces.Discrete(2)
    observation_space = spaces.Box(
        low=-np.array([TRACK_LIMIT * 2, np.inf, ANGLE_LIMIT * 2, np.inf], dtype=np.float32),
        high=np.array([TRACK_LIMIT * 2, np.inf, ANGLE_LIMIT * 2, np.inf], dtype=np.float32),
        dtype=np.float32,
    )

    def reset(self, arguments: np.ndarray) -> None:
        """Place the cart and pole; the pole's centre moves with its rotation about the hinge."""
        super().reset(arguments)
        assert self._pole is not None
        _, velocity, angle, angular_velocity = arguments.tolist()
        half = POLE_LENGTH / 2
        self._pole.velocity = (
            velocity + half * angular_velocity * math.cos(angle),
            -half * angular_velocity * math.sin(angle),
        )

    def set_action(self, action: Any) -> None:
        """Push with ``max_force`` to the right for 1, to the left for 0."""
        self.force = self.max_force if int(action) == 1 else -self.max_force

    def _after_physics_tick(self, delta: float) -> None:
        assert self._cart is not None and self._pole is not None
        self.add_reward(1.0)
        if (
            abs(self._pole.angle) > self.angle_limit
            or abs(self._cart.position.x) > self._track_limit
        ):
            self.set_terminated()

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Cart x, cart velocity, pole angle, pole angular velocity (gymnasium's order)."""
        cart, pole = self._cart, self._pole
        assert cart is not None and pole is not None
        return np.array(
            (cart.position.x, cart.velocity.x, -pole.angle, -pole.angular_velocity),
            dtype=np.float32,
        )


class ClassicCartPoleEnvironment(RLEnvironment):
    """Gymnasium's CartPole-v1 on the pymunk CartPole scene (one physics tick per step)."""

    physics_ticks_per_second = 50
    render_view = (-3.0, -1.0, 3.0, 1.5)
    reset_options = ("low", "high")

    def __init__(self) -> None:
        super().__init__("ClassicCartPole", repeat_action=1)
        self.add_child(ClassicCartPoleAgent())
        self.add_child(ClassicCartPoleWorld())


def main() -> None:
    """Serve it: ``python -m examples.classic_cartpole [--port P]``."""
    from rlenv_tools.cli import serve_command

    raise SystemExit(serve_command(TARGET))
