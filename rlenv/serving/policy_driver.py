"""Agents driven by policy files or their heuristic (``rlenv serve --policy AGENT=FILE``).

**What drives.** ``AGENT=FILE.onnx`` runs a policy file (:mod:`rlenv.serving.onnx_policy`);
``AGENT=heuristic`` (:data:`HEURISTIC`) runs the agent's own :meth:`RLAgent.heuristic
<rlenv.agent.RLAgent.heuristic>`, refused at start when its class defines none.

**Who acts.** A driven agent's action is its policy's, computed inside each step from the
agent's own observation (``get_data({})``) just before the action applies
(:meth:`DrivenAgents.complete`, called by :meth:`Instance.act
<rlenv.serving._instance.Instance.act>`). Two cases follow:

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

**A policy that fails is a failed episode**, never a dead server. Its action is checked against
its agent's space (:func:`~rlenv.serving.onnx_policy.fit_action`: clipped into a ``Box``, NaN
refused; a heuristic's, user code, must be an action of the space as it is), and a file's call
runs under a deadline and a memory bound (:mod:`rlenv.serving.onnx_policy`). When a policy
raises, runs past its deadline or gives what no action is, the episode ends where it stands
(``error`` in the statistics; a learner's step is answered ``environment_error``, reset
required), the environment is left as it was (nothing was applied), and the failure is logged
once per agent. Driven alone, the server waits :data:`FAILURE_PAUSE` seconds before the next
episode, answering observers and signals meanwhile, so a policy that always fails costs one
episode a second, not a loop.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Collection, Mapping, Sequence
from pathlib import Path
from typing import Any, Final, Literal

from rlenv.agent import RLAgent
from rlenv.protocol import ErrorReply, Reply, Request, Response
from rlenv.protocol.errors import ErrorCode
from rlenv.protocol.spaces import SpaceMismatch, compile_check
from rlenv.serving.onnx_policy import OnnxPolicy, PolicyError, fit_action

__all__ = ["FAILURE_PAUSE", "HEURISTIC", "DrivenAgents", "Policy", "PolicyDriver", "load_policies"]

logger = logging.getLogger(__name__)

FAILURE_PAUSE = 1.0
"""Seconds a driven server waits after a failed episode before it starts the next."""

_LOGGED = 64  # distinct failures a driver logs (each once); past that, none

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
    return {
        agent: HEURISTIC if path == HEURISTIC else OnnxPolicy(path)
        for agent, path in policies.items()
    }


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
                what = policy if policy == HEURISTIC else policy.path
                raise ValueError(
                    f"--policy {name}={what}: the environment has no agent "
                    f"{name!r}; its agents: {', '.join(names)}"
                )
            if policy == HEURISTIC:
                if not agent.has_heuristic():
                    cls = type(agent).__name__
                    raise ValueError(
                        f"--policy {name}=heuristic: agent {name!r} (class {cls}) "
                        f"has no heuristic; define {cls}.heuristic(observation)"
                    )
            else:
                policy.check_spaces(name, agent.observation_space, agent.action_space)
        self.policies = dict(policies)
        self.names = frozenset(policies)
        self.every_agent = self.names == set(names)
        self._checks = {
            name: compile_check(by_name[name].action_space, "action")
            for name, policy in policies.items()
            if policy == HEURISTIC
        }
        self._failed: set[str] = set()  # agents whose policy failure was logged

    def actions(
        self, agents: Sequence[RLAgent], only: Collection[str] | None = None
    ) -> dict[str, Any]:
        """The driven agents' actions (those still in the episode, of ``only`` if given).

        A policy file's is checked against its agent's action space (clipped into a ``Box``);
        a heuristic's must be an action of the space as it is.

        Raises:
            PolicyError: a policy or heuristic (or the observation it needs) failed, or gave
                no action of its space; the first failure of each agent is logged.
        """
        names = self.names if only is None else self.names & set(only)
        return {
            agent.name: self._action(agent, self.policies[agent.name])
            for agent in agents
            if agent.name in names and not (agent.terminated or agent.truncated)
        }

    def _action(self, agent: RLAgent, policy: Policy) -> Any:
        who = f"agent {agent.name!r}"
        try:
            if policy == HEURISTIC:
                return self._heuristic(agent)
            action = policy.act(agent.get_data({}))
        except PolicyError as error:
            failure = PolicyError(error if policy == HEURISTIC else f"{who}: {error}")
        except Exception as error:  # the policy's code, or the environment's observation
            failure = PolicyError(
                f"{who}: its {'heuristic' if policy == HEURISTIC else 'policy'} "
                f"failed: {type(error).__name__}: {error}"
            )
        else:
            try:
                return fit_action(agent.action_space, action, f"{who}: its policy")
            except PolicyError as error:
                failure = error
        if agent.name not in self._failed:
            self._failed.add(agent.name)
            logger.warning("%s; its episodes fail (logged once per agent)", failure)
        raise failure

    def _heuristic(self, agent: RLAgent) -> Any:
        action = agent.heuristic(agent.get_data({}))
        try:
            return self._checks[agent.name](action)
        except SpaceMismatch as error:
            raise PolicyError(
                f"{type(agent).__name__}.heuristic of agent {agent.name!r} gave "
                f"{action!r:.80}, not an action of {agent.action_space}: "
                f"{error}"
            ) from None

    def complete(self, action: Any, agents: Sequence[RLAgent]) -> Any:
        """A joint action (several agents) with the driven agents' actions put in."""
        return {**action, **self.actions(agents)}


class PolicyDriver:
    """Episodes one after another on an instance whose every agent a policy drives.

    Args:
        answer: the host's door (:meth:`Host.answer <rlenv.serving._host.Host.answer>`).
        instance: the instance it plays (the host's only one).
        driven: its driven agents (every agent).
        max_episode_steps: steps after which an episode is cut short (``None``: never).
        clock: the clock of :data:`FAILURE_PAUSE`.
    """

    def __init__(
        self,
        answer: Callable[[Request], Reply],
        instance: Any,
        driven: DrivenAgents,
        max_episode_steps: int | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._answer, self._instance, self._driven = answer, instance, driven
        self.max_episode_steps = max_episode_steps
        self.episodes = 0  # started so far: the seed of the next one
        self._steps = 0
        self._running = False
        self._clock = clock
        self._resume_at = 0.0  # after a failure: when the next episode may start
        self._logged: set[str] = set()

    def wait(self) -> float:
        """Seconds until :meth:`step` has something to do (0 but after a failed episode)."""
        return 0.0 if self._running else max(0.0, self._resume_at - self._clock())

    def step(self) -> None:
        """One request's worth of play: a reset when no episode runs, else one step."""
        if not self._running:
            if self.wait() > 0.0:
                return
            seed = self.episodes
            self.episodes += 1
            self._steps = 0
            self._running = self._served(self._answer(Request(0, {"reset": {"seed": seed}})))
            return
        instance = self._instance
        try:
            action = (
                {}
                if instance.multi_agent
                else self._driven.actions(instance.agents)[instance.agents[0].name]
            )
        except PolicyError as error:  # logged by DrivenAgents; nothing was applied
            instance.abandon_episode(f"the episode failed: {error}")
            self._fail()
            return
        reply = self._answer(Request(0, {"action": action}))
        if not self._served(reply):
            return
        self._steps += 1
        if reply.terminated or reply.truncated:  # type: ignore[union-attr]
            self._running = False
        elif self.max_episode_steps is not None and self._steps >= self.max_episode_steps:
            instance.stats.end("truncated")  # as a time limit: the next reset starts afresh
            self._running = False

    def _served(self, reply: Reply) -> bool:
        """Whether ``reply`` served; a failed episode if not.

        An ``environment_error`` was logged where it was raised (a policy's once); any other
        refusal is logged once per message.
        """
        if reply.__class__ is Response:
            return True
        assert isinstance(reply, ErrorReply)
        message = reply.message
        if (
            reply.code != ErrorCode.ENVIRONMENT_ERROR
            and message not in self._logged
            and len(self._logged) < _LOGGED
        ):
            self._logged.add(message)
            logger.warning("a policy-driven request failed (logged once): %s", message)
        self._fail()
        return False

    def _fail(self) -> None:
        self._running = False
        self._resume_at = self._clock() + FAILURE_PAUSE
