"""The determinism probes: sets last one episode, and snapshots replay bit for bit.

- **determinism after sets**: a property set with ``inspect set`` lasts for its episode only,
  so ``reset(seed)`` gives the same trajectory before and after the set, and so does a snapshot
  taken right after that reset (skipped when the environment exports no writable float
  property);
- **repeated restores**: a snapshot taken mid-episode (after a mid-episode ``inspect set``)
  restored twice, with other steps between, replays bit for bit what the episode did.

Trajectories are lists of :class:`_Record`, compared by their msgpack bytes, agent by agent
where an answer holds several (by name: where agents come and go, an answer holds some).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rlenv.protocol import ErrorReply, Request, Response, pack
from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv_tools.compliance._harness import Harness, Skipped

__all__ = ["DeterminismProbes"]

_ACTIONS = 12
"""Fixed actions of the determinism and restore probes (fewer if the episode ends first)."""
_MAX_CANDIDATES = 8
"""Writable properties tried, at most, to find one whose set changes the trajectory."""


class DeterminismProbes:
    """The determinism probes of one run, on ``harness`` (its controller in control)."""

    def __init__(self, harness: Harness) -> None:
        self.harness = harness
        self.controller = harness.controller
        self._actions: list[Any] | None = None
        self._property: _Property | None = None
        self._searched = False

    @property
    def actions(self) -> list[Any]:
        """The fixed actions of the trajectories (drawn once)."""
        if self._actions is None:
            self._actions = [self.harness.valid_action() for _ in range(_ACTIONS)]
        return self._actions

    def answer(self, parts: dict[str, Any]) -> Response:
        """The controller's answer to a request of ``parts``.

        Raises:
            RemoteError: the answer is an error.
            Skipped: the environment raised on a request of the contract's probes: they
                cannot judge an environment that fails on actions of its own space.
        """
        self.controller.send_request(Request(0, parts))
        reply = self.controller.receive_reply()
        if isinstance(reply, ErrorReply):
            if reply.code == ErrorCode.ENVIRONMENT_ERROR:
                self.harness.start_episode()  # for the probes after this one
                raise Skipped(
                    "the environment raised on an action of its space: "
                    f"{reply.message.splitlines()[0]}"
                )
            raise RemoteError(reply.code, reply.message, reply.fatal)
        return reply

    def begin(self, start: dict[str, Any]) -> list[_Record]:
        """Start an episode (``{"reset": ...}`` or ``{"restore": ...}``): its first record."""
        response = self.answer({**start, "observation": {"agent": {}}})
        observation, _ = self.controller.reset_result(response)
        return [_Record.of(response, observation)]

    def play(self, actions: Sequence[Any], records: list[_Record]) -> list[_Record]:
        """``records`` followed by the records of ``actions``, until the episode ends."""
        records = list(records)
        for action in actions:
            if records[-1].terminated or records[-1].truncated:
                break
            reply = self.answer(self.controller.step_request(action).parts)
            observation, *_ = self.controller.step_result(reply)
            records.append(_Record.of(reply, observation))
        return records

    def trajectory(self, start: dict[str, Any], actions: Sequence[Any]) -> list[_Record]:
        """The records of an episode started by ``start`` and driven by ``actions``."""
        return self.play(actions, self.begin(start))

    def replay(self, snapshot: dict[str, Any], actions: Sequence[Any]) -> list[_Record] | str:
        """The trajectory of ``actions`` from the restored ``snapshot``, or why it failed."""
        try:
            return self.trajectory({"restore": snapshot}, actions)
        except RemoteError as error:
            return f"{error.code}: {error.message.splitlines()[0] if error.message else ''}"

    def set(self, prop: _Property, value: Any) -> None:
        """``inspect set`` of ``prop`` to ``value``, by the controller."""
        self.controller.set_property(prop.path, prop.name, value)

    def settable(self) -> _Property | None:
        """The property the set probes set; ``None`` if the environment exports none.

        A writable float (or list of floats) property whose set changes the trajectory, else
        the first writable one. Found once.
        """
        if not self._searched:
            self._searched = True
            try:
                self._property = self.find_settable()
            finally:
                self.harness.start_episode()  # the search may have played an episode to its end
        return self._property

    def find_settable(self) -> _Property | None:
        """Search the writable candidates for the property :meth:`settable` returns."""
        baseline = self.trajectory({"reset": {"seed": self.harness.seed}}, self.actions)
        candidates = _writable_candidates(self.controller.tree())  # nodes made at reset too
        fallback = None
        for prop in candidates[:_MAX_CANDIDATES]:
            try:
                start = self.begin({"reset": {"seed": self.harness.seed}})
                self.set(prop, prop.moved())
            except RemoteError as error:
                if error.code != ErrorCode.BAD_REQUEST:
                    raise
                continue  # read-only, or not of the sort it shows
            try:
                moved: list[_Record] | None = self.play(self.actions, start)
            except RemoteError:  # the environment could not run with that value
                moved = None
            self.put_back(prop)
            if moved is None:
                continue
            if _difference(baseline, moved) is not None:
                return prop
            fallback = fallback or prop
        return fallback

    def put_back(self, prop: _Property | None) -> None:
        """Set ``prop`` back to its original value, in a fresh episode.

        A server that keeps sets past a reset would otherwise carry one probe's value into
        the next probe.
        """
        if prop is None:
            return
        try:
            self.controller.reset(seed=self.harness.seed)
            self.set(prop, prop.original)
        except RemoteError:
            pass  # the probe's own finding says more; the controller's next reset tells

    def determinism_after_sets(self) -> None:
        """A set lasts for its episode: the same seed and actions replay bit for bit.

        reset(seed) and fixed actions give the same trajectory before and after an
        ``inspect set``; so does a snapshot taken right after the second reset, restored.
        """
        prop = self.settable()
        if prop is None:
            raise Skipped(
                "the environment exports no writable float (or list of floats) "
                "property in inspect tree"
            )
        seed, value = self.harness.seed, prop.moved()
        try:
            first = self.trajectory({"reset": {"seed": seed}}, self.actions)
            self.set(prop, value)
            start = self.begin({"reset": {"seed": seed}})
            snapshot = self.controller.snapshot()
            second = self.play(self.actions, start)
            restored = self.replay(snapshot, self.actions)
            problems = []
            difference = _difference(first, second)
            if difference is not None:
                problems.append(
                    f"after inspect set {prop} = {value} then reset(seed={seed}), "
                    f"the same actions gave another trajectory than before the "
                    f"set, at {difference}"
                )
            taken = "a snapshot taken right after that reset, restored,"
            if isinstance(restored, str):
                problems.append(f"{taken} expected the trajectory before the set, got {restored}")
            elif (difference := _difference(first, restored)) is not None:
                problems.append(
                    f"{taken} replays that other trajectory too"
                    if problems and _difference(second, restored) is None
                    else f"{taken} gave another trajectory than before the set, at {difference}"
                )
            assert not problems, "; ".join(problems)
        finally:
            self.put_back(prop)
            self.harness.start_episode()

    def repeated_restores(self) -> None:
        """A snapshot restored twice replays what its episode did, bit for bit, each time.

        The snapshot is taken mid-episode (after a mid-episode set, if any property is
        writable) and restored twice, with other steps (and sets) between.
        """
        prop = self.settable()
        seed = self.harness.seed + 1
        head, middle, tail = self.actions[:3], self.actions[3:6], self.actions[6:]
        try:
            played = self.play(head, self.begin({"reset": {"seed": seed}}))
            taken = f"after reset(seed={seed})"
            if prop is not None:
                value = prop.moved()
                self.set(prop, value)
                taken += f", {len(played) - 1} steps, inspect set {prop} = {value}"
            played = self.play(middle, played)
            snapshot = self.controller.snapshot()
            taken += f" and {len(played) - 1} steps in all"
            original = self.play(tail, played[-1:])
            first = self.replay(snapshot, tail)
            between = self.begin({"reset": {"seed": seed + 1}})  # other steps between
            if prop is not None:
                self.set(prop, prop.moved(2))
            self.play(head, between)
            second = self.replay(snapshot, tail)
            problems = []
            for ordinal, restored in (("first", first), ("second", second)):
                what = f"the {ordinal} restore of a snapshot taken {taken}"
                if isinstance(restored, str):
                    problems.append(f"{what}: expected it to replay the episode, got {restored}")
                elif (difference := _difference(original, restored)) is not None:
                    problems.append(
                        f"{what}, then the same actions, differs from what the "
                        f"episode did after the snapshot, at {difference}"
                    )
            if (
                not isinstance(first, str)
                and not isinstance(second, str)
                and (difference := _difference(first, second)) is not None
            ):
                problems.append(f"the two restores differ from each other, at {difference}")
            assert not problems, "; ".join(problems)
        finally:
            self.put_back(prop)
            self.harness.start_episode()


@dataclass(frozen=True)
class _Property:
    """An exported property of a float or a list of floats, as ``inspect tree`` showed it."""

    path: str
    name: str
    original: float | list[float]

    def moved(self, times: int = 1) -> float | list[float]:
        """A clearly different value.

        Each number moves away from zero by its magnitude (at least 1), ``times`` times, so
        that signs (a mass, a length) stay as they were.
        """

        def move(value: float) -> float:
            return value + times * math.copysign(max(1.0, abs(value)), value)

        if isinstance(self.original, list):
            return [move(value) for value in self.original]
        return move(self.original)

    def __str__(self) -> str:
        return f"{self.path}:{self.name}"


def _writable_candidates(tree: Any) -> list[_Property]:
    """Exported properties holding a finite float or a list of them.

    Vectors (a gravity, say) first, then in tree order. Whether one is writable only a set can
    tell.
    """

    def is_float(value: Any) -> bool:
        return type(value) is float and math.isfinite(value)

    found = []
    for node in tree if isinstance(tree, list) else ():
        exported = node.get("exported") if isinstance(node, dict) else None
        if not isinstance(exported, dict) or not isinstance(node.get("path"), str):
            continue
        for name, value in exported.items():
            if is_float(value) or (
                isinstance(value, list) and value and all(is_float(item) for item in value)
            ):
                found.append(_Property(node["path"], str(name), value))
    return sorted(found, key=lambda prop: not isinstance(prop.original, list))


@dataclass(frozen=True)
class _Record:
    """One answer of a trajectory: the observation as it travelled and as read, and the rest."""

    sent: Any
    observation: Any
    reward: float
    terminated: bool
    truncated: bool
    frames: int
    agents: Any

    @classmethod
    def of(cls, response: Response, observation: Any) -> _Record:
        """The record of ``response``, whose agent observation reads as ``observation``."""
        sent = response.observation.get("agent") if response.observation else None
        return cls(
            sent,
            observation,
            response.reward,
            response.terminated,
            response.truncated,
            response.frames,
            response.agents,
        )

    def bits(self, start: bool) -> bytes:
        """The record as msgpack (floats as float 64): equal bytes, bit-identical records.

        The start of a trajectory (the answer to a reset or a restore, or the step a snapshot
        was taken after) compares by its observation and flags only.
        """
        fields = [_by_agent(self.sent), self.terminated, self.truncated]
        if not start:
            fields += [self.reward, self.frames, _by_agent(self.agents)]
        return pack(fields)

    def agent_difference(self, other: _Record, start: bool) -> str:
        """``", at agent NAME"``: the first agent (by name) whose part differs, else ``""``.

        An answer of several agents is compared agent by agent, by name: its observation
        and, past the start, its reward and flags.
        """
        parts = [(self.sent, other.sent)] + ([] if start else [(self.agents, other.agents)])
        for mine, theirs in parts:
            if not (isinstance(mine, dict) and isinstance(theirs, dict)):
                continue
            for name in sorted(mine.keys() | theirs.keys(), key=str):
                if name not in mine or name not in theirs:
                    return f", at agent {name!r} (in one answer only)"
                if pack(mine[name]) != pack(theirs[name]):
                    return f", at agent {name!r}"
        return ""

    def show(self, start: bool) -> str:
        """The record, for a failure line."""
        text = f"observation {_show(self.observation)}"
        if not start:
            text += f", reward {self.reward!r}, frames {self.frames}"
            if self.agents is not None:
                text += f", agents {self.agents!r}"
        if self.terminated or self.truncated:
            text += ", terminated" if self.terminated else ", truncated"
        return text


def _difference(expected: Sequence[_Record], got: Sequence[_Record]) -> str | None:
    """Where two trajectories first differ, in words; ``None`` if they are bit-identical."""
    for index, (want, have) in enumerate(zip(expected, got, strict=False)):
        start = index == 0
        if want.bits(start) != have.bits(start):
            where = "the first observation" if start else f"step {index}"
            shown_want, shown_have = want.show(start), have.show(start)
            bits = " (equal as printed, different bits)" if shown_want == shown_have else ""
            agent = want.agent_difference(have, start)
            return f"{where}{agent}: expected {shown_want:.240}, got {shown_have:.240}{bits}"
    if len(expected) != len(got):
        return f"the episode lasted {len(got) - 1} steps, expected {len(expected) - 1}"
    return None


def _by_agent(value: Any) -> Any:
    """A map of agents as pairs sorted by name (answers compare agent by agent), else itself."""
    if isinstance(value, dict):
        return sorted(value.items(), key=lambda item: str(item[0]))
    return value


def _show(value: Any) -> str:
    if isinstance(value, np.ndarray):
        if value.size > 64:
            return f"<array {value.dtype.str} {value.shape}: {_show(value.flat[:8].copy())}...>"
        if value.ndim == 0:
            return _show(value[()])
        return "[" + ", ".join(_show(item) for item in value) + "]"
    if isinstance(value, np.generic):
        return str(value)  # as short as its dtype allows
    if isinstance(value, dict):
        return "{" + ", ".join(f"{key!r}: {_show(item)}" for key, item in value.items()) + "}"
    if isinstance(value, tuple | list):
        return "(" + ", ".join(_show(item) for item in value) + ")"
    return repr(value)
