"""PettingZoo ``ParallelEnv`` over a multi-agent rlenv environment.

A server with several agents declares ``Dict`` action and observation spaces keyed by agent
name; this adaptor splits them back into PettingZoo's per-agent view. Agents whose episode has
ended leave ``agents`` and take no further actions; the server checks that too. Agents the
server drives itself (``rlenv serve --policy``, the hello's ``driven``) are in neither
``possible_agents`` nor ``agents``, and take no actions from here
(:mod:`rlenv_client.trainer_view`).

Agents that come and go (an environment with ``possible_agents``, protocol 2.6):
``possible_agents`` lists every agent that may appear, ``agents`` those in play: an agent that
joins is in it from the answer it first shows up in (its first reward is 0.0), one that leaves
is removed after the step that returns its final transition. Each step returns entries for
every agent in play, as PettingZoo's parallel API wants: an agent not due to decide keeps its
last observation, with reward 0 and both flags false, and ``infos[agent]["due"]`` says
whether it decides now (every agent's info has it). An action for an agent not due is
ignored: it is never sent.

A group of agents (an :class:`~rlenv.agent_group.RLAgentGroup`, protocol 2.7) is one array on
the wire and named agents here: member ``i`` of group ``G`` is ``f"{G}_{i}"`` (PettingZoo's
``pursuer_0`` convention), every member in ``possible_agents`` (in the group's place), with one
member's spaces; ``agents`` holds the members in play, as above: a member joins from the answer
it first shows up in (reward 0.0) and leaves after the step that returns its final transition,
never to come back in the episode. The members' actions travel as the group's one array (zeros
in the rows of members not in play). :mod:`rlenv_client._members_in_play` does it.

Needs the optional extra: ``pip install pettingzoo``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from rlenv_client._agents_in_play import Turn
from rlenv_client._members_in_play import MembersInPlay, in_play
from rlenv_client.session import Session
from rlenv_client.trainer_view import TrainerView

__all__ = ["RemoteParallelEnv"]


class RemoteParallelEnv(ParallelEnv):
    """Any multi-agent rlenv environment as a PettingZoo parallel environment.

    Args:
        target: the environment class as ``MODULE:CLASS`` (a server is started for it).
        address: ``HOST:PORT`` of a running server instead.
        repeat_action: physics ticks per step; the server's default if ``None``.
        max_cycles: truncate every agent after this many steps (``None``: never).
        in_process: run the environment in this process.
        render_mode: ``"rgb_array"`` or ``None``.
        timeout: seconds to wait for each answer.
        server_args: extra arguments for ``rlenv serve``.
        token: the secret of a server that requires one (default ``$RLENV_TOKEN``).
    """

    metadata = {"name": "rlenv_parallel", "render_modes": ["rgb_array"]}

    def __init__(
        self,
        target: str | None = None,
        *,
        address: str | None = None,
        repeat_action: int | None = None,
        max_cycles: int | None = None,
        in_process: bool = False,
        render_mode: str | None = None,
        timeout: float = 30.0,
        server_args: Sequence[str] = (),
        token: str | None = None,
    ) -> None:
        self.session = Session(
            target,
            address=address,
            in_process=in_process,
            timeout=timeout,
            server_args=server_args,
            token=token,
        )
        try:
            self._view = TrainerView(self.session.client.hello)
        except ValueError:
            self.session.close()
            raise
        self._in_play = in_play(self._view, self.session.client.hello)
        self.possible_agents = list(
            self._view.agents if self._in_play is None else self._in_play.names
        )
        self.agents: list[str] = []
        self.action_spaces, self.observation_spaces = (
            self._view if self._in_play is None else self._in_play
        ).agent_spaces()
        self.repeat_action = repeat_action
        self.max_cycles = max_cycles
        self.render_mode = render_mode
        self._cycles = 0

    def observation_space(self, agent: str) -> spaces.Space:
        """The observation space of ``agent``."""
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        """The action space of ``agent``."""
        return self.action_spaces[agent]

    def configure(self, **settings: Any) -> None:
        """Configure the environment, as ``RemoteEnv.configure`` does; replayed after a restart.

        ``agent`` sets every agent, or one agent by its name (or a class by its name):
        ``configure(agent={"Runner1": {"max_force": 6.0}})``.
        """
        self.session.configure(**settings)

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
        """Start an episode with every agent (with the starting ones, when agents come and go)."""
        observation, info = self.session.client.reset(seed=seed, options=options)
        self._cycles = 0
        if self._in_play is not None:
            turn = self._in_play.start(observation, info)
            self.agents = list(turn.agents)
            return dict(turn.observations), {agent: {"due": True} for agent in self.agents}
        self.agents = list(self.possible_agents)
        return self._split(observation), {agent: {} for agent in self.agents}

    def step(self, actions: dict[str, Any]) -> tuple[dict[str, Any], ...]:
        """Act for every agent still in the episode; returns PettingZoo's five dicts.

        An agent that another client claimed in this step (a person played it, see
        :meth:`~rlenv_client.inspection.Inspection.claim`) has ``"claimed": True`` in its info:
        its action was not the one given here, so a learner leaves its transition out.

        Raises:
            ValueError: an action for an agent the server drives (see
                :mod:`rlenv_client.trainer_view`).
        """
        if self._in_play is not None:
            return self._step_in_play(actions)
        live = list(self.agents)
        self._view.refuse_driven(actions)
        joint = {agent: actions[agent] for agent in live} if self._view.joint else actions[live[0]]
        observation, reward, terminated, truncated, info = self.session.client.step(
            joint, self.repeat_action
        )
        self._cycles += 1
        outcomes = info.get("agents") or {
            live[0]: {"reward": reward, "terminated": terminated, "truncated": truncated}
        }
        cut = self.max_cycles is not None and self._cycles >= self.max_cycles
        observations = {
            agent: value for agent, value in self._split(observation).items() if agent in live
        }
        rewards = {agent: float(outcomes[agent]["reward"]) for agent in live}
        terminations = {agent: bool(outcomes[agent]["terminated"]) for agent in live}
        truncations = {agent: bool(outcomes[agent]["truncated"]) or cut for agent in live}
        infos: dict[str, dict[str, Any]] = {agent: {"frames": info["frames"]} for agent in live}
        _mark_claimed(infos, info)
        self.agents = [agent for agent in live if not (terminations[agent] or truncations[agent])]
        return observations, rewards, terminations, truncations, infos

    def _step_in_play(self, actions: dict[str, Any]) -> tuple[dict[str, Any], ...]:
        assert self._in_play is not None
        self._view.refuse_driven(actions)
        observation, _, terminated, truncated, info = self.session.client.step(
            self._in_play.action(actions), self.repeat_action
        )
        self._cycles += 1
        cut = self.max_cycles is not None and self._cycles >= self.max_cycles
        turn: Turn = self._in_play.answer(observation, info, ended=terminated or truncated or cut)
        infos = {
            agent: {"frames": info["frames"], "due": agent in turn.due} for agent in turn.agents
        }
        members = self._in_play.members if isinstance(self._in_play, MembersInPlay) else {}
        _mark_claimed(infos, info, members)
        self.agents = list(self._in_play.agents)
        return (
            dict(turn.observations),
            dict(turn.rewards),
            dict(turn.terminated),
            dict(turn.truncated),
            infos,
        )

    def render(self) -> np.ndarray | None:
        """The current frame (``rgb_array``), or ``None``."""
        return self.session.client.render() if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        """Disconnect, and stop the server this environment started."""
        self.session.close()

    def _split(self, observation: Any) -> dict[str, Any]:
        if self._view.joint:
            return dict(self._view.observation(observation))
        return {self.possible_agents[0]: observation}


def _mark_claimed(
    infos: dict[str, dict[str, Any]],
    info: dict[str, Any],
    members: Mapping[str, Sequence[str]] | None = None,
) -> None:
    """``"claimed": True`` in the infos of the agents a person played (protocol 2.6 claims).

    A claimed group (``members``: each group's members) played every one of its members.
    """
    for agent in info.get("claimed", ()):
        for name in (members or {}).get(agent, (agent,)):
            if name in infos:
                infos[name]["claimed"] = True
