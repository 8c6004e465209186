"""Environments whose agents come and go, and decide at their own pace (issue 42).

``Walker``: a point on a line; its action (``Discrete(3)``: -1, 0, +1) is its velocity per tick;
it observes its position and the episode's tick, and earns 1 per tick in play. Everything is
deterministic, so a test can say which tick did what.

``ComeAndGoEnvironment`` (possible agents A, B, C, D): A and B start; C is added at tick 6 (in
``_physics_process``: deferred to the end of the pass), B is freed at tick 10 (``queue_free``),
A terminates at tick 20 (``set_terminated``, it stays in the tree), C is truncated at tick 30;
then no one is left. ``world`` settings ask for hostile changes at tick 3: ``add_again`` (an
agent under a used name), ``add_undeclared``, ``add_wrong_class``.

``PacedEnvironment``: ``Fast`` decides every 2 ticks, ``Slow`` every 6 ticks at offset 3, and
``Plain`` at every answer (no period); ``Jerky`` (period 4) does not act between decisions.

``DrivenEnvironment``, for a server that drives its ``Steady`` agents (``rlenv serve
--policy Follower=heuristic --policy Late=heuristic``): ``Leader`` decides every 4 ticks,
``Follower`` every 3 at offset 1 (inside the leader's steps), ``Late`` (every 2) joins at tick 5
and is freed at tick 13, both inside a step; every agent is truncated at tick 24.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv import RLAgent, RLEnvironment, RLEnvWorld

__all__ = [
    "ComeAndGoEnvironment",
    "DrivenEnvironment",
    "FixedEnvironment",
    "PacedEnvironment",
    "Steady",
    "Walker",
]


class Walker(RLAgent):
    """A point on a line that walks at its action's velocity."""

    action_space = spaces.Discrete(3)
    observation_space = spaces.Box(-1000.0, 1000.0, (2,), np.float32)
    configurable = ("stride",)

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.stride = 1.0  # a setting: how far a step of velocity 1 goes
        self.position = 0.0
        self.velocity = 0.0
        self.actions: list[tuple[int, Any]] = []  # (tick, action) as set_action got them
        self.observed_at: list[int] = []  # the ticks get_data ran at

    def set_action(self, action: Any) -> None:
        self.actions.append((_tick(self), action))
        self.velocity = float(action) - 1.0 if action is not None else 0.0

    def no_action(self) -> Any:
        return None  # no velocity at all (the idle action would be -1: Discrete's start)

    def reset(self, arguments: Any) -> None:
        self.position = 0.0
        self.velocity = 0.0

    def _physics_process(self, delta: float) -> None:
        self.position += self.velocity * self.stride

    def _after_physics_tick(self, delta: float) -> None:
        self.add_reward(1.0)

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        assert self.is_inside_tree(), f"{self.name} observed outside the tree"
        self.observed_at.append(_tick(self))
        return np.array([self.position, _tick(self)], dtype=np.float32)


class Sprinter(RLAgent):
    """Not a Walker (the declaration names Walker for D: a mismatch)."""

    action_space = Walker.action_space
    observation_space = Walker.observation_space


class Steady(Walker):
    """A walker with a heuristic: right up to position 3, then back (a server may drive it)."""

    def heuristic(self, observation: np.ndarray) -> int:
        return 2 if observation[0] < 3 else 0


def _tick(agent: RLAgent) -> int:
    environment = agent.get_parent()
    return getattr(environment, "ticks", 0)


class LineWorld(RLEnvWorld):
    """Nothing but settings: which hostile change the environment makes at tick 3."""

    configurable = ("add_again", "add_undeclared", "add_wrong_class")

    def __init__(self) -> None:
        super().__init__("World")
        self.add_again = self.add_undeclared = self.add_wrong_class = False

    def reset(self, options: Mapping[str, Any]) -> None:
        pass

    def get_data(self, observation_request: Mapping[str, Any]) -> Any:
        return {}


class ComeAndGoEnvironment(RLEnvironment):
    """A and B start, C joins at tick 6, B is freed at 10, A terminates at 20, C truncated at 30."""

    possible_agents = {"A": Walker, "B": Walker, "C": Walker, "D": Walker}

    def __init__(self) -> None:
        super().__init__("ComeAndGo", repeat_action=4)
        self.add_child(LineWorld())
        self.ticks = 0

    def _reset(self, options: Mapping[str, Any]) -> None:
        for node in list(self.get_children()):
            if isinstance(node, Walker):
                self.remove_child(node)
                node.queue_free()
        self.ticks = 0
        self.add_child(Walker("A"))
        self.add_child(Walker("B"))

    def _physics_process(self, delta: float) -> None:
        self.ticks += 1
        world = self.world
        assert isinstance(world, LineWorld)
        if self.ticks == 3:
            if world.add_again:
                self.add_child(Walker("A"))
            if world.add_undeclared:
                self.add_child(Walker("E"))
            if world.add_wrong_class:
                self.add_child(Sprinter("D"))
        if self.ticks == 6:
            self.add_child(Walker("C"))
        if self.ticks == 10:
            self.get_node("B").queue_free()
        if self.ticks == 20:
            self.get_node("A").set_terminated()
        if self.ticks == 30:
            self.get_node("C").set_truncated()


class _CountingEnvironment(RLEnvironment):
    """A fixed set of walkers, counting the episode's ticks; ``_tick`` acts on each."""

    ticks = 0

    def _reset(self, options: Mapping[str, Any]) -> None:
        self.ticks = 0
        for agent in self.agents:
            agent.reset(None)

    def _physics_process(self, delta: float) -> None:
        self.ticks += 1
        self._tick()

    def _tick(self) -> None:
        """What the environment does at the tick just counted."""


class PacedEnvironment(_CountingEnvironment):
    """Four agents, three paces: Fast every 2 ticks, Slow every 6 at 3, Plain every answer."""

    def __init__(self) -> None:
        super().__init__("Paced", repeat_action=4)
        fast, slow, plain, jerky = (Walker(name) for name in ("Fast", "Slow", "Plain", "Jerky"))
        fast.decision_period = 2
        slow.decision_period, slow.decision_offset = 6, 3
        jerky.decision_period, jerky.act_between_decisions = 4, False
        for agent in (fast, slow, plain, jerky):
            self.add_child(agent)
        self.add_child(LineWorld())

    def _tick(self) -> None:
        if self.ticks >= 24:
            for agent in self.agents:
                agent.set_truncated()


class FixedEnvironment(_CountingEnvironment):
    """Two walkers, no declaration, no periods: every agent at every answer, as ever."""

    def __init__(self) -> None:
        super().__init__("Fixed", repeat_action=4)
        self.add_child(Walker("A"))
        self.add_child(Walker("B"))
        self.add_child(LineWorld())

    def _tick(self) -> None:
        if self.ticks == 6:
            self.add_child(Walker("C"))


class DrivenEnvironment(_CountingEnvironment):
    """A leader every 4 ticks; ``Steady`` agents (driven) deciding inside its steps."""

    possible_agents = {"Leader": Walker, "Follower": Steady, "Late": Steady}

    def __init__(self) -> None:
        super().__init__("Driven", repeat_action=4)
        leader, follower = Walker("Leader"), Steady("Follower")
        leader.decision_period = 4
        follower.decision_period, follower.decision_offset = 3, 1
        self.add_child(leader)
        self.add_child(follower)
        self.add_child(LineWorld())

    def _reset(self, options: Mapping[str, Any]) -> None:
        late = self.get_node_or_null("Late")
        if late is not None:
            self.remove_child(late)
            late.queue_free()
        super()._reset(options)

    def _tick(self) -> None:
        if self.ticks == 5:
            late = Steady("Late")
            late.decision_period = 2
            self.add_child(late)
        if self.ticks == 13:
            self.get_node("Late").queue_free()
        if self.ticks >= 24:
            for agent in self.agents:
                agent.set_truncated()
