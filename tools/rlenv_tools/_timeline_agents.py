"""Who is in play at each step of a timeline, who left when, and what each agent earned.

Where agents come and go, or decide at their own pace, an answer holds only the agents due and
those that just left; a timeline's step records (:data:`~rlenv_tools.forking.StepRecord`)
carry each answer's ``info["agents"]``, from which these are read (no re-simulation).
:class:`~rlenv_tools.timeline.Timeline` answers with them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from rlenv.protocol import Hello
from rlenv_tools.forking import StepRecord

__all__ = [
    "AgentHistory",
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
    """

    def __init__(self, starting: Sequence[str], records: Sequence[StepRecord], hello: Hello):
        self._starting, self._records, self._hello = starting, records, hello

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
        episode's return.
        """
        return agent_returns(self._starting, self._records[:upto], self._hello)


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
        in_play += [name for name in agents if name not in in_play]
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
            returns[name] = returns.get(name, 0.0) + (0.0 if reward is None else reward)
    return returns


def _left(outcome: Any) -> bool:
    """Whether an agent's part of an answer (``info["agents"][name]``) says it left."""
    return isinstance(outcome, Mapping) and bool(
        outcome.get("terminated") or outcome.get("truncated")
    )
