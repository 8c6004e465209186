"""The contract probes: the promises of the protocol (``docs/protocol.md``) a server must keep.

Each is a probe whose failure line says what was expected and what came back:

- **control**: a refused request takes no control (another client's refused ``reset`` before
  the controller's first one); while the controller holds control, another client's ``reset``
  and actions get a non-fatal ``busy``, and its observations, snapshots, ``inspect`` reads,
  ``action: nil`` and id-only requests are answered;
- **determinism after sets**: a property set with ``inspect set`` lasts for its episode only,
  so ``reset(seed)`` gives the same trajectory before and after the set, and so does a snapshot
  taken right after that reset (skipped when the environment exports no writable float
  property);
- **repeated restores**: a snapshot taken mid-episode (after a mid-episode ``inspect set``)
  restored twice, with other steps between, replays bit for bit what the episode did;
- **ext types**: a request holding msgpack ext type -1 (timestamp) or a foreign one gets a
  non-fatal ``bad_frame`` and the connection goes on; every reply the suite reads holds no ext
  type but 1;
- **the token rule** (when given the token): a malformed first frame is answered ``bad_request``
  without closing the connection, the next request with the token is accepted; a wrong token
  on the first request is a fatal ``unauthorized``.

Trajectories are lists of :class:`_Record`, compared by their msgpack bytes.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rlenv.protocol import ErrorReply, Request, Response, pack
from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv.testing import frame
from rlenv_client.compliance.harness import (
    Harness,
    Probes,
    Skipped,
    assert_error,
    connection_closed,
)

__all__ = ["ContractProbes"]

_ACTIONS = 12
"""Fixed actions of the determinism and restore probes (fewer if the episode ends first)."""
_MAX_CANDIDATES = 8
"""Writable properties tried, at most, to find one whose set changes the trajectory."""


class ContractProbes:
    """The contract probes of one run, on ``harness``."""

    def __init__(self, harness: Harness) -> None:
        self.harness = harness
        self.controller = harness.controller
        self._actions: list[Any] | None = None
        self._property: _Property | None = None
        self._searched = False

    def ext_type_probes(self) -> Probes:
        """Requests holding ext type -1 (a timestamp) or a foreign one."""
        return [("ext type -1 (a msgpack timestamp) in reset.options",
                 lambda: self.ext_type_refused(-1)),
                ("ext type 5 in reset.options", lambda: self.ext_type_refused(5))]

    def probes_under_control(self) -> Probes:
        """The probes that need the controller in control, last the tap's final reading."""
        return [
            ("another client while the controller holds control",
             self.open_to_all_while_controlled),
            ("determinism after sets", self.determinism_after_sets),
            ("repeated restores", self.repeated_restores),
            ("no ext type but 1 in the server's frames", self.no_foreign_ext_types),
        ]

    # --- ext types and the token rule, on raw connections ---

    def ext_type_refused(self, code: int) -> None:
        """A request holding ext ``code`` (a fixext 4) in ``reset.options`` is refused.

        The answer is a non-fatal ``bad_frame`` naming the ext type, and the connection
        answers the next request.
        """
        ext = b"\xd6" + struct.pack("b", code) + b"\x00\x00\x00\x00"
        body = b"\x82\xa2id\x01\xa5reset\x81\xa7options\x81\xa4when" + ext
        with self.harness.connect() as sock:
            self.harness.send_probe(sock, frame(body))
            reply = self.harness.read_frame(sock)
            assert_error(reply, ErrorCode.BAD_FRAME, "ext type", fatal=False)
            message = reply["error"]["message"]
            assert str(code) in message, \
                f"expected the message to name ext type {code}, got {message!r}"
            sock.sendall(frame(pack({"id": 2})))
            after = self.harness.read_frame(sock)
            assert after.get("id") == 2 and "error" not in after, \
                f"after the refused frame, expected an answer to {{'id': 2}}, got {after!r:.200}"

    def token_rule(self) -> None:
        """The token is checked on the first request, not the first frame.

        A malformed first frame carrying the token is refused (``bad_request``) without
        closing; the next request with the token is accepted; a wrong (or missing) token on a
        fresh connection's first request is a fatal ``unauthorized``.
        """
        harness, token = self.harness, self.harness.token
        if token is None:
            raise Skipped("no token was given to the suite")
        problems = []
        with harness.connect(authenticate=False) as sock:
            if not harness.hello.get("token_required"):
                raise Skipped("the server requires no token")
            harness.send_probe(sock, frame(pack({"id": "x", "token": token})))
            try:
                assert_error(harness.read_frame(sock), ErrorCode.BAD_REQUEST, "id", fatal=False)
                sock.sendall(frame(pack({"id": 1, "token": token})))
                after = harness.read_frame(sock)
                assert after.get("id") == 1 and "error" not in after, \
                    f"then expected {{'id': 1, 'token': ...}} to be accepted, got {after!r:.200}"
            except AssertionError as failure:
                problems.append(f"a malformed first frame {{'id': 'x', 'token': ...}}: {failure}")
        for what, request in (("a wrong token", {"id": 1, "token": token + "-wrong"}),
                              ("no token", {"id": 1})):
            with harness.connect(authenticate=False) as sock:
                harness.send_probe(sock, frame(pack(request)))
                reply = harness.read_frame(sock)
                try:
                    assert_error(reply, ErrorCode.UNAUTHORIZED, "", fatal=True)
                    assert connection_closed(sock), "the connection stayed open"
                except AssertionError as failure:
                    problems.append(f"a first request with {what}: {failure}")
        assert not problems, "; ".join(problems)

    # --- control ---

    def refused_request_takes_no_control(self) -> None:
        """A refused request takes no control.

        While nobody controls the environment, another client's refused requests (a reset
        with seed -1, a reset with an invalid action) leave the controller's first reset
        answered, not ``busy``. The other client stays connected meanwhile.
        """
        with self.harness.client() as other:
            for what, parts, code in (
                ("reset(seed=-1)", {"reset": {"seed": -1}}, ErrorCode.BAD_REQUEST),
                ("a reset with the action 'jump'", {"reset": {}, "action": "jump"},
                 ErrorCode.INVALID_ACTION),
            ):
                other.send_request(Request(0, parts))
                reply = other.receive_reply()
                assert isinstance(reply, ErrorReply), \
                    f"another client's {what} was accepted: {reply!r:.160}"
                assert reply.code == code, \
                    f"another client's {what}: expected {code}, got {reply.code}: " \
                    f"{reply.message}"
            try:
                self.harness.start_episode()
            except RemoteError as error:
                assert error.code != ErrorCode.BUSY, (
                    "after another client's refused requests, expected the first valid reset "
                    f"to be answered, got busy: {error.message}")
                raise

    def open_to_all_while_controlled(self) -> None:
        """Only the controller steps the environment; everyone may look at it, and edit it.

        Another client's reset and action get a non-fatal ``busy`` and change nothing; its
        observation, snapshot, inspect tree and get, ``action: nil`` and an id-only request
        are answered; so is its ``inspect set`` (an inspector's edit, protocol 2.2), which the
        controller's snapshot then records.
        """
        problems = []
        own = self.answer({"observation": {"agent": {}}}).observation
        tree = self.controller.tree()
        readable = next(((node["path"], name) for node in tree
                         for name in node.get("exported") or ()), None)
        writable = next(([node["path"], name, value] for node in tree
                         for name, value in (node.get("exported") or {}).items()
                         if name not in node.get("read_only", ()) and type(value) is float),
                        None)
        with self.harness.client() as other:
            for what, parts in (("reset(seed=1)", {"reset": {"seed": 1}}),
                                ("action", other.step_request(self.harness.valid_action()).parts)):
                other.send_request(Request(0, parts))
                reply = other.receive_reply()
                if not isinstance(reply, ErrorReply):
                    problems.append(f"another client's {what} was accepted while the "
                                    "controller held control")
                elif reply.code != ErrorCode.BUSY or reply.fatal:
                    fatal = "fatal " if reply.fatal else ""
                    problems.append(f"another client's {what}: expected a non-fatal busy, got "
                                    f"{fatal}{reply.code}: {reply.message}")
            answered: list[tuple[str, dict[str, Any]]] = [
                ("observation", {"observation": {"agent": {}}}),
                ("snapshot", {"snapshot": {}}),
                ("inspect tree", {"inspect": {"tree": {}}}),
                ("{'action': nil}", {"action": None}),
                ("id-only request", {}),
            ]
            if readable is not None:
                answered.append((f"inspect get of {readable[0]}:{readable[1]}", {"inspect": {
                    "get": {"path": readable[0], "property": readable[1]}}}))
            if writable is not None:  # set to the value it has: logged, changes nothing
                path, name, value = writable
                answered.append((f"inspect set of {path}:{name}", {"inspect": {
                    "set": {"path": path, "property": name, "value": value}}}))
            for what, parts in answered:
                other.send_request(Request(0, parts))
                reply = other.receive_reply()
                if isinstance(reply, ErrorReply):
                    problems.append(f"another client's {what}: expected an answer, got "
                                    f"{reply.code}: {reply.message}")
                elif what == "observation" and pack(reply.observation) != pack(own):
                    problems.append("another client's observation differs from the "
                                    "controller's: the refused requests changed the environment")
        if writable is not None and not problems:
            events = self.controller.snapshot()["events"]
            if not events or list(events[-1]) != ["set", *writable]:
                problems.append(f"another client's inspect set of {writable[0]}:{writable[1]} "
                                f"is not the last event of the controller's snapshot: "
                                f"{events[-1:]!r:.120}")
        assert not problems, "; ".join(problems)


    # --- sets, snapshots, restores: trajectories compared bit for bit ---

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
                raise Skipped("the environment raised on an action of its space: "
                              f"{reply.message.splitlines()[0]}")
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
            self._property = self.find_settable()
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
            raise Skipped("the environment exports no writable float (or list of floats) "
                          "property in inspect tree")
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
                problems.append(f"after inspect set {prop} = {value} then reset(seed={seed}), "
                                f"the same actions gave another trajectory than before the "
                                f"set, at {difference}")
            taken = "a snapshot taken right after that reset, restored,"
            if isinstance(restored, str):
                problems.append(f"{taken} expected the trajectory before the set, got {restored}")
            elif (difference := _difference(first, restored)) is not None:
                problems.append(
                    f"{taken} replays that other trajectory too" if problems and
                    _difference(second, restored) is None else
                    f"{taken} gave another trajectory than before the set, at {difference}")
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
                    problems.append(f"{what}, then the same actions, differs from what the "
                                    f"episode did after the snapshot, at {difference}")
            if not isinstance(first, str) and not isinstance(second, str) and \
                    (difference := _difference(first, second)) is not None:
                problems.append(f"the two restores differ from each other, at {difference}")
            assert not problems, "; ".join(problems)
        finally:
            self.put_back(prop)
            self.harness.start_episode()

    def no_foreign_ext_types(self) -> None:
        """No frame the suite read so far held an ext type other than 1."""
        found = self.harness.tap.unreported()
        assert not found, "; ".join(found)



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
            if is_float(value) or (isinstance(value, list) and value and
                                   all(is_float(item) for item in value)):
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
        return cls(sent, observation, response.reward, response.terminated,
                   response.truncated, response.frames, response.agents)

    def bits(self, start: bool) -> bytes:
        """The record as msgpack (floats as float 64): equal bytes, bit-identical records.

        The start of a trajectory (the answer to a reset or a restore, or the step a snapshot
        was taken after) compares by its observation and flags only.
        """
        fields = [self.sent, self.terminated, self.truncated]
        if not start:
            fields += [self.reward, self.frames, self.agents]
        return pack(fields)

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
            return f"{where}: expected {shown_want:.240}, got {shown_have:.240}{bits}"
    if len(expected) != len(got):
        return f"the episode lasted {len(got) - 1} steps, expected {len(expected) - 1}"
    return None


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

