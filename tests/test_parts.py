"""Tests of request parts (``rlenv.serving._parts``), served by a Host in this process.

The protocol only checks a request's envelope (an integer id, a string token: see
``test_protocol.py``); what its parts may hold, and in which company, is the server's part
table. Each refusal is checked for its code, for the fragment of its message that names the
field, and for having changed nothing: a twin host that never saw the refused request must go
on exactly as the host that refused it (same observations, rewards, random draws, config and
episode log). No sockets.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pytest

from examples.cartpole import TARGET, CartPoleEnvironment
from examples.plinko import TARGET as PLINKO
from rlenv.protocol import BatchResponse, ErrorReply, Reply, Request, Response, StepsResponse, pack
from rlenv.protocol.errors import ErrorCode
from rlenv.serving._host import Host
from rlenv.serving._parts import PARTS, takes_control
from rlenv_client import LocalClient, RemoteError

# CartPole: action Box(-1, 1, (1,), float32), observation Box((5,), float32).
ACTION = [0.25]
OBSERVE_ALL: Mapping[str, Any] = {"agent": {}, "world": {}}


# --- helpers ---------------------------------------------------------------------------------


def _ask(host: Host, parts: Mapping[str, Any], request_id: int = 1) -> Reply:
    return host.answer(Request(request_id, dict(parts)))


def _all(host: Host, parts: Mapping[str, Any]) -> Reply:
    """The same parts to every instance, as a batch."""
    return _ask(host, {"batch": [dict(parts) for _ in host.instances]})


def _start(host: Host) -> None:
    """Start an episode on every instance, each with its own seed (so draws are reproducible)."""
    reply = _ask(host, {"batch": [{"reset": {"seed": 10 + i}} for i in range(len(host.instances))]})
    assert isinstance(reply, BatchResponse)
    assert all(type(each) is Response for each in reply.replies)


def _continuation(host: Host) -> list[bytes]:
    """What the host answers to a fixed sequence that reads every kind of state it keeps.

    Steps (the configured repeat_action, physics state, rewards), a reset without a seed (the
    random generator), a step with its own repeat_action, then snapshots (config, the episode's
    generator state and events). Answers are compared as the bytes they travel as.
    """
    actions = [[0.3] for _ in host.instances]
    replies = [
        _ask(host, {"steps": {"action": actions}}),
        _all(host, {"reset": {}, "observation": OBSERVE_ALL}),
        _ask(host, {"steps": {"action": [[-0.7] for _ in host.instances], "repeat_action": 3}}),
        _all(host, {"observation": OBSERVE_ALL}),
        _all(host, {"snapshot": {}}),
    ]
    return [pack(reply.to_wire()) for reply in replies]


def _twin_check(
    parts: Mapping[str, Any], *, count: int = 1, started: bool = True, target: str = TARGET
) -> tuple[Reply, bool]:
    """Answer ``parts`` on one host of two twins; (the answer, whether the twins still agree).

    The twins serve ``target``, CartPole by default (its actions: ``[x]``, x in [-1, 1]).
    """
    host, twin = Host(target, count), Host(target, count)
    for each in (host, twin):
        if started:
            _start(each)
    if started:
        before = _all(host, {"observation": OBSERVE_ALL})
        _all(twin, {"observation": OBSERVE_ALL})
    reply = _ask(host, parts, request_id=7)
    if started:
        after = _all(host, {"observation": OBSERVE_ALL})
        _all(twin, {"observation": OBSERVE_ALL})
        if reply.__class__ is ErrorReply:
            assert after == before  # the observation did not move
    if not started:
        for each in (host, twin):
            _start(each)
    return reply, _continuation(host) == _continuation(twin)


def assert_refused(
    parts: Mapping[str, Any],
    code: ErrorCode,
    fragment: str,
    *,
    count: int = 1,
    started: bool = True,
) -> ErrorReply:
    """``parts`` is refused with ``code``, a message holding ``fragment``; nothing changed."""
    reply, unchanged = _twin_check(parts, count=count, started=started)
    assert isinstance(reply, ErrorReply), reply
    assert reply.id == 7 and reply.code == code and reply.fatal is False, reply
    assert fragment in reply.message, reply.message
    assert unchanged, "a refused request changed the environment"
    return reply


# --- the twin check itself -------------------------------------------------------------------


@pytest.mark.parametrize(
    ("parts", "count"),
    [
        pytest.param({"reset": {}}, 1, id="reset"),
        pytest.param({"action": ACTION}, 1, id="action"),
        pytest.param({"action": ACTION, "repeat_action": 1}, 1, id="action-1-tick"),
        pytest.param({"config": {"environment": {"repeat_action": 2}}}, 1, id="config"),
        pytest.param({"config": {"agent": {"max_force": 11.0}}}, 1, id="config-agent"),
        pytest.param(
            {"inspect": {"set": {"path": "Agent", "property": "max_force", "value": 9.0}}},
            1,
            id="inspect-set",
        ),
        pytest.param({"batch": [None, {"action": ACTION}]}, 2, id="batch-second"),
        pytest.param({"steps": {"action": [[0.0], [0.0]], "reset": [True, False]}}, 2, id="steps"),
    ],
)
def test_the_twin_check_sees_every_accepted_change(parts: dict[str, Any], count: int) -> None:
    """Guards the refusal tests: an accepted request that changes anything is noticed."""
    reply, unchanged = _twin_check(parts, count=count)
    assert reply.__class__ is not ErrorReply, reply
    assert not unchanged


@pytest.mark.parametrize(
    "parts",
    [
        pytest.param({"observation": {"agent": {}}}, id="observation"),
        pytest.param(
            {"observation": {"agent": {}, "world": {}, "render": {"width": 8}}},
            id="observation-render",
        ),
        pytest.param({"snapshot": {}}, id="snapshot"),
        pytest.param({"inspect": {"tree": {}}}, id="inspect-tree"),
        pytest.param(
            {"inspect": {"get": {"path": "Agent", "property": "max_force"}}}, id="inspect-get"
        ),
        pytest.param({"action": None, "observation": {"agent": {}}}, id="nil-action"),
    ],
)
def test_requests_that_only_read_change_nothing(parts: dict[str, Any]) -> None:
    reply, unchanged = _twin_check(parts)
    assert isinstance(reply, Response) and reply.id == 7
    assert unchanged


_EDIT = {"level": 3, "seed": 5, "n_edits": 4}


@pytest.mark.parametrize(
    ("parts", "started"),
    [
        pytest.param({"edit_level": _EDIT}, True, id="plain"),
        pytest.param({"edit_level": _EDIT}, False, id="plain-no-episode"),
        pytest.param({"edit_level": _EDIT, "observation": {"agent": {}}}, True, id="observed"),
        pytest.param({"batch": [None, {"edit_level": _EDIT}]}, True, id="batch"),
        pytest.param({"batch": [None, {"edit_level": _EDIT}]}, False, id="batch-no-episode"),
    ],
)
def test_an_edit_of_a_level_changes_nothing(parts: dict[str, Any], started: bool) -> None:
    reply, unchanged = _twin_check(parts, count=2, started=started, target=PLINKO)
    answer = reply.replies[1] if isinstance(reply, BatchResponse) else reply
    assert isinstance(answer, Response) and answer.frames == 0 and answer.reward == 0.0
    assert answer.info["level"]["root"]["children"][0]["name"] == "Pegs"
    assert unchanged


def test_an_environment_without_edits_refuses_them_changing_nothing() -> None:
    assert_refused(
        {"edit_level": {"level": 0, "seed": 0}},
        ErrorCode.BAD_REQUEST,
        "edit_level: CartPoleWorld has no _edit_level",
        count=2,
    )


# --- empty requests --------------------------------------------------------------------------


def test_an_empty_request_is_answered_with_an_empty_response() -> None:
    reply, unchanged = _twin_check({})
    assert reply == Response(7)
    assert reply.observation is None and reply.frames == 0 and reply.info == {}
    assert unchanged


def test_a_request_with_only_a_token_is_answered_with_an_empty_response() -> None:
    host = Host(TARGET)
    assert host.answer(Request(3, {}, token="s3cret")) == Response(3)


def test_an_empty_request_before_any_reset_is_answered_too() -> None:
    reply, unchanged = _twin_check({}, started=False)
    assert reply == Response(7) and unchanged


# --- unknown keys ----------------------------------------------------------------------------


def _expected_keys(message: str) -> set[str]:
    return set(message.split("expected any of ", 1)[1].split(", "))


@pytest.mark.parametrize(
    ("parts", "fragment"),
    [
        pytest.param({"bogus": 1}, "unknown request key 'bogus'", id="bogus"),
        pytest.param({"step": {}}, "unknown request key 'step'", id="step"),
        pytest.param({"reset": {}, "act": 2}, "unknown request key 'act'", id="with-known"),
        pytest.param({"id": 3}, "unknown request key 'id'", id="id-in-parts"),
        pytest.param({b"reset": {}}, "unknown request key \"b'reset'\"", id="bytes-key"),
    ],
)
def test_unknown_keys_are_refused_listing_the_expected_keys(
    parts: dict[Any, Any], fragment: str
) -> None:
    reply = assert_refused(parts, ErrorCode.BAD_REQUEST, fragment)
    assert _expected_keys(reply.message) == set(PARTS) | {"token", "shared_memory"}


def test_unknown_key_in_a_batch_slot_lists_the_keys_of_one_instance() -> None:
    reply = assert_refused(
        {"batch": [None, {"bogus": 1}]}, ErrorCode.BAD_REQUEST, "batch[1]", count=2
    )
    assert "'bogus'" in reply.message
    assert _expected_keys(reply.message) == set(PARTS) - {"batch", "steps"}


@pytest.mark.parametrize(
    ("parts", "fragment"),
    [
        pytest.param({"reset": {"bogus": 1}}, "unknown key 'bogus' in reset", id="reset"),
        pytest.param(
            {"observation": {"agent": {}, "pixels": {}}},
            "unknown key 'pixels' in observation",
            id="observation",
        ),
        pytest.param(
            {"observation": {"render": {"width": 8, "depth": 3}}},
            "unknown key 'depth' in observation.render",
            id="render",
        ),
        pytest.param({"config": {"physics": {}}}, "unknown key 'physics' in config", id="config"),
    ],
)
def test_unknown_keys_inside_a_part_are_refused(parts: dict[str, Any], fragment: str) -> None:
    assert_refused(parts, ErrorCode.BAD_REQUEST, fragment)


# --- parts that must be maps -----------------------------------------------------------------


@pytest.mark.parametrize("name", ["config", "reset", "observation", "snapshot", "restore"])
@pytest.mark.parametrize("value", [[1], "all", None, 3, True], ids=repr)
def test_parts_that_must_be_maps(name: str, value: Any) -> None:
    assert_refused({name: value}, ErrorCode.BAD_REQUEST, f"request '{name}' must be a map")


@pytest.mark.parametrize(
    ("parts", "fragment"),
    [
        pytest.param(
            {"config": {"environment": [1]}},
            "config.environment must be a map",
            id="config-environment",
        ),
        pytest.param({"reset": {"options": [1]}}, "reset.options must be a map", id="options"),
        pytest.param(
            {"observation": {"render": 64}}, "observation.render must be a map", id="render"
        ),
        pytest.param({"snapshot": {"x": 1}}, "snapshot takes an empty map", id="snapshot"),
    ],
)
def test_nested_maps_are_checked(parts: dict[str, Any], fragment: str) -> None:
    assert_refused(parts, ErrorCode.BAD_REQUEST, fragment)


@pytest.mark.parametrize("seed", [-1, 1.5, "7", True, [1]], ids=repr)
def test_reset_seed_must_be_a_non_negative_integer(seed: Any) -> None:
    assert_refused(
        {"reset": {"seed": seed}}, ErrorCode.BAD_REQUEST, "reset.seed must be an integer >= 0"
    )


@pytest.mark.parametrize("size", [0, -1, 4097, 8.0, "8", True], ids=repr)
def test_render_size_is_checked(size: Any) -> None:
    assert_refused(
        {"observation": {"render": {"width": size}}},
        ErrorCode.BAD_REQUEST,
        "observation.render.width must be an integer in [1, 4096]",
    )


@pytest.mark.parametrize("value", [0, 1.5, "x", True], ids=repr)
def test_config_values_are_checked(value: Any) -> None:
    assert_refused(
        {"config": {"environment": {"repeat_action": value}}},
        ErrorCode.INVALID_CONFIG,
        "repeat_action must be an integer >= 1",
    )


# --- repeat_action ---------------------------------------------------------------------------


@pytest.mark.parametrize("repeat", [0, -3, 2.0, True, "4", None], ids=repr)
def test_repeat_action_must_be_an_integer_of_at_least_one(repeat: Any) -> None:
    assert_refused(
        {"action": ACTION, "repeat_action": repeat},
        ErrorCode.BAD_REQUEST,
        f"'repeat_action' must be an integer >= 1, got {repeat!r}",
    )


_BEYOND = 10_001  # one tick over the hello's limits.max_repeat_action


@pytest.mark.parametrize(
    ("parts", "count", "code", "fragment"),
    [
        pytest.param(
            {"action": ACTION, "repeat_action": _BEYOND},
            1,
            ErrorCode.BAD_REQUEST,
            "'repeat_action' must be at most 10000 ticks (the hello's "
            "limits.max_repeat_action), got 10001",
            id="request",
        ),
        pytest.param(
            {"action": ACTION, "repeat_action": 2**40},
            1,
            ErrorCode.BAD_REQUEST,
            "got 1099511627776",
            id="request-huge",
        ),
        pytest.param(
            {"batch": [None, {"action": ACTION, "repeat_action": _BEYOND}]},
            2,
            ErrorCode.BAD_REQUEST,
            "'repeat_action' must be at most 10000",
            id="batch",
        ),
        pytest.param(
            {"steps": {"action": [[0.1], [0.1]], "repeat_action": _BEYOND}},
            2,
            ErrorCode.BAD_REQUEST,
            "steps.repeat_action must be at most 10000",
            id="steps",
        ),
        pytest.param(
            {"config": {"environment": {"repeat_action": _BEYOND}}},
            1,
            ErrorCode.INVALID_CONFIG,
            "repeat_action must be at most 10000",
            id="config",
        ),
    ],
)
def test_repeat_action_is_bounded_by_the_hello_s_limit(
    parts: dict[str, Any],
    count: int,
    code: ErrorCode,
    fragment: str,
) -> None:
    """Before, any number went: one request kept the server's loop for as long as it asked."""
    reply, unchanged = _twin_check(parts, count=count)
    answer = reply.replies[1] if isinstance(reply, BatchResponse) else reply
    assert isinstance(answer, ErrorReply) and answer.code == code, answer
    assert fragment in answer.message, answer.message
    assert unchanged
    host = Host(TARGET)
    assert host.hello.limits["max_repeat_action"] == 10_000
    assert isinstance(
        _ask(host, {"reset": {}, "action": ACTION, "repeat_action": 10_000}), Response
    )  # the limit itself is served
    host.close()


def test_repeat_action_is_bounded_with_several_agents_too() -> None:
    from examples.pair import TARGET as PAIR

    with LocalClient(PAIR) as client:
        client.reset(seed=0)
        action = {name: np.zeros(2, np.float32) for name in ("Red", "Blue")}
        with pytest.raises(RemoteError) as refused:
            client.step(action, repeat_action=_BEYOND)
        assert refused.value.code == ErrorCode.BAD_REQUEST
        assert "must be at most 10000 ticks" in refused.value.message
        assert client.step(action, repeat_action=3)[4]["frames"] == 3  # the episode goes on


def test_a_restore_whose_action_asks_for_more_ticks_than_the_limit_is_refused() -> None:
    host = Host(TARGET)
    _ask(host, {"reset": {"seed": 1}})
    _ask(host, {"action": ACTION})
    snapshot = _ask(host, {"snapshot": {}}).info["snapshot"]  # type: ignore[union-attr]
    snapshot["events"][-1][2] = _BEYOND
    refused = _ask(host, {"restore": snapshot})
    assert isinstance(refused, ErrorReply) and refused.code == ErrorCode.BAD_REQUEST
    assert "restore: events[0]: the action's frames must be at most 10000" in refused.message
    host.close()


@pytest.mark.parametrize(
    "parts",
    [
        pytest.param({"repeat_action": 2}, id="alone"),
        pytest.param({"action": None, "repeat_action": 2}, id="nil-action"),
        pytest.param({"repeat_action": 2, "observation": {"agent": {}}}, id="with-observation"),
    ],
)
def test_repeat_action_needs_an_action(parts: dict[str, Any]) -> None:
    assert_refused(parts, ErrorCode.BAD_REQUEST, "'repeat_action' given without an 'action'")


def test_repeat_action_sets_the_ticks_of_this_action_only() -> None:
    host = Host(TARGET)
    _start(host)
    assert _ask(host, {"action": ACTION, "repeat_action": 2}).frames == 2  # type: ignore[union-attr]
    assert _ask(host, {"action": ACTION}).frames == 4  # type: ignore[union-attr]


# --- actions and episodes --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("action", "fragment"),
    [
        pytest.param([5.0], "action[0] is 5.0", id="out-of-bounds"),
        pytest.param([0.0, 0.0], "action has shape (2,)", id="wrong-shape"),
        pytest.param("left", "action", id="str"),
    ],
)
def test_invalid_actions_are_refused(action: Any, fragment: str) -> None:
    assert_refused({"action": action}, ErrorCode.INVALID_ACTION, fragment)


@pytest.mark.parametrize(
    "parts",
    [
        pytest.param({"action": ACTION}, id="action"),
        pytest.param({"observation": {"agent": {}}}, id="observation"),
        pytest.param({"snapshot": {}}, id="snapshot"),
    ],
)
def test_before_any_reset_an_episode_is_required(parts: dict[str, Any]) -> None:
    assert_refused(parts, ErrorCode.RESET_REQUIRED, "no episode has started", started=False)


def test_every_part_is_checked_before_any_applies() -> None:
    """A valid reset or config in a request whose action is refused is not applied either."""
    assert_refused(
        {"reset": {"seed": 99}, "action": [9.0]}, ErrorCode.INVALID_ACTION, "action[0] is 9.0"
    )
    assert_refused(
        {
            "config": {"environment": {"repeat_action": 2}},
            "reset": {"seed": 99},
            "observation": {"bogus": {}},
        },
        ErrorCode.BAD_REQUEST,
        "'bogus'",
    )
    assert_refused(
        {"reset": {}, "observation": {"render": {"width": 0}}},
        ErrorCode.BAD_REQUEST,
        "observation.render.width",
    )


def test_parts_apply_in_the_table_order_whatever_the_order_of_the_keys() -> None:
    """config, then reset, then action, then observation, as :data:`PARTS` lists them."""
    ordered, shuffled = Host(TARGET), Host(TARGET)
    parts = {
        "config": {"environment": {"repeat_action": 3}},
        "reset": {"seed": 3},
        "action": ACTION,
        "observation": {"agent": {}},
    }
    first = _ask(ordered, parts)
    second = _ask(shuffled, dict(reversed(list(parts.items()))))
    assert isinstance(first, Response) and first.frames == 3
    assert pack(first.to_wire()) == pack(second.to_wire())
    assert (
        list(PARTS).index("config")
        < list(PARTS).index("reset")
        < list(PARTS).index("action")
        < list(PARTS).index("observation")
    )


# --- parts that go alone ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("parts", "fragment"),
    [
        pytest.param({"snapshot": {}, "reset": {}}, "snapshot goes alone", id="snapshot-reset"),
        pytest.param(
            {"snapshot": {}, "action": ACTION}, "snapshot goes alone", id="snapshot-action"
        ),
        pytest.param({"restore": {}, "config": {}}, "restore goes alone", id="restore-config"),
        pytest.param(
            {"inspect": {"tree": {}}, "reset": {}}, "inspect goes alone", id="inspect-reset"
        ),
        pytest.param(
            {"inspect": {"tree": {}}, "repeat_action": 2}, "inspect goes alone", id="inspect-repeat"
        ),
        pytest.param(
            {"restore": {}, "snapshot": {}}, "restore or snapshot, not both", id="restore-snapshot"
        ),
        pytest.param({"inspect": {"tree": {}}, "snapshot": {}}, "not both", id="inspect-snapshot"),
        pytest.param(
            {"steps": {"action": [[0.0]]}, "reset": {}},
            "a 'steps' request carries nothing else but its id",
            id="steps-reset",
        ),
        pytest.param(
            {"batch": [{"reset": {}}], "observation": {}},
            "a 'batch' request carries nothing else but its id",
            id="batch-observation",
        ),
        pytest.param(
            {"batch": [{"reset": {}}], "steps": {"action": [[0.0]]}},
            "carries nothing else but its id",
            id="batch-steps",
        ),
    ],
)
def test_parts_that_go_alone(parts: dict[str, Any], fragment: str) -> None:
    assert_refused(parts, ErrorCode.BAD_REQUEST, fragment)


@pytest.mark.parametrize(
    "alone", [{"snapshot": {}}, {"inspect": {"tree": {}}}], ids=["snapshot", "inspect"]
)
def test_parts_that_go_alone_may_bring_an_observation(alone: dict[str, Any]) -> None:
    host = Host(TARGET)
    _start(host)
    reply = _ask(host, {**alone, "observation": {"agent": {}}})
    assert isinstance(reply, Response) and set(reply.observation or {}) == {"agent"}


# --- steps -----------------------------------------------------------------------------------

_STEP = [[0.1], [-0.1]]  # one action per instance, for two


@pytest.mark.parametrize(
    ("steps", "code", "fragment"),
    [
        pytest.param([1, 2], ErrorCode.BAD_REQUEST, "'steps' must be a map", id="list"),
        pytest.param("go", ErrorCode.BAD_REQUEST, "'steps' must be a map", id="str"),
        pytest.param(None, ErrorCode.BAD_REQUEST, "'steps' must be a map", id="nil"),
        pytest.param(
            {"reset": [True, True]},
            ErrorCode.BAD_REQUEST,
            "'steps' needs an 'action'",
            id="no-action",
        ),
        pytest.param(
            {"action": None}, ErrorCode.BAD_REQUEST, "'steps' needs an 'action'", id="nil-action"
        ),
        pytest.param(
            {"action": _STEP, "jump": 1},
            ErrorCode.BAD_REQUEST,
            "unknown key 'jump' in steps",
            id="unknown-key",
        ),
        pytest.param(
            {"action": _STEP, "reset": [1, 0]},
            ErrorCode.BAD_REQUEST,
            "steps.reset must be a list of booleans",
            id="reset-ints",
        ),
        pytest.param(
            {"action": _STEP, "reset": "yes"},
            ErrorCode.BAD_REQUEST,
            "steps.reset must be a list of booleans",
            id="reset-str",
        ),
        pytest.param(
            {"action": _STEP, "reset": b"\x00\x02"},
            ErrorCode.BAD_REQUEST,
            "steps.reset must be a list of booleans",
            id="reset-bytes-2",
        ),
        pytest.param(
            {"action": _STEP, "reset": np.zeros((2, 1), np.bool_)},
            ErrorCode.BAD_REQUEST,
            "steps.reset must be a list of booleans",
            id="reset-2d",
        ),
        pytest.param(
            {"action": _STEP, "reset": [True]},
            ErrorCode.BAD_REQUEST,
            "steps.reset has 1 flags for 2 instances",
            id="reset-short",
        ),
        pytest.param(
            {"action": _STEP, "reset": b"\x01"},
            ErrorCode.BAD_REQUEST,
            "steps.reset has 1 flags for 2 instances",
            id="reset-bytes-short",
        ),
        pytest.param(
            {"action": _STEP, "reset": np.zeros(3, np.uint8)},
            ErrorCode.BAD_REQUEST,
            "steps.reset has 3 flags for 2 instances",
            id="reset-array-long",
        ),
        pytest.param(
            {"action": _STEP, "reset": np.array([0, 2], np.uint8)},
            ErrorCode.BAD_REQUEST,
            "steps.reset must be a list of booleans",
            id="reset-array-2",
        ),
        pytest.param(
            {"action": _STEP, "reset": np.zeros(2, np.int64)},
            ErrorCode.BAD_REQUEST,
            "steps.reset must be a list of booleans",
            id="reset-array-int64",
        ),
        pytest.param(
            {"action": _STEP, "reset": bytearray(2)},
            ErrorCode.BAD_REQUEST,
            "steps.reset must be a list of booleans",
            id="reset-bytearray",
        ),
        pytest.param(
            {"action": _STEP, "repeat_action": 0},
            ErrorCode.BAD_REQUEST,
            "steps.repeat_action must be an integer >= 1",
            id="repeat-zero",
        ),
        pytest.param(
            {"action": _STEP, "repeat_action": 1.0},
            ErrorCode.BAD_REQUEST,
            "steps.repeat_action must be an integer >= 1",
            id="repeat-float",
        ),
        pytest.param(
            {"action": [[0.1]]}, ErrorCode.INVALID_ACTION, "steps.action", id="one-action-for-two"
        ),
        pytest.param(
            {"action": [[0.1], [3.0]]},
            ErrorCode.INVALID_ACTION,
            "steps.action[1, 0]",
            id="out-of-bounds",
        ),
    ],
)
def test_malformed_steps_are_refused(steps: Any, code: ErrorCode, fragment: str) -> None:
    assert_refused({"steps": steps}, code, fragment, count=2)


def test_steps_before_a_reset_are_refused_naming_the_instance() -> None:
    assert_refused(
        {"steps": {"action": _STEP}},
        ErrorCode.RESET_REQUIRED,
        "steps: instance 0",
        count=2,
        started=False,
    )


def test_steps_after_an_episode_ended_are_refused_naming_the_instance() -> None:
    host = Host(TARGET, 2)
    _start(host)
    ended = _ask(
        host, {"batch": [None, {"config": {"agent": {"angle_limit": 0.0}}, "action": [0.1]}]}
    )
    assert isinstance(ended, BatchResponse) and ended.replies[1].terminated
    reply = _ask(host, {"steps": {"action": _STEP}})
    assert isinstance(reply, ErrorReply) and reply.code == ErrorCode.RESET_REQUIRED
    assert reply.message == "steps: instance 1: the episode has ended; reset first"
    reply = _ask(host, {"steps": {"action": _STEP, "reset": b"\x00\x01"}})
    assert isinstance(reply, StepsResponse) and reply.errors is None
    assert reply.frames.tolist() == [4, 0]


@pytest.mark.parametrize(
    "mask",
    [
        pytest.param([True, False], id="list"),
        pytest.param(b"\x01\x00", id="bytes"),
        pytest.param(np.array([True, False]), id="bool-array"),
        pytest.param(np.array([1, 0], np.uint8), id="uint8-array"),
    ],
)
def test_steps_reset_mask_forms(mask: Any) -> None:
    host = Host(TARGET, 2)
    _start(host)
    reply = _ask(host, {"steps": {"action": _STEP, "reset": mask}})
    assert isinstance(reply, StepsResponse) and reply.errors is None
    assert reply.frames.tolist() == [0, 4]  # instance 0 reset, instance 1 stepped
    assert len(reply.observation) == 2 * 5 * 4  # two packed float32 observations of five


def test_steps_with_every_instance_resetting_need_no_episode() -> None:
    host = Host(TARGET, 2)
    reply = _ask(host, {"steps": {"action": _STEP, "reset": [True, True]}})
    assert isinstance(reply, StepsResponse) and reply.frames.tolist() == [0, 0]


# --- batch -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("batch", "fragment"),
    [
        pytest.param("all", "'batch' must be a non-empty list of requests or nil", id="str"),
        pytest.param({"0": {}}, "'batch' must be a non-empty list", id="map"),
        pytest.param(None, "'batch' must be a non-empty list", id="nil"),
        pytest.param([], "'batch' must be a non-empty list", id="empty"),
        pytest.param([None, None, None], "a batch of 3 requests for 2 instances", id="too-long"),
        pytest.param([None, 3], "batch[1] must be a map or nil", id="slot-int"),
        pytest.param([[{}], None], "batch[0] must be a map or nil", id="slot-list"),
        pytest.param(
            [{"steps": {"action": _STEP}}, None],
            "unknown request key batch[0].",
            id="steps-in-slot",
        ),
        pytest.param(
            [None, {"batch": [None]}], "unknown request key batch[1].", id="batch-in-slot"
        ),
        pytest.param([None, {"token": "t"}], "unknown request key batch[1].", id="token-in-slot"),
        pytest.param(
            [{"snapshot": {}, "reset": {}}, None], "snapshot goes alone", id="slot-not-alone"
        ),
        pytest.param([{"reset": {}}, {"jump": 1}], "batch[1]", id="good-then-bad"),
    ],
)
def test_malformed_batches_are_refused_whole(batch: Any, fragment: str) -> None:
    assert_refused({"batch": batch}, ErrorCode.BAD_REQUEST, fragment, count=2)


def test_a_slot_refused_by_its_checks_fails_alone() -> None:
    """The shape of every slot is the batch's business; a slot's values are the slot's."""
    host = Host(TARGET, 2)
    _start(host)
    before = _ask(host, {"batch": [{"observation": {"agent": {}}}, None]})
    reply = _ask(host, {"batch": [{"action": [9.0]}, {"action": ACTION}]}, request_id=5)
    assert isinstance(reply, BatchResponse) and reply.id == 5
    refused, served = reply.replies
    assert isinstance(refused, ErrorReply) and refused.code == ErrorCode.INVALID_ACTION
    assert refused.id == 5 and "action[0] is 9.0" in refused.message
    assert isinstance(served, Response) and served.frames == 4
    assert _ask(host, {"batch": [{"observation": {"agent": {}}}, None]}) == before

    reply = _ask(host, {"batch": [{"config": [1]}, None]})
    assert isinstance(reply, BatchResponse)
    (error, nothing) = reply.replies
    assert isinstance(error, ErrorReply) and error.code == ErrorCode.BAD_REQUEST
    assert "request 'config' must be a map" in error.message and nothing is None


def test_a_batch_shorter_than_the_instances_leaves_the_rest_alone() -> None:
    host = Host(TARGET, 3)
    _start(host)
    reply = _ask(host, {"batch": [None, {"action": ACTION}]})
    assert isinstance(reply, BatchResponse)
    assert reply.replies[0] is None and isinstance(reply.replies[1], Response)


# --- which parts take control ----------------------------------------------------------------

_SET = {"set": {"path": "Agent", "property": "max_force", "value": 9.0}}
_GET = {"get": {"path": "Agent", "property": "max_force"}}


@pytest.mark.parametrize(
    ("parts", "controls"),
    [
        pytest.param({"config": {}}, True, id="config"),
        pytest.param({"config": [1]}, True, id="config-malformed"),
        pytest.param({"reset": {}}, True, id="reset"),
        pytest.param({"reset": {}, "observation": {"agent": {}}}, True, id="reset-observation"),
        pytest.param({"action": ACTION}, True, id="action"),
        pytest.param({"action": 0}, True, id="action-zero"),
        pytest.param({"action": ACTION, "repeat_action": 2}, True, id="action-repeat"),
        pytest.param({"restore": {}}, True, id="restore"),
        pytest.param({"steps": {"action": _STEP}}, True, id="steps"),
        pytest.param({"batch": [None, {"reset": {}}]}, True, id="batch-reset"),
        pytest.param({"batch": [{"observation": {}}, {"action": ACTION}]}, True, id="batch-action"),
        pytest.param({}, False, id="empty"),
        pytest.param({"observation": {"agent": {}, "world": {}}}, False, id="observation"),
        pytest.param({"snapshot": {}}, False, id="snapshot"),
        pytest.param({"inspect": {"tree": {}}}, False, id="inspect-tree"),
        pytest.param({"inspect": _GET}, False, id="inspect-get"),
        pytest.param({"inspect": _SET}, False, id="inspect-set"),  # an inspector's edit (2.2)
        pytest.param(
            {"inspect": {"configure": {"agent": {"max_force": 9.0}}}}, False, id="inspect-configure"
        ),
        pytest.param({"batch": [{"inspect": _SET}]}, False, id="batch-inspect-set"),
        pytest.param({"repeat_action": 2}, False, id="repeat-action-alone"),
        pytest.param({"action": None}, False, id="nil-action"),
        pytest.param(
            {"action": None, "observation": {"agent": {}}}, False, id="nil-action-observation"
        ),
        pytest.param({"batch": [None, {"observation": {}}]}, False, id="batch-observation"),
        pytest.param({"batch": [None, None]}, False, id="batch-nothing"),
        pytest.param({"batch": [{"action": None}, {"inspect": _GET}]}, False, id="batch-read-only"),
        pytest.param({"bogus": 1}, False, id="unknown"),
    ],
)
def test_takes_control(parts: dict[str, Any], controls: bool) -> None:
    assert takes_control(parts) is controls


# --- through the client ----------------------------------------------------------------------


def test_a_refusal_reaches_a_local_client_as_a_remote_error() -> None:
    with LocalClient(TARGET) as client:
        observation, _ = client.reset(seed=1)
        with pytest.raises(RemoteError) as info:
            client.step(np.array(ACTION, np.float32), repeat_action=0)
        assert info.value.code == ErrorCode.BAD_REQUEST
        assert "'repeat_action' must be an integer >= 1" in info.value.message
        client.send_request(Request(0, {"bogus": 1}))
        reply = client.receive_reply()
        assert isinstance(reply, ErrorReply) and "'bogus'" in reply.message
        # The episode goes on where it was.
        assert np.array_equal(client.observe()["agent"], observation)
        _, _, terminated, truncated, info_ = client.step(np.array(ACTION, np.float32))
        assert info_["frames"] == 4 and not (terminated or truncated)


# --- arrays where maps belong ---------------------------------------------------------------


@pytest.mark.parametrize(
    "parts",
    [
        pytest.param({"observation": np.zeros(3)}, id="array"),
        pytest.param({"observation": {"agent": np.zeros(3)}}, id="agent-array"),
        pytest.param({"batch": [{"observation": np.zeros(3)}]}, id="in-a-batch"),
    ],
)
def test_an_array_where_an_observation_map_belongs_is_refused(parts: dict[str, Any]) -> None:
    """Arrays arrive from the wire (ext type 1); the host must answer, not raise."""
    host = Host(TARGET)
    _start(host)
    reply = _ask(host, parts)
    if isinstance(reply, BatchResponse):  # a batch answers each slot on its own
        (reply,) = reply.replies
    assert isinstance(reply, ErrorReply) and reply.code == ErrorCode.BAD_REQUEST
    assert "must be a map" in reply.message


# --- user code that raises while a request is checked --------------------------------------


class _Touchy(CartPoleEnvironment):
    """An environment whose own configuration check raises something unexpected."""

    configurable = ("repeat_action", "mood")

    def __init__(self) -> None:
        super().__init__()
        self.mood = "calm"

    def check_config(self, config: Mapping[str, Any]) -> None:
        if config.get("mood") == "angry":
            raise LookupError("no such mood here")
        super().check_config(config)


def test_user_code_raising_in_a_check_is_an_environment_error_and_changes_nothing() -> None:
    host, twin = Host(_Touchy), Host(_Touchy)
    for each in (host, twin):
        _start(each)
    reply = _ask(host, {"config": {"environment": {"mood": "angry"}}, "action": ACTION})
    assert isinstance(reply, ErrorReply) and reply.code == ErrorCode.ENVIRONMENT_ERROR
    assert "no such mood here" in reply.message and "nothing was applied" in reply.message
    assert "LookupError" in reply.message  # the traceback
    assert _continuation(host) == _continuation(twin)
