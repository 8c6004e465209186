"""Environments that misbehave on purpose, to see rlenv's error handling at work.

Serve one and drive it: ``rlenv serve examples.faulty:FaultyEnvironment``.

- :class:`FaultyEnvironment`: a Discrete(3) agent whose tick raises for action 1 and whose
  observation raises for action 2 (each answered with an ``environment_error`` naming the node,
  after which a reset recovers); episodes end after 10 ticks. Its ``_draw`` always raises.
- :class:`CountingEnvironment`: the observation counts the physics ticks since the reset, so a
  client can account for every transition (the fault harness in the tests does); action 1 gives
  a NaN observation, which the server refuses to send.
- :class:`WrongShapeEnvironment`: observations that do not match the declared space, to see what
  ``rlenv check`` reports.
- :class:`UnsendableEnvironment`: after action 1, ``info`` holds a value msgpack cannot carry;
  the server answers with an ``environment_error`` instead.
- :class:`SlowEnvironment`: action 1 makes its tick sleep for an hour (a hung environment:
  what deadlines are for); action 0 behaves.
- :class:`DyingEnvironment`: action 1 ends its process at once (``os._exit``), as a crash in
  native code would; action 2 calls ``sys.exit``; action 0 behaves.
- :class:`BrittleEnvironment`: a ball under gravity; ``reset(options={"fail": True})`` makes
  its world's reset raise after it removed its physics, leaving the environment broken until
  the server rebuilds it.
- :class:`StuckEnvironment`: inside a pymunk collision callback (where cffi swallows
  exceptions, a ``SIGALRM``'s included), action 1 loops forever and action 2 sleeps for
  5 s; action 0 behaves.

## Action Space
``Discrete(3)`` (Faulty, WrongShape, Dying, Stuck) or ``Discrete(2)`` (Counting, Unsendable,
Slow, Brittle: a push left or right).

## Observation Space
``Box(0, 1000, (1,), int64)`` ticks since the reset (Faulty, Unsendable, Slow, Dying, Stuck),
``Box(0, 1e9, (1,), float64)`` (Counting), ``Box(-inf, inf, (4,), float64)`` the ball's position
and velocity (Brittle).

## Rewards
0.5 per tick (Faulty); none otherwise.

## Episode End
Faulty terminates after 10 ticks; the others never end.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import pymunk
from gymnasium import spaces

from rlenv import CollisionShape, PhysicsWorld, RigidBody, RLAgent, RLEnvironment, RLEnvWorld


class CountingWorld(RLEnvWorld):
    """No physics: counts the physics ticks it processed since the reset."""

    def __init__(self) -> None:
        super().__init__("World")
        self.ticks = 0

    def reset(self, options: Mapping[str, Any]) -> None:
        """Start counting from zero."""
        self.ticks = 0

    def _physics_process(self, delta: float) -> None:
        self.ticks += 1

    def get_data(self, observation_request: Mapping[str, Any]) -> dict[str, Any]:
        """The tick count, for displays."""
        return {"ticks": self.ticks}


class _ActionAgent(RLAgent):
    """Remembers its last (discrete) action; the subclasses misbehave on some of them."""

    def __init__(self) -> None:
        super().__init__("Agent")
        self.action = 0

    def reset(self, arguments: Any) -> None:
        """Forget the last action."""
        self.action = 0

    def set_action(self, action: Any) -> None:
        """Remember the action."""
        self.action = int(action)

    @property
    def ticks(self) -> int:
        """The ticks the counting world processed since the reset."""
        world = self.environment.world
        assert isinstance(world, CountingWorld)
        return world.ticks


class FaultyAgent(_ActionAgent):
    """Raises inside the tick for action 1, inside get_data for action 2; ends at tick 10."""

    action_space = spaces.Discrete(3)
    observation_space = spaces.Box(0, 1000, (1,), np.int64)

    def _physics_process(self, delta: float) -> None:
        if self.action == 1:
            raise RuntimeError("the agent tripped over action 1")

    def _after_physics_tick(self, delta: float) -> None:
        self.add_reward(0.5)
        if self.ticks >= 10:
            self.set_terminated()

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Ticks since the reset; raises for action 2."""
        if self.action == 2:
            raise ValueError("no observation for action 2")
        return np.array([self.ticks], dtype=np.int64)


class FaultyEnvironment(RLEnvironment):
    """A counting world and an agent that raises on demand."""

    def __init__(self) -> None:
        super().__init__("Faulty", repeat_action=3)
        self.add_child(FaultyAgent())
        self.add_child(CountingWorld())

    def _draw(self) -> dict[str, Any]:
        """Raises: an inspector's failing request must not end the controller's episode."""
        raise RuntimeError("this environment cannot draw")


class WrongShapeAgent(FaultyAgent):
    """Declares a 1-element observation and returns 2 elements."""

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Two elements where the space declares one."""
        return np.zeros(2, dtype=np.int64)


class WrongShapeEnvironment(RLEnvironment):
    """An environment whose observations do not match its observation space."""

    def __init__(self) -> None:
        super().__init__("WrongShape")
        self.add_child(WrongShapeAgent())
        self.add_child(CountingWorld())


class TickAgent(_ActionAgent):
    """Observes how many ticks ran since the reset; never terminates; NaN on action 1."""

    action_space = spaces.Discrete(2)
    observation_space = spaces.Box(0.0, 1e9, (1,), np.float64)

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Ticks since the reset, or NaN after action 1."""
        return np.array([np.nan if self.action == 1 else self.ticks], dtype=np.float64)


class CountingEnvironment(RLEnvironment):
    """Observation = physics ticks since the reset: every transition can be accounted for."""

    def __init__(self) -> None:
        super().__init__("Counting", repeat_action=50)
        self.add_child(TickAgent())
        self.add_child(CountingWorld())


class UnsendableAgent(_ActionAgent):
    """Two actions: 0 behaves, 1 makes the environment's info unsendable."""

    action_space = spaces.Discrete(2)
    observation_space = spaces.Box(0, 1000, (1,), np.int64)

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Ticks since the reset."""
        return np.array([self.ticks], dtype=np.int64)


class UnsendableEnvironment(RLEnvironment):
    """A counting world whose ``info`` holds a set (msgpack has none) after action 1."""

    def __init__(self) -> None:
        super().__init__("Unsendable", repeat_action=1)
        self.add_child(UnsendableAgent())
        self.add_child(CountingWorld())

    def _get_info(self) -> dict[str, Any]:
        """A set after action 1, which cannot travel; nothing otherwise."""
        assert isinstance(self.agent, UnsendableAgent)
        return {"odd": {1, 2}} if self.agent.action == 1 else {}


class SlowAgent(UnsendableAgent):
    """Sleeps for an hour inside the tick after action 1."""

    def _physics_process(self, delta: float) -> None:
        if self.action == 1:
            time.sleep(3600)


class SlowEnvironment(RLEnvironment):
    """A counting world whose agent hangs on action 1 (see :class:`SlowAgent`)."""

    def __init__(self) -> None:
        super().__init__("Slow", repeat_action=1)
        self.add_child(SlowAgent())
        self.add_child(CountingWorld())


class DyingAgent(UnsendableAgent):
    """Ends the whole process inside the tick after action 1; calls ``sys.exit`` after 2."""

    action_space = spaces.Discrete(3)

    def _physics_process(self, delta: float) -> None:
        if self.action == 1:
            os._exit(70)  # no cleanup, no answer: as a segfault in native code would
        if self.action == 2:
            sys.exit(3)


class DyingEnvironment(RLEnvironment):
    """A counting world whose agent kills its process on action 1 (see :class:`DyingAgent`)."""

    def __init__(self) -> None:
        super().__init__("Dying", repeat_action=1)
        self.add_child(DyingAgent())
        self.add_child(CountingWorld())


class BrittleWorld(RLEnvWorld):
    """A ball in a physics world built afresh at every reset, from the episode's generator.

    Its reset removes the old physics first and only then reads the options: with ``fail`` it
    raises there, leaving no physics at all (the half-done reset the server must recover from).
    """

    def __init__(self) -> None:
        super().__init__("World")
        self.add_child(self._physics())

    def reset(self, options: Mapping[str, Any]) -> None:
        """Build a new physics world with the ball at a seeded place.

        Raises:
            NodeNotFoundError: the physics is gone (a previous reset failed half way).
            ValueError: ``options["fail"]``, after the physics was removed.
        """
        self.remove_child(self.get_node("Physics"))
        if options.get("fail"):
            raise ValueError("this level is refused (asked with options['fail'])")
        self.add_child(self._physics())

    def _physics(self) -> PhysicsWorld:
        physics = PhysicsWorld(gravity=(0.0, -9.81), name="Physics")
        ball = RigidBody(position=(0.0, 5.0), name="Ball")
        ball.add_child(CollisionShape.circle(0.2, mass=1.0, name="Skin"))
        physics.add_child(ball)
        return physics

    def sample_initial_position(self) -> np.ndarray:
        """The ball's position and velocity, from the episode's generator."""
        return self.np_random.uniform(-1.0, 1.0, size=4)


class BrittleAgent(RLAgent):
    """Pushes the ball left (0) or right (1); observes its position and velocity."""

    action_space = spaces.Discrete(2)
    observation_space = spaces.Box(-np.inf, np.inf, (4,), np.float64)

    def __init__(self) -> None:
        super().__init__("Agent")
        self.push = 0.0

    @property
    def ball(self) -> RigidBody:
        """The ball of the world's current physics."""
        ball = self.environment.get_node("World/Physics/Ball")
        assert isinstance(ball, RigidBody)
        return ball

    def reset(self, arguments: np.ndarray) -> None:
        """Place the ball: x, y offset, and velocity from ``arguments``."""
        x, y, vx, vy = arguments.tolist()
        self.ball.position = (x, 5.0 + y)
        self.ball.velocity = (vx, vy)
        self.push = 0.0

    def set_action(self, action: Any) -> None:
        """Push right for 1, left for 0."""
        self.push = 1.0 if int(action) == 1 else -1.0

    def _physics_process(self, delta: float) -> None:
        self.ball.apply_impulse((self.push * delta, 0.0))

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """The ball's position and velocity."""
        ball = self.ball
        return np.array([*ball.position, *ball.velocity], dtype=np.float64)


class BrittleEnvironment(RLEnvironment):
    """A ball whose world's reset can fail half way (``reset(options={"fail": True})``)."""

    reset_options = ("fail",)

    def __init__(self) -> None:
        super().__init__("Brittle", repeat_action=2)
        self.add_child(BrittleAgent())
        self.add_child(BrittleWorld())


class StuckAgent(UnsendableAgent):
    """Collides two circles in a pymunk space after a non-zero action, and stalls in the callback.

    The collision callback loops forever (action 1) or sleeps for 5 s (action 2).
    """

    action_space = spaces.Discrete(3)

    def _physics_process(self, delta: float) -> None:
        if self.action:
            space = pymunk.Space()
            for _ in range(2):  # two circles at the same place: they touch at once
                body = pymunk.Body(1.0, 1.0)
                space.add(body, pymunk.Circle(body, 1.0))
            space.on_collision(begin=self._stall)
            space.step(delta)

    def _stall(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        if self.action == 1:
            while True:
                pass
        time.sleep(5.0)


class StuckEnvironment(RLEnvironment):
    """A counting world whose agent hangs inside a pymunk callback (see :class:`StuckAgent`)."""

    def __init__(self) -> None:
        super().__init__("Stuck", repeat_action=1)
        self.add_child(StuckAgent())
        self.add_child(CountingWorld())
