"""Actions: a client's action checked against one instance's action space, or refused.

With one agent, the action is a member of its space. With several, it is a map from agent
name to action for every agent still in the episode (every agent when the request starts an
episode first); actions for agents whose episode ended are ignored, so that a client holding
the joint ``Dict`` action space may keep sending them (PettingZoo's convention). Actions for
agents a policy drives (``rlenv serve --policy``) are ignored too: their policy gives them
(:mod:`rlenv.serving.policy_driver`), except in a replayed action, where the logged ones
replay. An action leaves out the agents a request's ``heuristic`` part names (their heuristic
acts), and may not act for them.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence
from typing import Any

from gymnasium import spaces

from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.protocol.messages import MAX_REPEAT_ACTION
from rlenv.protocol.spaces import SpaceMismatch, compile_check
from rlenv.serving._agents_in_play import AgentsInPlay
from rlenv.serving._roster import Roster

__all__ = ["MAX_REPEAT_ACTION", "ActionCheck", "check_repeat_action"]


def check_repeat_action(repeat: Any, name: str, code: ErrorCode = ErrorCode.BAD_REQUEST) -> int:
    """``repeat`` if it is a number of ticks an action may run: an int in 1..MAX_REPEAT_ACTION.

    Raises:
        RequestError: ``code``, naming the field ``name``.
    """
    if type(repeat) is not int or repeat < 1:
        raise RequestError(code, f"{name} must be an integer >= 1, got {repeat!r:.40}")
    if repeat > MAX_REPEAT_ACTION:
        raise RequestError(
            code,
            f"{name} must be at most {MAX_REPEAT_ACTION} ticks (the "
            f"hello's limits.max_repeat_action), got {repeat}",
        )
    return repeat


class ActionCheck:
    """Checks actions for one instance's agents, with checkers compiled once.

    Args:
        agents: the instance's agents.
        space: their joint action space (the agent's own with one agent).
        several: whether actions are keyed by agent name (the roster's ``several``).
        driven: the agents a policy drives (with several agents): no action is needed for them.
    """

    def __init__(
        self,
        agents: Sequence[Any],
        space: spaces.Space,
        several: bool,
        driven: frozenset[str] = frozenset(),
        due: Callable[[], Collection[str]] | None = None,
    ) -> None:
        self._every = list(agents)
        self._agents = [agent for agent in agents if agent.name not in driven]
        self._driven = driven
        self._due = due
        self._several = several
        self._one = compile_check(space, "action")
        self._each = {a.name: compile_check(a.action_space, f"action[{a.name!r}]") for a in agents}

    @classmethod
    def of(cls, roster: Roster, space: spaces.Space, driven: frozenset[str]) -> ActionCheck:
        """The check of a roster's agents.

        While agents come and go (:class:`AgentsInPlay`), of every possible agent: an action
        is needed from those due.
        """
        in_play = roster if isinstance(roster, AgentsInPlay) else None
        due = None if in_play is None else (lambda: in_play.asked)
        return cls(roster.actors(), space, roster.several, driven, due)

    def __call__(
        self,
        action: Any,
        fresh: bool,
        where: str = "",
        replayed: bool = False,
        heuristic: frozenset[str] = frozenset(),
    ) -> Any:
        """``action`` in its space's native form.

        ``fresh``: the request starts an episode first (every agent takes an action). A
        ``replayed`` action (from a snapshot's log) holds the agents that were still in the
        episode: any of them, driven ones included (their logged actions replay). The agents
        named in ``heuristic`` act by their heuristic in this action: they need no entry, and
        may not have one.

        Raises:
            RequestError: ``invalid_action``, the message prefixed with ``where``.
        """
        try:
            if not self._several:
                return self._one(action)
            agents = self._agents
            if not isinstance(action, Mapping):
                raise SpaceMismatch(
                    f"action must be a map from agent name to action, one per "
                    f"agent in the episode: {[a.name for a in agents]}"
                )
            unknown = sorted(map(str, action.keys() - self._each.keys()))
            if unknown:
                raise SpaceMismatch(f"action for unknown agent {unknown[0]!r}")
            if replayed:
                return {
                    a.name: self._each[a.name](action[a.name])
                    for a in self._every
                    if a.name in action
                }
            if self._driven:
                action = {k: v for k, v in action.items() if k not in self._driven}
            if heuristic:
                both = sorted(heuristic & action.keys())
                if both:
                    raise SpaceMismatch(
                        f"an action for agent {both[0]!r}, whose heuristic "
                        "acts in this step (the heuristic part): one or the "
                        "other"
                    )
                agents = [a for a in agents if a.name not in heuristic]
            if self._due is not None:
                if fresh:
                    raise RequestError(
                        ErrorCode.BAD_REQUEST,
                        f"{where}an action in the request that resets: agents come and go "
                        "here, and which ones start is known only once the reset ran; send "
                        "the action in the next request",
                    )
                due = self._due()
                live = [a.name for a in agents if a.name in due]
            else:
                live = [a.name for a in agents if fresh or not (a.terminated or a.truncated)]
            missing = sorted(set(live) - action.keys())
            if missing:
                raise SpaceMismatch(f"no action for agent {missing[0]!r}")
            return {name: self._each[name](action[name]) for name in live}
        except SpaceMismatch as error:
            raise RequestError(ErrorCode.INVALID_ACTION, f"{where}{error}") from None

    def of_agent(self, name: str, action: Any, where: str = "") -> Any:
        """``action`` for agent ``name`` alone (one of several), in its space's native form.

        Raises:
            RequestError: ``invalid_action``, the message prefixed with ``where``.
        """
        try:
            return self._each[name](action)
        except SpaceMismatch as error:
            raise RequestError(ErrorCode.INVALID_ACTION, f"{where}{error}") from None
