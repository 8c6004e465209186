"""The contract probes: the promises of the protocol (``docs/protocol.md``) a server must keep.

Each is a probe whose failure line says what was expected and what came back:

- **control**: a refused request takes no control (another client's refused ``reset`` before
  the controller's first one); while the controller holds control, another client's ``reset``
  and actions get a non-fatal ``busy``, and its observations, snapshots, ``inspect`` reads,
  ``action: nil`` and id-only requests are answered;
- **determinism after sets** and **repeated restores**:
  :class:`~rlenv_tools.compliance._determinism.DeterminismProbes`;
- **ext types**: a request holding msgpack ext type -1 (timestamp) or a foreign one gets a
  non-fatal ``bad_frame`` and the connection goes on; every reply the suite reads holds no ext
  type but 1;
- **the token rule** (when given the token): a malformed first frame is answered ``bad_request``
  without closing the connection, the next request with the token is accepted; a wrong token
  on the first request is a fatal ``unauthorized``.
"""

from __future__ import annotations

import struct
from typing import Any

from rlenv.protocol import ErrorReply, Request, pack
from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv.testing import frame
from rlenv_tools.compliance._determinism import DeterminismProbes
from rlenv_tools.compliance._harness import (
    Harness,
    Probes,
    Skipped,
    assert_error,
    connection_closed,
)

__all__ = ["ContractProbes"]


class ContractProbes:
    """The contract probes of one run, on ``harness``."""

    def __init__(self, harness: Harness) -> None:
        self.harness = harness
        self.controller = harness.controller
        self.determinism = DeterminismProbes(harness)

    def ext_type_probes(self) -> Probes:
        """Requests holding ext type -1 (a timestamp) or a foreign one."""
        return [
            (
                "ext type -1 (a msgpack timestamp) in reset.options",
                lambda: self.ext_type_refused(-1),
            ),
            ("ext type 5 in reset.options", lambda: self.ext_type_refused(5)),
        ]

    def probes_under_control(self) -> Probes:
        """The probes that need the controller in control, last the tap's final reading."""
        return [
            (
                "another client while the controller holds control",
                self.open_to_all_while_controlled,
            ),
            ("determinism after sets", self.determinism.determinism_after_sets),
            ("repeated restores", self.determinism.repeated_restores),
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
            assert str(code) in message, (
                f"expected the message to name ext type {code}, got {message!r}"
            )
            sock.sendall(frame(pack({"id": 2})))
            after = self.harness.read_frame(sock)
            assert after.get("id") == 2 and "error" not in after, (
                f"after the refused frame, expected an answer to {{'id': 2}}, got {after!r:.200}"
            )

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
                assert after.get("id") == 1 and "error" not in after, (
                    f"then expected {{'id': 1, 'token': ...}} to be accepted, got {after!r:.200}"
                )
            except AssertionError as failure:
                problems.append(f"a malformed first frame {{'id': 'x', 'token': ...}}: {failure}")
        for what, request in (
            ("a wrong token", {"id": 1, "token": token + "-wrong"}),
            ("no token", {"id": 1}),
        ):
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
                (
                    "a reset with the action 'jump'",
                    {"reset": {}, "action": "jump"},
                    ErrorCode.INVALID_ACTION,
                ),
            ):
                other.send_request(Request(0, parts))
                reply = other.receive_reply()
                assert isinstance(reply, ErrorReply), (
                    f"another client's {what} was accepted: {reply!r:.160}"
                )
                assert reply.code == code, (
                    f"another client's {what}: expected {code}, got {reply.code}: {reply.message}"
                )
            try:
                self.harness.start_episode()
            except RemoteError as error:
                assert error.code != ErrorCode.BUSY, (
                    "after another client's refused requests, expected the first valid reset "
                    f"to be answered, got busy: {error.message}"
                )
                raise

    def open_to_all_while_controlled(self) -> None:
        """Only the controller steps the environment; everyone may look at it, and edit it.

        Another client's reset and action get a non-fatal ``busy`` and change nothing; its
        observation, snapshot, inspect tree and get, ``action: nil`` and an id-only request
        are answered; so is its ``inspect set`` (an inspector's edit, protocol 2.2), which the
        controller's snapshot then records.
        """
        problems = []
        own = self.determinism.answer({"observation": {"agent": {}}}).observation
        answered, writable = _open_requests(self.controller.tree())
        with self.harness.client() as other:
            for what, parts in (
                ("reset(seed=1)", {"reset": {"seed": 1}}),
                ("action", other.step_request(self.harness.valid_action()).parts),
            ):
                other.send_request(Request(0, parts))
                reply = other.receive_reply()
                if not isinstance(reply, ErrorReply):
                    problems.append(
                        f"another client's {what} was accepted while the controller held control"
                    )
                elif reply.code != ErrorCode.BUSY or reply.fatal:
                    fatal = "fatal " if reply.fatal else ""
                    problems.append(
                        f"another client's {what}: expected a non-fatal busy, got "
                        f"{fatal}{reply.code}: {reply.message}"
                    )
            for what, parts in answered:
                other.send_request(Request(0, parts))
                reply = other.receive_reply()
                if isinstance(reply, ErrorReply):
                    problems.append(
                        f"another client's {what}: expected an answer, got "
                        f"{reply.code}: {reply.message}"
                    )
                elif (
                    what == "observation"
                    and (
                        difference := _observer_difference(
                            own,
                            reply.observation,
                            self.controller.hello.possible_agents is not None,
                        )
                    )
                    is not None
                ):
                    problems.append(
                        f"another client's observation differs from the "
                        f"controller's{difference}: the refused requests changed the environment"
                    )
        if writable is not None and not problems:
            events = self.controller.snapshot()["events"]
            if not events or list(events[-1]) != ["set", *writable]:
                problems.append(
                    f"another client's inspect set of {writable[0]}:{writable[1]} "
                    f"is not the last event of the controller's snapshot: "
                    f"{events[-1:]!r:.120}"
                )
        assert not problems, "; ".join(problems)

    def no_foreign_ext_types(self) -> None:
        """No frame the suite read so far held an ext type other than 1."""
        found = self.harness.tap.unreported()
        assert not found, "; ".join(found)


def _observer_difference(own: Any, observers: Any, come_and_go: bool) -> str | None:
    """How an observer's observation differs from the controller's, or ``None``.

    Where agents come and go, the controller's answer holds the agents of its last answer and
    an observer's every agent in play: each of the controller's agents is compared, agent by
    agent (``", at agent NAME"`` names the first that differs).
    """
    if not come_and_go:
        return None if pack(observers) == pack(own) else ""
    mine, theirs = (
        (value or {}).get("agent") or {} if isinstance(value, dict) else {}
        for value in (own, observers)
    )
    for name, value in mine.items():
        if name not in theirs or pack(theirs[name]) != pack(value):
            return f", at agent {name!r}"
    return None


def _open_requests(
    tree: list[dict[str, Any]],
) -> tuple[list[tuple[str, dict[str, Any]]], list[Any] | None]:
    """The requests any client may send while another controls, each with its name in words.

    The reads, ``action: nil`` and an id-only request; an ``inspect get`` of the first exported
    property in ``tree`` (the controller's inspect tree), and an ``inspect set`` of the first
    writable float property to the value it has (logged, it changes nothing).

    Returns:
        The named requests' parts, and the set's ``[path, property, value]`` (``None``: the
        tree has no writable float property).
    """
    readable = next(
        ((node["path"], name) for node in tree for name in node.get("exported") or ()), None
    )
    writable = next(
        (
            [node["path"], name, value]
            for node in tree
            for name, value in (node.get("exported") or {}).items()
            if name not in node.get("read_only", ()) and type(value) is float
        ),
        None,
    )
    answered: list[tuple[str, dict[str, Any]]] = [
        ("observation", {"observation": {"agent": {}}}),
        ("snapshot", {"snapshot": {}}),
        ("inspect tree", {"inspect": {"tree": {}}}),
        ("{'action': nil}", {"action": None}),
        ("id-only request", {}),
    ]
    if readable is not None:
        answered.append(
            (
                f"inspect get of {readable[0]}:{readable[1]}",
                {"inspect": {"get": {"path": readable[0], "property": readable[1]}}},
            )
        )
    if writable is not None:
        path, name, value = writable
        answered.append(
            (
                f"inspect set of {path}:{name}",
                {"inspect": {"set": {"path": path, "property": name, "value": value}}},
            )
        )
    return answered, writable
