"""The processes behind a timeline and its branches: the checkpoints, and the cursor's walk.

A :class:`~rlenv_tools.timeline.Timeline` re-simulates its episode in processes it starts, owns
and ends (:mod:`rlenv_tools.forking`): :class:`Processes` holds them (the first, the parked
copies, the cursor that steps) and brings the cursor to a step of a timeline, parking
checkpoints on the way; :class:`Checkpoints` says which steps of one timeline have a parked
copy, and :func:`measured_spacing` how far apart they go.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from rlenv.protocol.errors import RemoteError
from rlenv_client._recorded_parts import as_recorded
from rlenv_client.replay import digest
from rlenv_tools.forking import ForkedEnvironment, StepRecord

if TYPE_CHECKING:
    from rlenv_tools.timeline import Timeline

__all__ = ["WORKING", "Checkpoints", "Mark", "Processes", "Result", "measured_spacing"]

_PROBE_STEPS = 8  # steps timed at a time to space the checkpoints (twice: the least spacing)
_PROBE_ROUNDS = 4  # times they are timed
_REPLAY_BUDGET = 0.005  # seconds of steps from a checkpoint to the step asked for, at most
_MOST_APART = 1000  # steps between two checkpoints, at most (unless the episode is longer)
_MOST_CHECKPOINTS = 256  # over one episode (and at most half a timeline's processes)
WORKING = 2
"""Processes besides the checkpoints: the cursor, a tick view's copy."""
_MEASURE_EVERY = 8  # parks between two measures of the memory (an eighth of them, past 64)
Result = tuple[Any, float, bool, bool, dict[str, Any]]  # observation, reward, ends, info
Events = list[list[list[Any]]]  # each step's events: changes, its action, its parts


@dataclass(frozen=True)
class Mark:
    """A checkpoint: a parked copy of the environment at a step, and what that step returned."""

    environment: ForkedEnvironment
    result: Result


class Checkpoints:
    """Parked copies every ``every`` steps (the reset's at 0), as a timeline passes them.

    Going to step ``k`` copies the nearest one at or before ``k`` and takes at most
    ``every - 1`` steps from there.
    """

    def __init__(self, every: int, marks: Mapping[int, Mark]) -> None:
        self.every = every
        self._marks = dict(marks)

    def due(self, step: int) -> bool:
        """Whether a checkpoint should be parked on reaching ``step``."""
        return step % self.every == 0 and step not in self._marks

    def next_due(self, step: int) -> int:
        """The first step after ``step`` where one is due."""
        return (step // self.every + 1) * self.every

    def keep(self, step: int, mark: Mark) -> None:
        """Remember ``mark`` as the checkpoint at ``step``."""
        self._marks[step] = mark

    def nearest(self, step: int) -> tuple[int, Mark]:
        """The checkpoint at ``step`` or the latest before it."""
        best = max(k for k in self._marks if k <= step)
        return best, self._marks[best]

    def within(self, length: int, room: int) -> None:
        """Space them so that ``length`` steps park at most half of ``room`` more processes."""
        self.every = max(self.every, -(-length // (room // 2 or 1)))

    def upto(self, step: int) -> Checkpoints:
        """A copy holding the checkpoints at ``step`` and before (a branch's shared part)."""
        return Checkpoints(self.every, {k: m for k, m in self._marks.items() if k <= step})


def measured_spacing(length: int, goto: Callable[[int], object]) -> int:
    """Checkpoints as far apart as ~5 ms of steps, from the cost of the first few.

    ``goto`` brings the timeline (of ``length`` steps) to a step. The first steps after a copy
    pay for its first writes to shared pages; the next ones are timed, a few at a time, and
    the quickest few count (the machine's noise only ever adds).
    """
    if length < _PROBE_STEPS * (_PROBE_ROUNDS + 1):
        return _MOST_APART
    goto(_PROBE_STEPS)
    costs = []
    for round_ in range(2, _PROBE_ROUNDS + 2):
        began = time.perf_counter()
        goto(round_ * _PROBE_STEPS)
        costs.append((time.perf_counter() - began) / _PROBE_STEPS)
    spacing = min(_MOST_APART, max(2 * _PROBE_STEPS, int(_REPLAY_BUDGET / min(costs))))
    return max(spacing, -(-length // _MOST_CHECKPOINTS))


class Processes:
    """The processes of a root timeline and its branches: the first, parked copies, the cursor.

    The cursor is the copy that steps; ``position`` says which timeline's step it stands at.
    At most ``limit`` processes at once (the cursor and a tick view's copy included), holding
    at most ``memory`` bytes (their PSS, measured every few parks): past either, no more
    checkpoints are parked (going to a step then takes more steps from an earlier one).
    """

    def __init__(self, target: str, timeout: float, limit: int, memory: int) -> None:
        self.first = ForkedEnvironment.start(target, timeout=timeout)
        self.parked: list[ForkedEnvironment] = [self.first]
        self.cursor: ForkedEnvironment | None = None
        self.position: tuple[Timeline, int] | None = None
        self.result: Result | None = None
        self.closed = False
        self.limit = limit
        self.memory = memory
        self.driven: frozenset[str] = frozenset()  # the recording's server's (as_recorded)
        self._measured = 0  # bytes, at the last measure
        self._since = 0  # parks since

    def room(self) -> int:
        """How many more checkpoints may be parked now."""
        if self._measured > self.memory:
            return 0
        return max(0, self.limit - len(self.parked) - WORKING)

    def park(self, environment: ForkedEnvironment) -> ForkedEnvironment | None:
        """A copy of ``environment`` kept as it is now (``None``: no room left for one)."""
        if self._since >= max(_MEASURE_EVERY, len(self.parked) // 8):
            self._since, self._measured = 0, self.used()
        if not self.room():
            return None
        copy = environment.fork()
        self.parked.append(copy)
        self._since += 1
        return copy

    def used(self) -> int:
        """The memory the processes hold (PSS), in bytes."""
        cursor = [] if self.cursor is None else [self.cursor]
        return sum(environment.memory() for environment in self.parked + cursor)

    def pids(self) -> list[int]:
        """The ids of the processes holding the environment and its checkpoints."""
        cursor = [] if self.cursor is None else [self.cursor]
        return [environment.pid for environment in self.parked + cursor]

    def stepping(self) -> ForkedEnvironment:
        """The cursor (there is one: a timeline brought it to a step)."""
        assert self.cursor is not None
        return self.cursor

    def resume(self, mark: Mark) -> ForkedEnvironment:
        """A new cursor: a copy of the checkpoint's (the old cursor ends)."""
        self.drop_cursor()
        self.cursor = mark.environment.fork()
        return self.cursor

    def goto(
        self,
        timeline: Timeline,
        step: int,
        steps: Events,
        checkpoints: Checkpoints,
        records: list[StepRecord],
        check: Callable[[int, str], None],
    ) -> Result:
        """Bring the cursor to ``step`` of ``timeline``; what that step returned.

        ``steps``, ``checkpoints`` and ``records`` are the timeline's; from where the cursor
        stands on it, or else from the nearest checkpoint, the steps are taken (as
        :meth:`take` takes them, each checked).
        """
        if self.closed:
            raise RuntimeError("the timeline is closed")
        base, mark = checkpoints.nearest(step)
        position = self.position
        try:
            if position is not None and position[0] is timeline and base <= position[1] <= step:
                base, result = position[1], self.result
            else:
                self.resume(mark)
                result = mark.result
            result = self.take(
                base,
                steps[base:step],
                result,  # type: ignore[arg-type]
                checkpoints,
                records,
                check,
            )
        except (ConnectionError, RemoteError) as error:
            self.drop_cursor()
            raise RuntimeError(f"the timeline's environment failed: {error}") from None
        self.position, self.result = (timeline, step), result
        assert result is not None
        return result

    def take(
        self,
        step: int,
        steps: Events,
        result: Result,
        checkpoints: Checkpoints,
        records: list[StepRecord],
        check: Callable[[int, str], None] | None,
    ) -> Result:
        """Take ``steps`` after ``step`` on the cursor, parking checkpoints where due.

        A timeline's own steps are checked against the recording (``check(step, digest)``;
        the first time through a recording without digests, recorded); a branch's new steps
        (no ``check``) stop where its episode ends.
        """
        cursor = self.stepping()
        done = 0
        while done < len(steps):
            chunk = steps[done : checkpoints.next_due(step + done) - step]
            taken, observation, info = cursor.run(
                chunk, stop_at_end=check is None, driven=sorted(self.driven)
            )
            for record in taken:
                done += 1
                if step + done > len(records):
                    records.append(record)
                if check is not None:
                    check(step + done, record[0])
            result = (observation, *taken[-1][1:4], info)
            self.park_if_due(step + done, checkpoints, result)
            if check is None and (result[2] or result[3]):
                break
        return result

    def play(
        self,
        policy: Callable[[Any], Any],
        max_steps: int,
        repeat_action: int | None,
        result: Result,
        checkpoints: Checkpoints,
        records: list[StepRecord],
    ) -> Result:
        """A branch's new steps on the cursor, ``policy`` choosing each action.

        At most ``max_steps`` of them, fewer where its episode ends; checkpoints are parked
        where due.
        """
        cursor = self.stepping()
        for _ in range(max_steps):
            action = policy(result[0])
            answer = cursor.call("step", action, repeat_action)
            hello = self.first.hello
            assert hello is not None  # a started process said its hello
            observation, reward, terminated, truncated, info = as_recorded(
                answer, hello, self.driven
            )
            result = (observation, float(reward), bool(terminated), bool(truncated), info)
            records.append((digest(observation), *result[1:4], info.get("agents")))
            self.park_if_due(len(records), checkpoints, result)
            if terminated or truncated:
                break
        return result

    def park_if_due(self, step: int, checkpoints: Checkpoints, result: Result) -> None:
        """Park a copy of the cursor as the checkpoint at ``step``, where one is due (and fits)."""
        if checkpoints.due(step):
            parked = self.park(self.stepping())
            if parked is not None:
                checkpoints.keep(step, Mark(parked, result))

    def every_observation(self, mark: Mark, steps: Events) -> list[Any]:
        """Every step's observation, re-simulated from ``mark`` (a reset's) in one run."""
        try:
            cursor = self.resume(mark)
            observations = [mark.result[0]]
            if steps:
                observations += cursor.run(steps, observations=True, driven=sorted(self.driven))[1]
        except (ConnectionError, RemoteError) as error:
            self.drop_cursor()
            raise RuntimeError(f"the timeline's environment failed: {error}") from None
        self.position, self.result = None, None
        return observations

    def drop_cursor(self) -> None:
        """End the cursor (its copies live on)."""
        self.position = self.result = None
        if self.cursor is not None:
            self.cursor.close()
            self.cursor = None

    def close(self) -> None:
        """End every process; wait until they are gone."""
        if self.closed:
            return
        self.closed = True
        self.drop_cursor()
        for environment in self.parked:
            environment.close()
        for environment in self.parked:
            environment.end()
        self.parked.clear()
