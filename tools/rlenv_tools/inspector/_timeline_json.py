"""The JSON of a timeline's states, as the inspector's page gets it.

A step's state (:class:`~rlenv_tools.timeline.Step`), a page of the physics ticks inside a
step's action (:class:`~rlenv_tools.timeline.Tick`), one side of two branches compared, each
observation by agent as the live page shows it.
:class:`~rlenv_tools.inspector._timelines.Timelines` answers the page with them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from rlenv_tools.inspector._recordings import Branch
from rlenv_tools.inspector._watch import _shown, to_json
from rlenv_tools.timeline import Step, Tick, Timeline

__all__ = ["agents_json", "shown", "side_json", "state_json", "ticks_json"]


def shown(observation: Any, agents: Sequence[str]) -> dict[str, Any]:
    """An observation as the live page shows it, by agent."""
    if len(agents) > 1 and isinstance(observation, Mapping):  # the answer's agents
        return {name: _shown(observation[name]) for name in agents if name in observation}
    return {agents[0] if agents else "agent": _shown(observation)}


def state_json(state: Step, agents: Sequence[str]) -> dict[str, Any]:
    """The state after a step.

    Its ``reward``, ``terminated``, ``truncated``, ``info``, ``observation`` (by agent),
    ``draw`` (the scene's draw list) and ``properties`` (every node's exported values, by path).
    """
    return {
        "reward": to_json(state.reward),
        "terminated": state.terminated,
        "truncated": state.truncated,
        "info": to_json(state.info),
        "observation": shown(state.observation, agents),
        "draw": to_json(state.draw),
        "properties": to_json(state.properties),
    }


def agents_json(timeline: Timeline, step: int) -> dict[str, Any]:
    """Who is in play at ``step`` and what each agent earned so far.

    ``agents_in_play`` (:meth:`~rlenv_tools.timeline.Timeline.agents_in_play`), ``arrived``
    and ``left`` (those that joined, and left, at this step), ``agent_returns`` (each
    agent's return up to this step: a group's is its members' sum) and ``groups`` (each group
    of agents' members at this step: :func:`_members_json`).
    """
    in_play = timeline.agents.in_play()
    before = set(in_play[step - 1]) if step else set()
    return {
        "agents_in_play": in_play[step],
        "arrived": [name for name in in_play[step] if name not in before],
        "left": [name for name, at in timeline.agents.departures().items() if at == step],
        "agent_returns": to_json(timeline.agents.returns(step)),
        "groups": {name: _members_json(timeline, name, step) for name in timeline.hello.groups},
    }


def _members_json(timeline: Timeline, group: str, step: int) -> dict[str, Any]:
    """A group's members at ``step``: how many in play, who arrived and left, their returns.

    ``in_play`` (a count), ``arrived`` and ``left`` (member indices, at this step) and
    ``returns`` (each member's return over the whole timeline).
    """
    members = timeline.agents.members(group)
    return {
        "in_play": int(members.in_play[step].sum()),
        "arrived": [int(i) for i in np.flatnonzero(members.arrivals == step)] if step else [],
        "left": [int(i) for i in np.flatnonzero(members.departures == step)],
        "returns": members.returns.tolist(),
    }


def ticks_json(
    ticks: list[Tick], frames: int, first: int, count: int, agents: Sequence[str]
) -> dict[str, Any]:
    """A page of ``count`` ticks from ``first`` of an action of ``frames`` ticks.

    ``frames``, ``first``, ``next`` (the first tick of the next page, ``None`` after the
    last: the action's end or its episode's) and the ``ticks``.
    """
    more = (
        len(ticks) == count
        and first + count <= frames
        and not (ticks[-1].terminated or ticks[-1].truncated)
    )
    return {
        "frames": frames,
        "first": first,
        "next": first + count if more else None,
        "ticks": [
            {
                "tick": tick.tick,
                "reward": to_json(tick.reward),
                "terminated": tick.terminated,
                "truncated": tick.truncated,
                "info": to_json(tick.info),
                "observation": shown(tick.observation, agents),
                "properties": to_json(tick.properties),
                "draw": to_json(tick.draw),
            }
            for tick in ticks
        ],
    }


def side_json(branch: Branch, state: Step | None, agents: Sequence[str]) -> dict[str, Any]:
    """One branch of a comparison: its rewards and return, its state at the step compared.

    ``state`` is ``None`` where the branch does not reach that step.
    """
    rewards = branch.timeline.rewards
    return {
        "branch": branch.number,
        "label": branch.describe()["label"],
        "length": len(branch.timeline),
        "rewards": to_json(rewards),
        "return": to_json(sum(rewards)),
        "agent_returns": to_json(branch.timeline.agents.returns()),
        "observation": None if state is None else shown(state.observation, agents),
        "reward": None if state is None else to_json(state.reward),
    }
