"""What a timeline reads of its environment at a step: the state after it, its physics ticks.

:class:`Step` is the state after a step (:meth:`~rlenv_tools.timeline.Timeline.at`), read from
the process standing at it; :class:`Tick` the state after one physics tick inside a step's
action (:meth:`~rlenv_tools.timeline.Timeline.ticks`), each read on a copy of the process at
the step before, which takes the action one tick at a time (:func:`read_ticks`), or, where
agents come and go or decide at their own pace, restored from the recording's log cut at that
tick (:func:`restored_ticks`).
"""

from __future__ import annotations

import copy
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from rlenv.protocol.errors import RemoteError
from rlenv_tools._timeline_processes import Result
from rlenv_tools.forking import ForkedEnvironment

__all__ = ["Step", "Tick", "answer_tick", "read_step", "read_ticks", "restored_ticks", "tick_span"]

_SKIPPED_AT_ONCE = 10_000  # ticks a tick view takes unread in one run


@dataclass(frozen=True)
class Step:
    """The state after a step (:meth:`~rlenv_tools.timeline.Timeline.at`).

    Attributes:
        step: its number (0: after the reset).
        observation: the agent's observation, as the recording saw it.
        reward: the step's reward (0.0 at step 0).
        terminated: whether the episode terminated at this step.
        truncated: whether the episode was truncated at this step.
        info: the step's info (the reset's at step 0).
        draw: the scene as the inspector's vector draw list (``client.draw()``).
        properties: every node's exported properties, by node path (the inspect tree's).
    """

    step: int
    observation: Any
    reward: float
    terminated: bool
    truncated: bool
    info: dict[str, Any]
    draw: dict[str, Any]
    properties: dict[str, dict[str, Any]]


@dataclass(frozen=True)
class Tick:
    """The state after one physics tick inside a step's action.

    As :meth:`~rlenv_tools.timeline.Timeline.ticks` gives them.

    Attributes:
        tick: its number inside the action, from 1.
        observation: the agent's observation after the tick.
        reward: the tick's reward.
        terminated: whether the episode terminated at this tick.
        truncated: whether the episode was truncated at this tick.
        info: the tick's info.
        properties: every node's exported properties, by node path.
        draw: the scene after the tick, as the inspector's vector draw list.
    """

    tick: int
    observation: Any
    reward: float
    terminated: bool
    truncated: bool
    info: dict[str, Any]
    properties: dict[str, dict[str, Any]]
    draw: dict[str, Any]


def read_step(
    cursor: ForkedEnvironment, step: int, result: Result, nodes: Iterable[str] | None
) -> Step:
    """The state after ``step``: what it returned (``result``), read on ``cursor``, there.

    ``nodes``: the paths of the nodes whose properties to read (``None``: every node's).
    """
    observation, reward, terminated, truncated, info = result
    entries = (
        cursor.call("tree") if nodes is None else [cursor.call("node", path) for path in nodes]
    )
    properties = {node["path"]: dict(node["exported"]) for node in entries}
    return Step(
        step,
        copy.deepcopy(observation),
        reward,
        terminated,
        truncated,
        copy.deepcopy(info),
        cursor.call("draw"),
        properties,
    )


def tick_span(step: int, frames: int, first: int, count: int | None) -> int:
    """The last tick of a page from tick ``first``, ``count`` ticks at most (``None``: to the end).

    ``frames``: the ticks of step ``step``.

    Raises:
        IndexError: ``first`` past its ticks.
        ValueError: ``count`` below 1.
    """
    if not 1 <= first <= frames:
        raise IndexError(f"step {step} has ticks 1 to {frames}, not {first}")
    if count is not None and count < 1:
        raise ValueError("count must be at least 1")
    return frames if count is None else min(frames, first + count - 1)


def answer_tick(state: Step, tick: int) -> Tick:
    """A step's own answer (:meth:`~rlenv_tools.timeline.Timeline.at`) as its tick ``tick``."""
    return Tick(
        tick,
        state.observation,
        state.reward,
        state.terminated,
        state.truncated,
        state.info,
        state.properties,
        state.draw,
    )


def read_ticks(
    cursor: ForkedEnvironment, changes: list[list[Any]], action: Any, first: int, last: int
) -> list[Tick]:
    """Ticks ``first`` to ``last`` of an action, taken on a copy of ``cursor`` (then ended).

    ``cursor`` stands at the state before the step, ``changes`` are the events recorded before
    the action. Fewer ticks come back where the episode ends.

    Raises:
        RuntimeError: the environment failed.
    """
    ticking = cursor.fork()
    try:
        return _read_ticks(ticking, changes, action, first, last)
    except (ConnectionError, RemoteError) as error:
        raise RuntimeError(f"the timeline's environment failed: {error}") from None
    finally:
        ticking.end()


def _read_ticks(
    ticking: ForkedEnvironment, changes: list[list[Any]], action: Any, first: int, last: int
) -> list[Tick]:
    """Ticks ``first`` to ``last`` of an action, each taken on ``ticking`` with its own read.

    ``ticking`` is a copy at the state before the step, ``changes`` the events recorded before
    the action. Fewer ticks come back where the episode ends.
    """
    if first > 1 and _skip(ticking, changes, action, first - 1):
        return []  # the episode ended before ``first``
    ticks = []
    for tick in range(first, last + 1):
        events = [*changes, ["action", action, 1]] if tick == 1 else [["action", action, 1]]
        ((_, reward, terminated, truncated, _),), observation, info = ticking.run([events])
        properties = {node["path"]: dict(node["exported"]) for node in ticking.call("tree")}
        ticks.append(
            Tick(
                tick,
                observation,
                reward,
                terminated,
                truncated,
                info,
                properties,
                ticking.call("draw"),
            )
        )
        if terminated or truncated:
            break
    return ticks


def _skip(ticking: ForkedEnvironment, changes: list[list[Any]], action: Any, ticks: int) -> bool:
    """Take the first ``ticks`` ticks of an action unread; whether the episode ended."""
    taken = 0
    while taken < ticks:
        chunk = min(_SKIPPED_AT_ONCE, ticks - taken)
        steps = [[["action", action, 1]] for _ in range(chunk)]
        if taken == 0:
            steps[0] = [*changes, *steps[0]]
        records, _, _ = ticking.run(steps, stop_at_end=True)
        taken += len(records)
        if records[-1][2] or records[-1][3]:
            return True
    return False


def restored_ticks(
    cursor: ForkedEnvironment,
    snapshot: dict[str, Any],
    before: list[list[Any]],
    actions: list[list[Any]],
    first: int,
    last: int,
) -> list[Tick]:
    """Ticks ``first`` to ``last`` of a step, each restored from the log cut at that tick.

    Where agents come and go, a step's ticks cannot be taken one action of one tick at a
    time: at each tick other agents would be due, and answer, than in the step. Instead each
    tick's state is the snapshot ``snapshot`` restored with the events ``before`` the step's
    actions, then its ``actions`` (the action, then the parts that went on while driven agents
    decided) cut at that tick: the state after it, bit for bit, as the step ran it. The answer
    of a restore holds the agents due at that tick and no reward (an agent's reward is summed
    until its decision: the step's answer says it). Each restore runs on a copy of ``cursor``.

    Raises:
        RuntimeError: the environment failed.
    """
    ticks = []
    for tick in range(first, last + 1):
        cut = _cut(actions, tick)
        ticking = cursor.fork()
        try:
            observation, info = ticking.call("restore", {**snapshot, "events": [*before, *cut]})
            properties = {node["path"]: dict(node["exported"]) for node in ticking.call("tree")}
            draw = ticking.call("draw")
        except (ConnectionError, RemoteError) as error:
            raise RuntimeError(f"the timeline's environment failed: {error}") from None
        finally:
            ticking.end()
        ticks.append(Tick(tick, observation, 0.0, False, False, info, properties, draw))
    return ticks


def _cut(actions: list[list[Any]], tick: int) -> list[list[Any]]:
    """A step's ``actions`` (each with the ticks it ran) up to tick ``tick`` of the step."""
    cut = []
    for action in actions:
        frames = int(action[2])
        if tick <= frames:
            cut.append([action[0], action[1], tick, *action[3:]])
            break
        cut.append(action)
        tick -= frames
    return cut
