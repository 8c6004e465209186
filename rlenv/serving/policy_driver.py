"""Agents driven by policy files or their heuristic (``rlenv serve --policy AGENT=FILE``).

**What drives.** ``AGENT=FILE.onnx`` runs a policy file (:mod:`rlenv.serving.onnx_policy`);
``AGENT=heuristic`` (:data:`HEURISTIC`) runs the agent's own :meth:`RLAgent.heuristic
<rlenv.agent.RLAgent.heuristic>`, refused at start when its class defines none.

**Who acts.** A driven agent's action is its policy's, computed inside each step from the
agent's own observation (``get_data({})``) just before the action applies
(:meth:`DrivenAgents.complete`, called by :meth:`Instance.act
<rlenv.serving.instance.Instance.act>`). Two cases follow:

- **Every agent driven**: no client controls the environment. :class:`PolicyDriver` plays
  episodes one after the other inside the server's loop, between requests: episode ``n``
  (from 0) starts with a reset seeded ``n``, and ends when the environment ends it, or after
  ``max_episode_steps`` steps (counted as truncated in the statistics). Observers watch it
  (``stats()``, the inspector); a request that would change the environment is answered
  ``busy``.
- **Some agents driven**: a learner controls the environment as usual and sends the other
  agents' actions (a map from agent name to action); actions it sends for driven agents are
  ignored, as those for agents whose episode ended are. The policy opponents act within the
  learner's steps, so they see the same ticks.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection, Mapping, Sequence
from pathlib import Path
from typing import Any, Final, Literal

from rlenv.agent import RLAgent
from rlenv.protocol import ErrorReply, Reply, Request, Response
from rlenv.protocol.spaces import SpaceMismatch, compile_check
from rlenv.serving.onnx_policy import OnnxPolicy

__all__ = ["HEURISTIC", "DrivenAgents", "Policy", "PolicyDriver", "load_policies"]

logger = logging.getLogger(__name__)

HEURISTIC: Final = "heuristic"
"""What ``--policy AGENT=heuristic`` names instead of a file: the agent's own heuristic."""

Policy = OnnxPolicy | Literal["heuristic"]
"""What drives an agent: a loaded policy file, or :data:`HEURISTIC`."""


def load_policies(policies: Mapping[str, str | Path]) -> dict[str, Policy]:
    """Policy files loaded, by agent name; ``"heuristic"`` stays :data:`HEURISTIC`.

    Raises:
        ImportError: a file, and no onnxruntime.
        ValueError: a file that cannot be read or is not an rlenv policy (one line).
    """
    return {agent: HEURISTIC if path == HEURISTIC else OnnxPolicy(path)
            for agent, path in policies.items()}


class DrivenAgents:
    """The agents a policy file or their heuristic drives, checked against an instance's agents.

    Args:
        policies: what drives each driven agent, by agent name.
        agents: the instance's agents.

    Raises:
        ValueError: one line: an agent the environment does not have, a file whose spaces
            are not its agent's (naming both), or ``heuristic`` for an agent whose class
            defines none (naming the agent and its class).
    """

    def __init__(self, policies: Mapping[str, Policy], agents: Sequence[RLAgent]) -> None:
        names = [agent.name for agent in agents]
        by_name = dict(zip(names, agents, strict=True))
        for name, policy in policies.items():
            agent = by_name.get(name)
            if agent is None:
                what = policy if policy == HEURISTIC else policy.path  # type: ignore[union-attr]
                raise ValueError(f"--policy {name}={what}: the environment has no agent "
                                 f"{name!r}; its agents: {', '.join(names)}")
            if policy == HEURISTIC:
                if not agent.has_heuristic():
                    cls = type(agent).__name__
                    raise ValueError(f"--policy {name}=heuristic: agent {name!r} (class {cls}) "
                                     f"has no heuristic; define {cls}.heuristic(observation)")
            else:
                policy.check_spaces(  # type: ignore[union-attr]
                    name, agent.observation_space, agent.action_space)
        self.policies = dict(policies)
        self.names = frozenset(policies)
        self.every_agent = self.names == set(names)
        self._checks = {name: compile_check(by_name[name].action_space, "action")
                        for name, policy in policies.items() if policy == HEURISTIC}

    def actions(self, agents: Sequence[RLAgent],
                only: Collection[str] | None = None) -> dict[str, Any]:
        """The driven agents' actions (those still in the episode, of ``only`` if given).

        Raises:
            ValueError: a heuristic gave something that is not an action of its agent's space.
        """
        names = self.names if only is None else self.names & set(only)
        return {agent.name: self._act(agent) for agent in agents
                if agent.name in names and not (agent.terminated or agent.truncated)}

    def complete(self, action: Any, agents: Sequence[RLAgent]) -> Any:
        """A joint action (several agents) with the driven agents' actions put in."""
        return {**action, **self.actions(agents)}

    def _act(self, agent: RLAgent) -> Any:
        policy = self.policies[agent.name]
        observation = agent.get_data({})
        if policy != HEURISTIC:
            return policy.act(observation)  # type: ignore[union-attr]
        action = agent.heuristic(observation)
        try:
            return self._checks[agent.name](action)
        except SpaceMismatch as error:
            raise ValueError(f"{type(agent).__name__}.heuristic of agent {agent.name!r} gave "
                             f"{action!r:.80}, not an action of {agent.action_space}: "
                             f"{error}") from None


class PolicyDriver:
    """Episodes one after another on an instance whose every agent a policy drives.

    Args:
        answer: the host's door (:meth:`Host.answer <rlenv.serving.host.Host.answer>`).
        instance: the instance it plays (the host's only one).
        driven: its driven agents (every agent).
        max_episode_steps: steps after which an episode is cut short (``None``: never).
    """

    def __init__(self, answer: Callable[[Request], Reply], instance: Any,
                 driven: DrivenAgents, max_episode_steps: int | None = None) -> None:
        self._answer, self._instance, self._driven = answer, instance, driven
        self.max_episode_steps = max_episode_steps
        self.episodes = 0  # started so far: the seed of the next one
        self._steps = 0
        self._running = False

    def step(self) -> None:
        """One request's worth of play: a reset when no episode runs, else one step."""
        if not self._running:
            seed = self.episodes
            self.episodes += 1
            self._steps = 0
            self._running = self._served(self._answer(Request(0, {"reset": {"seed": seed}})))
            return
        instance = self._instance
        action = {} if instance.multi_agent else \
            self._driven.actions(instance.agents)[instance.agents[0].name]
        reply = self._answer(Request(0, {"action": action}))
        if not self._served(reply):
            self._running = False
            return
        self._steps += 1
        if reply.terminated or reply.truncated:  # type: ignore[union-attr]
            self._running = False
        elif self.max_episode_steps is not None and self._steps >= self.max_episode_steps:
            instance.stats.end("truncated")  # as a time limit: the next reset starts afresh
            self._running = False

    @staticmethod
    def _served(reply: Reply) -> bool:
        if reply.__class__ is Response:
            return True
        assert isinstance(reply, ErrorReply)
        logger.warning("a policy-driven request failed: %s", reply.message)
        return False
