"""Agents driven by policy files (``rlenv serve --policy AGENT=FILE``).

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
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from rlenv.agent import RLAgent
from rlenv.protocol import ErrorReply, Reply, Request, Response
from rlenv.serving.onnx_policy import OnnxPolicy

__all__ = ["DrivenAgents", "PolicyDriver"]

logger = logging.getLogger(__name__)


class DrivenAgents:
    """The agents a policy file drives, checked against an instance's agents.

    Args:
        policies: the policy of each driven agent, by agent name.
        agents: the instance's agents.

    Raises:
        ValueError: one line: an agent the environment does not have, or a file whose spaces
            are not its agent's (naming both).
    """

    def __init__(self, policies: Mapping[str, OnnxPolicy], agents: Sequence[RLAgent]) -> None:
        names = [agent.name for agent in agents]
        by_name = dict(zip(names, agents, strict=True))
        for name, policy in policies.items():
            agent = by_name.get(name)
            if agent is None:
                raise ValueError(f"--policy {name}={policy.path}: the environment has no agent "
                                 f"{name!r}; its agents: {', '.join(names)}")
            policy.check_spaces(name, agent.observation_space, agent.action_space)
        self.policies = dict(policies)
        self.names = frozenset(policies)
        self.every_agent = self.names == set(names)

    def actions(self, agents: Sequence[RLAgent]) -> dict[str, Any]:
        """The driven agents' actions (those still in the episode), from their observations."""
        policies = self.policies
        return {agent.name: policies[agent.name].act(agent.get_data({})) for agent in agents
                if agent.name in policies and not (agent.terminated or agent.truncated)}

    def complete(self, action: Any, agents: Sequence[RLAgent]) -> Any:
        """A joint action (several agents) with the driven agents' actions put in."""
        return {**action, **self.actions(agents)}


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
