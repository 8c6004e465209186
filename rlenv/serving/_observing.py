"""Observing: what an ``observation`` part asks for, gathered from the environment's nodes.

The agent's observation is packed by its space's codec (refused when it does not fit or holds
NaN or infinity); world data, draw lists and frames come from the environment as they are,
checked to be data a client can read (every map key a str).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rlenv.agent import RLAgent
from rlenv.environment import RLEnvironment
from rlenv.protocol.codec import find_non_text_key
from rlenv.protocol.spaces import Codec, SpaceMismatch, codec_for, find_non_finite
from rlenv.serving._agents_in_play import AgentsInPlay
from rlenv.serving._roster import Roster

__all__ = ["Observer", "check_text_keys", "non_finite_observation", "packed_observation"]


class Observer:
    """Gathers observations of one environment for its answers.

    Args:
        environment: the environment observed.
        agents: its agents; with several, agent observations are keyed by agent name.
    """

    def __init__(self, environment: RLEnvironment, roster: Roster) -> None:
        self.environment = environment
        agents = roster.agents
        self._agents = [(agent, codec_for(agent.observation_space)) for agent in agents]
        self._several = roster.several
        self._in_play = roster if isinstance(roster, AgentsInPlay) else None
        if self._in_play is not None:
            codecs = {
                name: codec_for(one.observation_space)
                for name, one in self._in_play.possible.items()
            }
            self._codecs = codecs
            self._asked: Any = {}
            self._in_play._observe = lambda agent: packed_observation(
                agent, codecs[agent.name], self._asked
            )

    def observe(self, request: Mapping[str, Any], reports: bool = True) -> dict[str, Any]:
        """The parts of the state an ``observation`` part asks for.

        While agents come and go, the agents the answer holds: those due (every agent in play
        for an answer that does not ``reports``), and those that left since the last answer.

        Raises:
            ValueError: an agent's observation does not fit its space or is not finite, or data
                holds a map key that is not a str (the environment's fault: answered as
                ``environment_error``).
        """
        observation: dict[str, Any] = {}
        environment = self.environment
        if "agent" in request:
            asked = request["agent"]
            in_play = self._in_play
            if in_play is not None:
                self._asked = asked
                codecs = self._codecs
                observation["agent"] = {
                    agent.name: packed_observation(agent, codecs[agent.name], asked)
                    for agent in in_play.answering(reports)
                }
                for name, gone in in_play.departures(reports).items():
                    observation["agent"][name] = gone.observation
            elif self._several:
                observation["agent"] = {
                    agent.name: packed_observation(agent, codec, asked)
                    for agent, codec in self._agents
                }
            else:
                agent, codec = self._agents[0]
                observation["agent"] = packed_observation(agent, codec, asked)
        if "world" in request:
            world = environment.world
            assert world is not None
            data = observation["world"] = world.get_data(request["world"])
            check_text_keys(data, f"{type(world).__name__}.get_data() returned")
        if "render" in request:
            size = request["render"]
            width, height = environment.render_size
            observation["render"] = environment._render(
                size.get("width", width), size.get("height", height)
            )
        if "draw" in request:
            drawn = observation["draw"] = environment._draw()
            check_text_keys(drawn, "_draw() returned")
        return observation


def packed_observation(agent: RLAgent, codec: Codec, request: Any) -> Any:
    """The agent's observation (``get_data(request)``) packed by ``codec``.

    Raises:
        FloatingPointError: it holds NaN or infinity (saying where).
        ValueError: it does not fit the agent's observation space.
    """
    data = agent.get_data(request)
    if agent._IS_GROUP:  # rows of members not in the answer are zeros
        data = agent._members.observed(data)  # type: ignore[attr-defined]
    try:
        return codec.pack(data)
    except SpaceMismatch as error:
        not_finite = non_finite_observation(agent, data)
        if not_finite is not None:
            raise not_finite from None
        raise ValueError(
            f"the observation of {agent.get_path()} does not fit its space "
            f"{agent.observation_space}: it {error}"
        ) from None


def non_finite_observation(agent: RLAgent, data: Any) -> FloatingPointError | None:
    """The error for ``agent``'s observation ``data`` holding NaN or infinity, saying where.

    ``None`` when it holds neither.
    """
    where = find_non_finite(data)
    if where is None:
        return None
    whose = f"{agent.get_path()}"
    if agent._IS_GROUP and where:  # its first index is a member's
        whose = f"member {where[1:].split(',')[0].rstrip(']')} of group {whose}"
    return FloatingPointError(
        f"the observation of {whose} is not finite at {where or '()'}: {data!r:.200}"
    )


def check_text_keys(value: Any, what: str) -> None:
    """Refuse data whose maps have a key that is not a str (clients refuse such a frame).

    Raises:
        ValueError: naming ``what`` and the key (the environment's fault: an
            ``environment_error``).
    """
    problem = find_non_text_key(value)
    if problem is not None:
        raise ValueError(f"{what} data that cannot travel: {problem}")
