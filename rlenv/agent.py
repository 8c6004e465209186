"""RLAgent: what the agent can do and see, and how it is rewarded (the seed's RLAgent)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from gymnasium import spaces

from rlenv.demonstration_keys import idle_action
from rlenv.rl_node import RLNode

__all__ = ["RLAgent"]


class RLAgent(RLNode):
    """Override to define what the agent can do and see, and how it is rewarded.

    Set :attr:`action_space` and :attr:`observation_space` (gymnasium spaces) as class attributes
    or in ``__init__``. Apply the action in ``_physics_process`` (before the physics steps) and
    report the outcome of each tick in ``_after_physics_tick`` (after it stepped) with
    :meth:`add_reward`, :meth:`set_terminated` and :meth:`set_truncated` (bevy_rl's
    ``set_reward`` / ``set_terminated``); signal handlers may report too. The environment sums
    the rewards of the ticks, answers the client, and stops the action early when the episode
    ends.

    The order within one request: the server checks the action against
    :attr:`action_space`, calls :meth:`set_action`, then runs the action's ticks; each tick
    runs every ``_physics_process`` (apply the action here), steps the physics, then calls
    :meth:`_after_physics_tick`. After the last tick (or the tick in which the episode ended),
    :meth:`get_data` gives the observation sent back with the summed reward. A reset sets
    :attr:`reward` to 0 and both flags to false, then calls :meth:`reset`.

    Attributes:
        action_space: the gymnasium space of the actions (sent to clients in the hello).
        observation_space: the gymnasium space of :meth:`get_data`'s observations.
        reward: reward accumulated since the last answer to the client (set back to 0 after
            each answer).
        terminated: the episode reached a terminal state of the task.
        truncated: the episode was cut short by something outside the task (a time limit).
        decision_period: physics ticks between the agent's decisions (ML-Agents'
            ``DecisionRequester.DecisionPeriod``); ``None``, the default, decides at every
            answer, every ``repeat_action`` ticks. An agent not due for a decision is absent
            from that answer and needs no action (docs/several-agents.md, "Decision periods").
        decision_offset: the tick, within each period, at which the agent decides (ML-Agents'
            ``DecisionStep``): it decides at the episode's ticks ``t`` with
            ``(t - decision_offset) % decision_period == 0``; staggers agents of one period.
        act_between_decisions: whether the agent's last action goes on applying on the ticks
            between its decisions (the default, ML-Agents' ``TakeActionsBetweenDecisions``).
            When ``False`` the action applies on the decision's first tick only, and the agent
            gets :meth:`no_action` on the others.
        demonstration_keys: the keys a person acts with from the inspector's page (``rlenv
            inspect --record-demonstrations DIR``): key names as the browser's
            ``KeyboardEvent.key`` gives them (``"ArrowLeft"``, ``"a"``, ``" "``) mapped to
            actions of :attr:`action_space`, e.g. ``{"ArrowLeft": 0, "ArrowRight": 2}``.
            ``None`` (the default) picks keys from the space
            (:func:`~rlenv.demonstration_keys.default_keys`): ``"1"``..``"9"`` for the first
            actions of a ``Discrete`` (and arrows when it has 2 or 3), arrows to the bounds of
            a ``Box`` of one or two values; other spaces have none (name yours). While no key
            is held the agent gets the space's idle action (0, clipped into a ``Box``'s
            bounds; a ``Discrete``'s ``start``); several held keys of a ``Box`` add up, of
            other spaces the last pressed counts.
    """

    action_space: spaces.Space
    observation_space: spaces.Space
    demonstration_keys: ClassVar[Mapping[str, Any] | None] = None
    decision_period: int | None = None
    decision_offset: int = 0
    act_between_decisions: bool = True
    _IS_GROUP: ClassVar[bool] = False  # True on RLAgentGroup (rlenv.agent_group) only

    def __init__(self, name: str | None = None) -> None:
        super().__init__(name)
        self.reward = 0.0
        self.terminated = False
        self.truncated = False

    def set_action(self, action: Any) -> None:
        """Receive the client's action, already checked against :attr:`action_space`.

        Called once per action, before its ticks run: store it, and apply it in
        ``_physics_process`` on every tick (forces are cleared after each physics step).
        """
        raise NotImplementedError(f"{type(self).__name__} must implement set_action")

    def no_action(self) -> Any:
        """The action an agent that does not act between its decisions gets on those ticks.

        By default the idle action of :attr:`action_space` (zero force: 0, clipped into a
        ``Box``'s bounds; a ``Discrete``'s ``start``). Override it when the idle action of
        your space does something.
        """
        return idle_action(self.action_space)

    def reset(self, arguments: Any) -> None:
        """Put the agent in its initial state, at the start of every episode.

        Args:
            arguments: what the environment's ``_reset`` passes: by default the world's
                :meth:`~rlenv.world.RLEnvWorld.sample_initial_position`, drawn after the
                world's own ``reset``.
        """

    def get_data(self, observation_request: Mapping[str, Any]) -> Any:
        """Return the observation, a member of :attr:`observation_space`.

        Called after a reset and after each action's ticks (and whenever a client observes).
        The server refuses an observation that does not fit the space or is not finite (an
        ``environment_error`` naming this agent).

        Args:
            observation_request: the client's request for the agent's observation, ``{}``
                unless a custom client asks for more.
        """
        raise NotImplementedError(f"{type(self).__name__} must implement get_data")

    def heuristic(self, observation: Any) -> Any:
        """Return an action of :attr:`action_space` for ``observation``: a hand-written policy.

        Optional, as ML-Agents' ``Heuristic()`` and Godot RL Agents' ``heuristic``: an agent
        class that does not override it has none (:meth:`has_heuristic`). ``rlenv serve
        --policy NAME=heuristic`` (``rlenv.Server(policies={NAME: "heuristic"})``) lets it act
        for agent ``NAME``, as a policy file would: it is called once per step, just before the
        action applies, on the observation the agent would be sent (``get_data({})``). The
        server checks what it returns against :attr:`action_space` (an
        ``environment_error`` naming the agent otherwise) and records it in the episode's
        log: snapshots and replays play the logged actions back without calling it. So draw
        any randomness from a generator of its own, not from the environment's
        ``np_random`` (the episode's, which a replay would then draw from differently). In
        the inspector, a person playing another agent leaves this one to its heuristic (a
        step's ``heuristic`` part).

        Args:
            observation: the agent's observation, a member of :attr:`observation_space`.
        """
        raise NotImplementedError(f"{type(self).__name__} has no heuristic")

    @classmethod
    def has_heuristic(cls) -> bool:
        """Whether this agent class defines :meth:`heuristic` (overrides RLAgent's)."""
        return cls.heuristic is not RLAgent.heuristic

    def _after_physics_tick(self, delta: float) -> None:
        """Called at the end of every physics tick of an action, after the physics stepped.

        Read the new state here, add rewards and set terminated or truncated: once an agent's
        episode ended, the action stops at the end of this tick (``info["frames"]`` counts the
        ticks that ran).

        Args:
            delta: the tick's length, in seconds.
        """

    def add_reward(self, reward: float) -> None:
        """Add ``reward`` to the reward of the current step."""
        self.reward += reward

    def set_reward(self, reward: float) -> None:
        """Replace the reward of the current step with ``reward``."""
        self.reward = reward

    def set_terminated(self, terminated: bool = True) -> None:
        """Mark the episode as ended by the task (the pole fell, the goal was reached)."""
        self.terminated = terminated

    def set_truncated(self, truncated: bool = True) -> None:
        """Mark the episode as cut short for a reason outside the task (a time limit)."""
        self.truncated = truncated
