"""What a trainer acts for: the server's agents less those it drives itself.

A server started with ``rlenv serve --policy NAME=FILE`` (or ``NAME=heuristic``) drives agent
``NAME`` itself, and its hello says so (``driven``, protocol 2.6). The adaptors
(:class:`~rlenv_client.env.RemoteEnv`, :class:`~rlenv_client.pettingzoo.RemoteParallelEnv`,
:class:`~rlenv_client.vector.RemoteVectorEnv`) leave those agents out, through a
:class:`TrainerView`:

- their spaces are ``Dict`` spaces of the other agents (still keyed by agent name, even when one
  is left), and their ``agents`` lists leave the driven ones out;
- an action needs no entry for a driven agent, and an entry for one is refused (a
  ``ValueError`` naming it: the trainer would believe it acts for an agent it does not);
- observations leave them out; the reward is the other agents' sum, and the episode ends when
  they are all done: ``terminated`` when each of them ended terminated, ``truncated`` when one
  was truncated. ``info["agents"]`` still reports every agent, as the server does.

A server that drives no agent gives a view that changes nothing.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, cast

from gymnasium import spaces
from gymnasium.vector.utils import concatenate, create_empty_array

from rlenv.protocol import Hello
from rlenv.protocol.messages import joint_end

if TYPE_CHECKING:  # a name only: the client's base imports the replays, which import this
    from rlenv_client.base import StepResult

__all__ = ["TrainerView"]


class TrainerView:
    """The agents of ``hello`` that a trainer acts for, and their spaces.

    Args:
        hello: the server's hello.

    Attributes:
        agents: the agents the trainer acts for, in the hello's order.
        driven: the agents the server drives (the hello's ``driven``).
        joint: whether actions are maps by agent name (the environment has several agents, or
            its agents come and go).
        action_space: the trainer's joint action space (the hello's when nothing is driven).
        observation_space: the trainer's joint observation space.

    Raises:
        ValueError: the server drives every agent: nothing is left to act for; or it has several
            agents and its spaces are not keyed by agent.
    """

    def __init__(self, hello: Hello) -> None:
        self.driven = hello.driven
        self.joint = len(hello.agents) > 1 or hello.possible_agents is not None
        self.agents = tuple(name for name in hello.agents if name not in hello.driven)
        if self.joint and not (
            isinstance(hello.action_space, spaces.Dict)
            and isinstance(hello.observation_space, spaces.Dict)
        ):
            raise ValueError(
                f"{hello.environment} has {len(hello.agents)} agents but its "
                "spaces are not keyed by agent"
            )
        if not self.agents:
            raise ValueError(
                f"the server drives every agent of {hello.environment} "
                f"({', '.join(hello.driven)}; rlenv serve --policy): there is "
                "nothing to act for; watch it (rlenv inspect), or serve it with "
                "fewer --policy"
            )
        self.action_space: spaces.Space = hello.action_space
        self.observation_space: spaces.Space = hello.observation_space
        self._driven_actions: dict[str, spaces.Space] = {}
        self._stand_ins: dict[int, dict[str, Any]] = {}  # by batch size
        if self.driven:
            assert isinstance(self.action_space, spaces.Dict)
            assert isinstance(self.observation_space, spaces.Dict)
            self._driven_actions = {name: self.action_space[name] for name in self.driven}
            self.action_space = spaces.Dict({name: self.action_space[name] for name in self.agents})
            self.observation_space = spaces.Dict(
                {name: self.observation_space[name] for name in self.agents}
            )

    def agent_spaces(self) -> tuple[dict[str, spaces.Space], dict[str, spaces.Space]]:
        """Each of the trainer's agents' action and observation spaces, by agent name.

        PettingZoo's ``action_spaces`` / ``observation_spaces`` and RLlib's per-agent maps.
        """
        if not self.joint:
            name = self.agents[0]
            return {name: self.action_space}, {name: self.observation_space}
        actions, observations = self.action_space, self.observation_space
        assert isinstance(actions, spaces.Dict) and isinstance(observations, spaces.Dict)
        return dict(actions.spaces), dict(observations.spaces)

    def action(self, action: Any) -> Any:
        """``action`` as the server takes it; refused if it acts for a driven agent.

        Raises:
            ValueError: an entry for a driven agent.
        """
        if self.driven and isinstance(action, Mapping):
            self.refuse_driven(action)
        return action

    def refuse_driven(self, actions: Mapping[str, Any]) -> None:
        """Refuse ``actions`` (keyed by agent name) if one is for a driven agent.

        Raises:
            ValueError: naming the first such agent.
        """
        for name in actions:
            if name in self.driven:
                raise ValueError(
                    f"agent {name!r} is driven by the server (rlenv serve "
                    f"--policy {name}=...): it takes no action from here; act "
                    f"for {', '.join(self.agents)} only"
                )

    def observation(self, observation: Any) -> Any:
        """``observation`` without the driven agents' (a map by agent name, or one batch)."""
        if not self.driven:
            return observation
        return {name: observation[name] for name in self.agents}

    def result(self, result: StepResult) -> StepResult:
        """A step's result for the trainer's agents (see :meth:`outcome`)."""
        if not self.driven:
            return result
        observation, _, _, _, info = result
        return (self.observation(observation), *self.outcome(info), info)

    def outcome(self, info: Mapping[str, Any]) -> tuple[float, bool, bool]:
        """The trainer's agents' reward, terminated and truncated, from ``info["agents"]``."""
        mine = [info["agents"][name] for name in self.agents]
        terminated, truncated = joint_end((o["terminated"], o["truncated"]) for o in mine)
        return float(sum(o["reward"] for o in mine)), terminated, truncated

    def full_actions(self, actions: Any, count: int) -> Any:
        """A batch of ``count`` trainer actions with stand-ins for the driven agents.

        A ``steps`` request carries every agent's column; the server ignores the driven
        agents' (their policy acts), so any member of their space will do.
        """
        if not self.driven:
            return actions
        self.refuse_driven(actions)
        stand_ins = self._stand_ins.get(count)
        if stand_ins is None:
            stand_ins = self._stand_ins[count] = {
                name: _stand_in(space, count) for name, space in self._driven_actions.items()
            }
        return {**actions, **stand_ins}


def _stand_in(space: spaces.Space, count: int) -> Any:
    """``count`` copies of one member of ``space``, batched."""
    space = copy.deepcopy(space)  # seeding the hello's own would change its samples
    space.seed(0)
    one = space.sample()
    out = cast(Any, create_empty_array(space, count))  # an action space: never None
    return concatenate(space, [one] * count, out)
