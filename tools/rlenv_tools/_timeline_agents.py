"""Who is in play at each step of a timeline, who left when, and what each agent earned.

Where agents come and go, or decide at their own pace, an answer holds only the agents due and
those that just left; a timeline's step records (:data:`~rlenv_tools.forking.StepRecord`)
carry each answer's ``info["agents"]``, from which these are read (no re-simulation).
:class:`~rlenv_tools.timeline.Timeline` answers with them.

A group of agents (``rlenv.RLAgentGroup``) counts as one agent here: in play while a member
is, its return the sum of its members'. :class:`MemberHistory` says the rest, member by member,
as arrays over the steps (one array operation per step, never one per member): who was in
play, when each arrived and left, what each earned.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rlenv.protocol import Hello
from rlenv_tools.forking import StepRecord

__all__ = [
    "AgentHistory",
    "MemberHistory",
    "agent_returns",
    "agents_in_play",
    "answer_agents",
    "departures",
]


class AgentHistory:
    """A timeline's agents, step by step: who was in play, who left when, what each earned.

    Args:
        starting: the agents the reset started.
        records: the timeline's step records, in order.
        hello: its server's hello.
        members: where the groups' member histories are kept between calls, by group, with
            the number of records each was read from (a timeline's own map).
    """

    def __init__(
        self,
        starting: Sequence[str],
        records: Sequence[StepRecord],
        hello: Hello,
        members: dict[str, tuple[int, MemberHistory]] | None = None,
    ):
        self._starting, self._records, self._hello = starting, records, hello
        self._members = {} if members is None else members

    def in_play(self) -> list[list[str]]:
        """Each step's agents in play, by step (step 0: those the reset started).

        An agent is in play from the answer it joined in to the answer it left in, both
        included, whether or not it was due at each step between (one that decides at its own
        pace is absent from some answers). With a fixed set of agents, every step has them all.
        """
        return agents_in_play(self._starting, self._records)

    def departures(self) -> dict[str, int]:
        """The step at which each agent that left did so (terminated or truncated)."""
        return departures(self._records)

    def returns(self, upto: int | None = None) -> dict[str, float]:
        """Each agent's return: the sum of its rewards up to step ``upto`` (default: the end).

        Every agent that was in play by then is listed, in the order they joined; an agent's
        first answer (``reward`` ``None``) counts nothing. With one agent, its name holds the
        episode's return. A group's is the sum of its members' returns.
        """
        return agent_returns(self._starting, self._records[:upto], self._hello)

    def members(self, group: str) -> MemberHistory:
        """Group ``group``'s members, step by step (see :class:`MemberHistory`).

        Raises:
            KeyError: the environment has no group of that name (the hello's ``groups``).
        """
        if group not in self._hello.groups:
            raise KeyError(
                f"{self._hello.environment} has no group {group!r}; its groups: "
                f"{', '.join(self._hello.groups) or 'none'}"
            )
        kept = self._members.get(group)
        if kept is None or kept[0] != len(self._records):
            count = self._hello.groups[group].instance_count
            kept = self._members[group] = (
                len(self._records),
                member_history(group, count, self._records),
            )
        return kept[1]


@dataclass(frozen=True)
class MemberHistory:
    """A group's members over a timeline's steps, as arrays (member ``i`` is column ``i``).

    Attributes:
        in_play: ``(steps + 1, N)`` bool: whether each member was in play at each step, from
            the answer it joined in (step 0: the reset's) to the answer it left in, both
            included, whether or not the group was due at each step between.
        arrivals: ``(N,)`` int: the step each member first played at (0: it started), ``-1``
            for one that never did.
        departures: ``(N,)`` int: the step each member left at, ``-1`` for one that did not.
        returns: ``(N,)`` float64: each member's return (its first answer counts nothing).
    """

    in_play: np.ndarray
    arrivals: np.ndarray
    departures: np.ndarray
    returns: np.ndarray


def member_history(group: str, count: int, records: Sequence[StepRecord]) -> MemberHistory:
    """Group ``group``'s members (``count`` of them) over ``records`` (see :class:`MemberHistory`).

    A member whose first reported row is not ``joined`` started at the reset (step 0); one whose
    is joined at that step. It is in play until the row it ended in, included.
    """
    steps = len(records)
    reported = np.zeros((steps + 1, count), np.bool_)
    joined = np.zeros((steps + 1, count), np.bool_)
    ended = np.zeros((steps + 1, count), np.bool_)
    returns = np.zeros(count, np.float64)
    for step, record in enumerate(records, start=1):
        outcome = (record[4] or {}).get(group)
        if outcome is None:
            continue  # the group was not due
        active = np.asarray(outcome["active"], np.bool_)
        reported[step] = active
        joined[step] = np.asarray(outcome["joined"], np.bool_)
        ended[step] = active & (
            np.asarray(outcome["terminated"], np.bool_) | np.asarray(outcome["truncated"], np.bool_)
        )
        returns += np.where(active, np.asarray(outcome["reward"], np.float64), 0.0)
    first_row = np.where(reported.any(axis=0), reported.argmax(axis=0), -1)
    started = (first_row >= 0) & ~joined[np.maximum(first_row, 0), np.arange(count)]
    arrivals = np.where(started, 0, np.where(joined.any(axis=0), joined.argmax(axis=0), -1))
    departures = np.where(ended.any(axis=0), ended.argmax(axis=0), -1)
    rows = np.arange(steps + 1)[:, None]
    in_play = (arrivals >= 0) & (rows >= arrivals) & ((departures < 0) | (rows <= departures))
    return MemberHistory(in_play, arrivals, departures, returns)


def answer_agents(observation: Any, hello: Hello) -> list[str]:
    """The agents an answer's observation holds (a map by name with several agents)."""
    if len(hello.agents) > 1 and isinstance(observation, Mapping):
        return [str(name) for name in observation]
    return list(hello.agents)


def agents_in_play(starting: Sequence[str], records: Sequence[StepRecord]) -> list[list[str]]:
    """Each step's agents in play (step 0: ``starting``, those the reset started).

    An agent is in play from the answer it joined in to the answer it left in, both included,
    whether or not it was due at each step between.
    """
    in_play = list(starting)
    steps = [list(in_play)]
    left: set[str] = set()  # those that left at the step before
    for record in records:
        agents = record[4] or {}
        in_play = [name for name in in_play if name not in left]
        in_play += [name for name in agents if name not in in_play and _reports(agents[name])]
        steps.append(list(in_play))
        left = {name for name, outcome in agents.items() if _left(outcome)}
    return steps


def departures(records: Sequence[StepRecord]) -> dict[str, int]:
    """The step at which each agent that left did so (terminated or truncated)."""
    return {
        name: step
        for step, record in enumerate(records, start=1)
        for name, outcome in (record[4] or {}).items()
        if _left(outcome)
    }


def agent_returns(
    starting: Sequence[str], records: Sequence[StepRecord], hello: Hello
) -> dict[str, float]:
    """Each agent's return over ``records``, in the order they joined.

    An agent's first answer (``reward`` ``None``) counts nothing. With one agent, its name holds
    the episode's return.
    """
    if len(hello.agents) < 2:
        return {hello.agents[0]: float(sum(record[1] for record in records))}
    returns = dict.fromkeys(starting, 0.0)
    for record in records:
        for name, outcome in (record[4] or {}).items():
            reward = outcome.get("reward")
            if name in hello.groups:  # the rows it reports (the others are zeros)
                reward = float(np.sum(reward, where=np.asarray(outcome["active"], np.bool_)))
            returns[name] = returns.get(name, 0.0) + (0.0 if reward is None else reward)
    return returns


def _reports(outcome: Any) -> bool:
    """Whether an agent's part of an answer reports it: a group's, when it has a row."""
    return not (isinstance(outcome, Mapping) and "active" in outcome) or bool(
        np.any(outcome["active"])
    )


def _left(outcome: Any) -> bool:
    """Whether an agent's part of an answer (``info["agents"][name]``) says it left.

    A group's (arrays, a row per member) says so when every row it reports ended: the group,
    as one agent, ends when no member is left in play.
    """
    if not isinstance(outcome, Mapping):
        return False
    if "active" in outcome:
        active = np.asarray(outcome["active"], np.bool_)
        ended = np.asarray(outcome["terminated"], np.bool_) | np.asarray(
            outcome["truncated"], np.bool_
        )
        return bool(active.any() and ended[active].all())
    return bool(outcome.get("terminated") or outcome.get("truncated"))
