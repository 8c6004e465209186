"""Swarm: a flock of 64 discs heading for a nest, one :class:`~rlenv.RLAgentGroup` (a swarm).

Every member of the flock is a disc in one pymunk room; they bump into each other on the way
to the nest, a circle at a random spot, and each leaves the episode when it reaches it. Three
quarters of the flock start; the others join one by one, every 8 ticks::

    Swarm (SwarmEnvironment)
    |___PhysicsFramesTimer
    |___Flock (Flock: RLAgentGroup)   instance_count 64, initial_count 48
    |___World (SwarmWorld)
        |___Physics (PhysicsWorld)    contact_monitor False; the walls, the nest, the 64 discs

The same scene is written as 64 ``RLAgent`` nodes, ``Member0`` .. ``Member63``, in
:class:`SwarmNodesEnvironment`, and as bare pymunk and numpy in ``benchmarks/swarm.py``'s
floor: the physics and the observations are :mod:`examples.swarm.scene`'s, written once. Given
the same seed and actions the group and the nodes move the discs along the same trajectories,
bit for bit (``tests/test_swarm.py``). Sizes 16 and 256 (``SwarmEnvironment16``,
``SwarmNodesEnvironment256`` ...) are for the benchmark; the room grows with the flock (three
grid cells of 1 m a member), so that its density stays the same.

## Action Space
``Box(-1, 1, (64, 2), float32)``: a row per member, the force on its disc as a fraction of
3 N (the member's ``Box(-1, 1, (2,))``, ``client.groups["Flock"].action_space``). Rows of
members not in play are ignored.

## Observation Space
``Box(-1, 1, (64, 6), float32)``: a row per member, its position over the room's half side
(7 m), its velocity over 5 m/s, and the nest relative to it over the room's side (14 m). Rows
of members not in this answer are zeros; ``info["agents"]["Flock"]["active"]`` says which are.

## Rewards
Per member and tick in play: 0.1 per metre it came closer to the nest (negative when it went
away), -0.001 (the sooner home, the better), and +1 when it reaches the nest. A member's first
transition after it joined has reward 0.

## Episode End
A member terminates when its disc's centre is inside the nest (radius 1.05 m): its disc leaves
the room. The episode ends when every member has (the flock, as one agent, terminates), and is
truncated for the members still in play after 600 ticks (10 s, 150 steps of 4 ticks).

``Flock.heuristic`` steers every member towards the nest, braking a little (:func:`scene.steer`,
the scripted baseline); ``rlenv serve examples.swarm:SwarmEnvironment --policy
Flock=heuristic`` lets the server play the flock itself (clients watch, ``rlenv inspect``
say). Random actions bring few members home.

## Trained
``benchmarks/train_swarm.py`` trains the flock with SB3's PPO over ``SB3VecEnv(2, TARGET,
agents="Flock")``: every member of both instances a sub-environment (128), one policy for all
(``n_steps`` 64, ``batch_size`` 1024, learning rate 1e-3; torch on one thread). 3,000,000
member-steps took 656 s on the 2-core development VM (a busy one). Its deterministic policy,
the scripted flock (the ``heuristic``) and random actions, over the same 10 seeds (1000 to
1009): return per episode mean 86.97, 86.98 and -36.34 (min 84.23, 84.03, -38.74; median
87.15, 87.11, -36.47); members home per episode 64.0, 64.0 and 0.4; steps per episode mean
83.5, 83.1 and 150 (the time limit). The trained flock is as fast home as the scripted one.

## Cost
``rlenv bench --swarm`` (``benchmarks/swarm.py``): the group, the nodes and the floor for 16,
64 and 256 members; figures in benchmarks/README.md ("A swarm") and docs/several-agents.md
("Swarms").
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces

from rlenv import PhysicsWorld, RLAgent, RLAgentGroup, RLEnvironment, RLEnvWorld

from .scene import (
    DAMPING,
    EPISODE_TICKS,
    JOIN_TICKS,
    OBSERVATION_SIZE,
    SwarmBodies,
    joining,
    observe,
    starting,
    steer,
)

__all__ = [
    "EPISODE_TICKS",
    "GROUP",
    "JOIN_TICKS",
    "MEMBERS",
    "NODE_TARGETS",
    "TARGET",
    "TARGETS",
    "Flock",
    "Member",
    "SwarmEnvironment",
    "SwarmEnvironment16",
    "SwarmEnvironment256",
    "SwarmNodesEnvironment",
    "SwarmNodesEnvironment16",
    "SwarmNodesEnvironment256",
    "SwarmWorld",
    "member_name",
    "starting",
]

GROUP = "Flock"
"""The group's name (``agents="Flock"`` in the adaptors)."""
MEMBERS = 64
"""The flock of ``rlenv/Swarm-v0``."""
_MEMBER_OBSERVATION = spaces.Box(-1.0, 1.0, (OBSERVATION_SIZE,), np.float32)
_MEMBER_ACTION = spaces.Box(-1.0, 1.0, (2,), np.float32)


def member_name(slot: int) -> str:
    """The per-node version's name of member ``slot``."""
    return f"Member{slot}"


class SwarmWorld(RLEnvWorld):
    """The room: a fresh :class:`~rlenv.PhysicsWorld` and :class:`~.scene.SwarmBodies` each reset.

    Args:
        count: the most members.
    """

    def __init__(self, count: int) -> None:
        super().__init__("World")
        self.count = count
        self.physics: PhysicsWorld | None = None
        self.bodies: SwarmBodies | None = None

    def reset(self, options: Mapping[str, Any]) -> None:
        """A new space (nothing left from the last episode), the nest and the spots drawn."""
        if self.physics is not None:
            self.remove_child(self.physics)
            self.physics.queue_free()
        self.physics = PhysicsWorld(
            gravity=(0.0, 0.0), damping=DAMPING, contact_monitor=False, name="Physics"
        )  # no node listens to a contact: the discs' contacts cost pymunk's step alone
        self.add_child(self.physics)
        self.bodies = SwarmBodies(self.physics.space, self.count)
        self.bodies.reset(self.np_random)

    def get_data(self, observation_request: Mapping[str, Any]) -> dict[str, Any]:
        """``{"bodies": float64 (N, 4)}``: each disc's position and velocity, read from pymunk.

        Rows of members whose disc is not in the room are NaN (``info["world"]`` of a client
        made with ``world_data=True``; the exactness test compares them).
        """
        bodies = self.bodies
        assert bodies is not None
        states = np.full((self.count, 4), np.nan)
        for slot in np.flatnonzero(bodies.in_play).tolist():
            body = bodies.bodies[slot]
            states[slot] = (*body.position, *body.velocity)
        return {"bodies": states}


class _Swarm(RLEnvironment):
    """What both versions share: the room, the members who start and join, the time limit.

    The versions differ in who the members are (:meth:`_start`, :meth:`_join`,
    :meth:`_truncate`): rows of one group, or nodes.
    """

    members: ClassVar[int] = MEMBERS
    render_size = (400, 400)
    configurable = (*RLEnvironment.configurable, "episode_ticks")
    episode_ticks = EPISODE_TICKS
    """The time limit in ticks (configurable: ``client.configure(episode_ticks=...)``)."""

    def __init__(self) -> None:
        super().__init__("Swarm", repeat_action=4)
        self.world_node = SwarmWorld(self.members)
        self.add_child(self.world_node)
        self.ticks = 0
        self.joined = 0  # members started or joined in this episode (the next slot to join)

    @property
    def bodies(self) -> SwarmBodies:
        """The discs (built at the first reset)."""
        bodies = self.world_node.bodies
        assert bodies is not None
        return bodies

    def _reset(self, options: Mapping[str, Any]) -> None:
        self.world_node.reset(options)
        self.ticks = 0
        self.joined = starting(self.members)
        first = list(range(self.joined))
        self.bodies.add(first)
        self._start(first)

    def _physics_process(self, delta: float) -> None:
        self.ticks += 1
        if joining(self.ticks, self.joined, self.members):
            slot = self.joined
            self.joined += 1
            self.bodies.add([slot])
            self._join(slot)
        if self.ticks >= self.episode_ticks:
            self._truncate()

    def _start(self, slots: list[int]) -> None:
        raise NotImplementedError

    def _join(self, slot: int) -> None:
        raise NotImplementedError

    def _truncate(self) -> None:
        raise NotImplementedError


# --- (a) one group ---------------------------------------------------------------------------


class Flock(RLAgentGroup):
    """The flock as one group: every member's force, rewards, ends and observations as arrays."""

    instance_count = MEMBERS
    initial_count = starting(MEMBERS)
    member_observation_space = _MEMBER_OBSERVATION
    member_action_space = _MEMBER_ACTION

    def __init__(self) -> None:
        super().__init__(GROUP)

    @property
    def bodies(self) -> SwarmBodies:
        """The discs."""
        return self.parent.bodies  # type: ignore[union-attr, no-any-return]

    def _physics_process(self, delta: float) -> None:
        self.bodies.push(self.actions)

    def _after_physics_tick(self, delta: float) -> None:
        bodies = self.bodies
        bodies.read()
        rows = np.flatnonzero(bodies.in_play)
        rewards, arrived = bodies.progress(rows)
        self.rewards[rows] += rewards
        home = rows[arrived]
        if len(home):
            bodies.remove(home.tolist())
            self.terminations[home] = True

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Every member's row (the answer keeps those it reports)."""
        bodies = self.bodies
        observe(bodies.states, bodies.nest, bodies.half, self.observations)
        return self.observations

    def heuristic(self, observation: np.ndarray) -> np.ndarray:
        """Every member towards the nest, braking a little (:func:`~.scene.steer`)."""
        return steer(observation)


@functools.cache
def _flock_of(count: int) -> type[Flock]:
    """:class:`Flock` of ``count`` members (the benchmark's sizes)."""
    if count == MEMBERS:
        return Flock
    return type("Flock", (Flock,), {"instance_count": count, "initial_count": starting(count)})


class SwarmEnvironment(_Swarm):
    """``rlenv/Swarm-v0``: the flock as one :class:`Flock` group."""

    def __init__(self) -> None:
        super().__init__()
        self.flock = _flock_of(self.members)()
        self.add_child(self.flock)

    def _start(self, slots: list[int]) -> None:
        """The group starts its first ``initial_count`` members itself."""

    def _join(self, slot: int) -> None:
        self.flock.add_member(slot)

    def _truncate(self) -> None:
        self.flock.truncations[self.flock.active] = True


# --- (b) one node a member -------------------------------------------------------------------


class Member(RLAgent):
    """One member as an ``RLAgent`` node: its own force, reward, end and observation."""

    observation_space = _MEMBER_OBSERVATION
    action_space = _MEMBER_ACTION

    def __init__(self, slot: int) -> None:
        super().__init__(member_name(slot))
        self.slot = slot
        self.action = np.zeros(2, np.float32)
        self.in_play = True

    @property
    def bodies(self) -> SwarmBodies:
        """The discs."""
        return self.parent.bodies  # type: ignore[union-attr, no-any-return]

    def set_action(self, action: np.ndarray) -> None:
        """Keep the action for the ticks until the next one."""
        self.action = action

    def _physics_process(self, delta: float) -> None:
        if self.in_play:
            self.bodies.push_one(self.slot, self.action)

    def _after_physics_tick(self, delta: float) -> None:
        bodies, slot = self.bodies, self.slot
        bodies.read_one(slot)
        rewards, arrived = bodies.progress(slice(slot, slot + 1))
        self.add_reward(float(rewards[0]))
        if arrived[0]:
            bodies.remove([slot])
            self.in_play = False
            self.set_terminated()
            self.queue_free()

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """This member's row (its body read again: it may have joined in the last tick)."""
        bodies, slot = self.bodies, self.slot
        bodies.read_one(slot)
        row = np.zeros((1, OBSERVATION_SIZE), np.float32)
        observe(bodies.states[slot : slot + 1], bodies.nest, bodies.half, row)
        return row[0]

    def heuristic(self, observation: np.ndarray) -> np.ndarray:
        """Towards the nest, braking a little (:func:`~.scene.steer`)."""
        return steer(observation)


class SwarmNodesEnvironment(_Swarm):
    """The same flock as :class:`SwarmEnvironment`, each member an :class:`Member` node."""

    possible_agents: ClassVar[Mapping[str, type[RLAgent]]] = {
        member_name(slot): Member for slot in range(MEMBERS)
    }

    def _start(self, slots: list[int]) -> None:
        for node in self.get_children():
            if isinstance(node, Member):
                self.remove_child(node)
                node.queue_free()
        for slot in slots:
            self.add_child(Member(slot))

    def _join(self, slot: int) -> None:
        self.add_child(Member(slot))

    def _truncate(self) -> None:
        for agent in self.agents:
            agent.set_truncated()


# --- the benchmark's sizes -------------------------------------------------------------------


class SwarmEnvironment16(SwarmEnvironment):
    """A flock of 16, one group (the benchmark's)."""

    members = 16


class SwarmEnvironment256(SwarmEnvironment):
    """A flock of 256, one group (the benchmark's)."""

    members = 256


class SwarmNodesEnvironment16(SwarmNodesEnvironment):
    """A flock of 16, one node a member (the benchmark's)."""

    members = 16
    possible_agents = {member_name(slot): Member for slot in range(16)}


class SwarmNodesEnvironment256(SwarmNodesEnvironment):
    """A flock of 256, one node a member (the benchmark's)."""

    members = 256
    possible_agents = {member_name(slot): Member for slot in range(256)}


TARGET = f"{__name__}:SwarmEnvironment"
TARGETS = {
    16: f"{__name__}:SwarmEnvironment16",
    MEMBERS: TARGET,
    256: f"{__name__}:SwarmEnvironment256",
}
"""The group version's target by flock size."""
NODE_TARGETS = {
    16: f"{__name__}:SwarmNodesEnvironment16",
    MEMBERS: f"{__name__}:SwarmNodesEnvironment",
    256: f"{__name__}:SwarmNodesEnvironment256",
}
"""The per-node version's target by flock size."""
