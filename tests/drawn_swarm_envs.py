"""``tests/swarm_envs.py``'s discs and shepherd in a ``PhysicsWorld``, which viewers draw.

``DrawnMixedEnvironment`` is ``MixedEnvironment`` whose pymunk space is a ``PhysicsWorld``'s
(a fresh one each reset), so that its draw list (the inspector's canvas) holds every disc in
play: the group's members and the shepherd.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rlenv import PhysicsWorld, RLEnvironment
from tests.swarm_envs import Discs, DiscWorld, Shepherd

__all__ = ["DrawnMixedEnvironment"]


class DrawnWorld(DiscWorld):
    """The discs' space is its PhysicsWorld child's, which steps it."""

    def reset(self, options: Mapping[str, Any]) -> None:
        old = self.get_node_or_null("Physics")
        if old is not None:
            self.remove_child(old)
            old.queue_free()
        physics = PhysicsWorld(gravity=(0.0, 0.0), damping=0.5, name="Physics")
        self.add_child(physics)
        self.space = physics.space
        self.ticks = 0

    def _physics_process(self, delta: float) -> None:
        self.ticks += 1  # the PhysicsWorld steps the space


class DrawnMixedEnvironment(RLEnvironment):
    """The group of discs beside the shepherd, in a PhysicsWorld."""

    render_view = (-4.0, -4.0, 4.0, 4.0)

    def __init__(self) -> None:
        super().__init__("DrawnMixed", repeat_action=4)
        self.add_child(Discs())
        self.add_child(Shepherd())
        self.add_child(DrawnWorld())
