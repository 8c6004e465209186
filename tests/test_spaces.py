"""Tests of rlenv.protocol.spaces: space specs, checking values, and the packed form of values.

Most tests run over every space of the catalog (``tests/spaces_catalog.py``). The compiled
checker is held to the careful :func:`check`: the same verdicts, the same messages, equal values.
"""

from __future__ import annotations

import math
import re
import types
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array
from spaces_catalog import TESTING_SPACES

from rlenv.protocol import pack, unpack
from rlenv.protocol.spaces import (
    SpaceMismatch,
    check,
    codec_for,
    compile_check,
    find_non_finite,
    space_from_spec,
    space_to_spec,
)

SAMPLES_PER_SPACE = 5


def _space_id(space: spaces.Space) -> str:
    return re.sub(r"\s+", " ", repr(space))[:60]


ALL_SPACES = [pytest.param(s, id=_space_id(s)) for s in TESTING_SPACES]


def _samples(space: spaces.Space) -> list:
    space.seed(0)
    return [space.sample() for _ in range(SAMPLES_PER_SPACE)]


# --- the catalog itself ----------------------------------------------------------------------


def test_catalog_covers_every_supported_space_type() -> None:
    types = {type(s) for s in TESTING_SPACES}
    assert types == {
        spaces.Box,
        spaces.Discrete,
        spaces.MultiDiscrete,
        spaces.MultiBinary,
        spaces.Tuple,
        spaces.Dict,
    }
    boxes = [s for s in TESTING_SPACES if isinstance(s, spaces.Box)]
    assert any(s.shape == () for s in boxes)
    assert any(s.dtype == np.uint8 and s.shape == (84, 84, 3) for s in boxes)
    assert any(np.isinf(s.low).any() and np.isinf(s.high).any() for s in boxes)
    assert any(s.dtype.kind == "i" for s in boxes)
    assert any(isinstance(s, spaces.Discrete) and s.start != 0 for s in TESTING_SPACES)
    assert any(isinstance(s, spaces.MultiDiscrete) and (s.start != 0).any() for s in TESTING_SPACES)
    assert {len(s.shape) for s in TESTING_SPACES if isinstance(s, spaces.MultiBinary)} == {1, 2}
    assert any(
        isinstance(s, spaces.Tuple) and any(isinstance(i, spaces.Dict) for i in s.spaces)
        for s in TESTING_SPACES
    )


# --- specs -----------------------------------------------------------------------------------


@pytest.mark.parametrize("space", ALL_SPACES)
def test_spec_round_trip(space: spaces.Space) -> None:
    rebuilt = space_from_spec(space_to_spec(space))
    assert type(rebuilt) is type(space)
    assert rebuilt == space


@pytest.mark.parametrize("space", ALL_SPACES)
def test_spec_round_trip_through_msgpack(space: spaces.Space) -> None:
    rebuilt = space_from_spec(unpack(pack(space_to_spec(space))))
    assert type(rebuilt) is type(space)
    assert rebuilt == space


@pytest.mark.parametrize("space", ALL_SPACES)
def test_spec_round_trip_keeps_dtype_and_shape(space: spaces.Space) -> None:
    rebuilt = space_from_spec(unpack(pack(space_to_spec(space))))
    assert rebuilt.shape == space.shape
    assert rebuilt.dtype == space.dtype
    # A rebuilt space produces the very same samples as the original under the same seed.
    space.seed(3)
    rebuilt.seed(3)
    for _ in range(3):
        a, b = space.sample(), rebuilt.sample()
        assert pack(a) == pack(b)


def test_box_spec_keeps_infinite_bounds_and_dtype() -> None:
    box = spaces.Box(low=np.array([-np.inf, 0.0]), high=np.array([np.inf, 1.0]), dtype=np.float64)
    rebuilt = space_from_spec(unpack(pack(space_to_spec(box))))
    assert rebuilt.dtype == np.float64
    assert rebuilt.low[0] == -np.inf and rebuilt.high[0] == np.inf
    assert rebuilt.low[1] == 0.0 and rebuilt.high[1] == 1.0


def test_spec_is_plain_data() -> None:
    spec = space_to_spec(spaces.Dict({"a": spaces.Discrete(3, start=2)}))
    assert spec == {
        "type": "Dict",
        "spaces": {"a": {"type": "Discrete", "n": 3, "start": 2, "dtype": "<i8"}},
    }
    assert type(spec["spaces"]["a"]["n"]) is int


def test_different_spaces_give_different_specs() -> None:
    a = space_from_spec(space_to_spec(spaces.Discrete(3)))
    b = space_from_spec(space_to_spec(spaces.Discrete(3, start=1)))
    assert a != b
    assert space_from_spec(space_to_spec(spaces.Discrete(3, dtype=np.int32))).dtype == np.int32
    c = space_from_spec(space_to_spec(spaces.Box(0.0, 1.0, (2,), np.float32)))
    d = space_from_spec(space_to_spec(spaces.Box(0.0, 1.0, (2,), np.float64)))
    assert c != d


@pytest.mark.parametrize(
    "space",
    [
        spaces.Text(5),
        spaces.Sequence(spaces.Discrete(2)),
        spaces.Graph(node_space=spaces.Discrete(2), edge_space=None),
        spaces.Tuple((spaces.Discrete(2), spaces.Text(3))),
        spaces.Dict({"ok": spaces.Discrete(2), "text": spaces.Text(3)}),
    ],
    ids=["Text", "Sequence", "Graph", "Text-in-Tuple", "Text-in-Dict"],
)
def test_unsupported_space_raises_type_error(space: spaces.Space) -> None:
    with pytest.raises(TypeError, match="not supported on the wire"):
        space_to_spec(space)


def test_check_against_unsupported_space_is_a_mismatch() -> None:
    with pytest.raises(SpaceMismatch, match=r"^action: Text spaces are not supported"):
        check(spaces.Text(5), "hello")


_BOX = {"type": "Box", "dtype": "<f4", "low": np.zeros(2), "high": np.ones(2)}


@pytest.mark.parametrize(
    "spec",
    [
        pytest.param([1, 2], id="not-a-map"),
        pytest.param("Box", id="a-string"),
        pytest.param(None, id="None"),
        pytest.param({}, id="no-type"),
        pytest.param({"type": "Text", "max_length": 3}, id="unknown-type"),
        pytest.param({"type": "box"}, id="type-wrong-case"),
        pytest.param({k: v for k, v in _BOX.items() if k != "dtype"}, id="Box-no-dtype"),
        pytest.param({k: v for k, v in _BOX.items() if k != "low"}, id="Box-no-low"),
        pytest.param({**_BOX, "dtype": "not-a-dtype"}, id="Box-bad-dtype"),
        pytest.param({**_BOX, "dtype": "|O"}, id="Box-object-dtype"),
        pytest.param({**_BOX, "high": np.ones(3)}, id="Box-shape-mismatch"),
        pytest.param({**_BOX, "low": [0.0, 0.0], "high": [1.0, 1.0]}, id="Box-list-bounds"),
        pytest.param({"type": "Discrete", "n": 3}, id="Discrete-no-start"),
        pytest.param({"type": "Discrete", "n": 0, "start": 0}, id="Discrete-n-0"),
        pytest.param({"type": "Discrete", "n": 2.5, "start": 0}, id="Discrete-n-float"),
        pytest.param({"type": "Discrete", "n": "3", "start": 0}, id="Discrete-n-str"),
        pytest.param(
            {"type": "MultiDiscrete", "dtype": "<i8", "nvec": [0, 2], "start": [0, 0]},
            id="MultiDiscrete-nvec-0",
        ),
        pytest.param({"type": "MultiDiscrete", "nvec": [2, 2]}, id="MultiDiscrete-no-dtype"),
        pytest.param({"type": "MultiBinary", "shape": [0]}, id="MultiBinary-0"),
        pytest.param({"type": "MultiBinary", "shape": [-2, 3]}, id="MultiBinary-negative"),
        pytest.param({"type": "MultiBinary"}, id="MultiBinary-no-shape"),
        pytest.param({"type": "Tuple", "spaces": 5}, id="Tuple-spaces-int"),
        pytest.param({"type": "Tuple"}, id="Tuple-no-spaces"),
        pytest.param({"type": "Tuple", "spaces": [{"type": "Nope"}]}, id="Tuple-bad-child"),
        pytest.param({"type": "Dict", "spaces": {"a": {"type": "Nope"}}}, id="Dict-bad-child"),
        pytest.param({"type": "Dict", "spaces": {"a": [1]}}, id="Dict-child-not-map"),
        pytest.param(
            {"type": "Tuple", "spaces": [{"type": "Dict", "spaces": {"x": {"type": "Box"}}}]},
            id="nested-bad-Box",
        ),
    ],
)
def test_invalid_spec_raises_value_error(spec: object) -> None:
    with pytest.raises(ValueError, match=r"space spec"):
        space_from_spec(spec)  # type: ignore[arg-type]


@pytest.mark.parametrize("inner", [[], [1, 2], 5, "abc"], ids=["empty-list", "list", "int", "str"])
def test_dict_spec_with_non_map_spaces_raises_value_error(inner: object) -> None:
    with pytest.raises(ValueError):
        space_from_spec({"type": "Dict", "spaces": inner})


@pytest.mark.parametrize("kind", [["Box"], {"a": 1}], ids=["list", "map"])
def test_spec_with_unhashable_type_raises_value_error(kind: object) -> None:
    with pytest.raises(ValueError):
        space_from_spec({"type": kind})


# --- check: accepting ------------------------------------------------------------------------


def _assert_same_value(a: object, b: object) -> None:
    """Exact structural equality of two values of a space (arrays compared bit for bit).

    The types must match too: ndarray for ndarray, np.int64 for np.int64, tuple, dict.
    """
    assert type(a) is type(b), f"{type(a).__name__} != {type(b).__name__}"
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys()
        for k in a:
            _assert_same_value(a[k], b[k])
    elif isinstance(a, tuple):
        assert isinstance(b, tuple) and len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _assert_same_value(x, y)
    else:
        x, y = np.asarray(a), np.asarray(b)
        assert x.dtype == y.dtype and x.shape == y.shape
        assert x.tobytes() == y.tobytes()


@pytest.mark.parametrize("space", ALL_SPACES)
def test_check_accepts_samples(space: spaces.Space) -> None:
    for sample in _samples(space):
        checked = check(space, sample)
        assert space.contains(checked)
        _assert_same_value(checked, sample)


@pytest.mark.parametrize("space", ALL_SPACES)
def test_check_accepts_samples_after_wire_round_trip(space: spaces.Space) -> None:
    for sample in _samples(space):
        decoded = unpack(pack(sample))
        checked = check(space, decoded)
        assert space.contains(checked)
        _assert_same_value(checked, sample)


@pytest.mark.parametrize(
    "space", [pytest.param(s, id=_space_id(s)) for s in TESTING_SPACES if isinstance(s, spaces.Box)]
)
def test_check_accepts_bounds_of_boxes(space: spaces.Box) -> None:
    finite_low = np.where(np.isfinite(space.low), space.low, 0).astype(space.dtype)
    finite_high = np.where(np.isfinite(space.high), space.high, 0).astype(space.dtype)
    for value in (finite_low, finite_high):
        assert space.contains(check(space, value))


def test_check_returns_native_types() -> None:
    assert type(check(spaces.Discrete(4), 2)) is np.int64
    tup = check(spaces.Tuple((spaces.Discrete(2), spaces.Discrete(3))), [1, 2])
    assert type(tup) is tuple and tup == (1, 2)
    assert all(type(v) is np.int64 for v in tup)
    d = check(spaces.Dict({"a": spaces.Discrete(2)}), {"a": 1})
    assert type(d) is dict and d == {"a": 1}
    md = check(spaces.MultiDiscrete([3, 3]), [2, 0])
    assert md.dtype == np.int64 and md.tolist() == [2, 0]
    mb = check(spaces.MultiBinary(3), [1, 0, 1])
    assert mb.dtype == np.int8 and mb.tolist() == [1, 0, 1]


def test_check_discrete_accepts_numpy_integers_and_0d_arrays() -> None:
    space = spaces.Discrete(3, start=-1)
    assert check(space, np.int8(-1)) == -1
    assert check(space, np.uint64(1)) == 1
    assert check(space, np.array(0)) == 0
    assert type(check(space, np.array(0))) is np.int64


@pytest.mark.parametrize(
    ("space", "value", "expected"),
    [
        (spaces.Box(-1.0, 2.0, (3,), np.float32), [0.5, -1, 2], np.float32),
        (spaces.Box(-1.0, 2.0, (3,), np.float32), (0.5, -1.0, 2.0), np.float32),
        (spaces.Box(-np.inf, np.inf, (2, 2), np.float64), [[1, 2], [3, 4]], np.float64),
        (spaces.Box(-7, 7, (4,), np.int32), [1, -7, 7, 0], np.int32),
        (spaces.Box(0, 255, (2,), np.uint8), [0, 255], np.uint8),
        (spaces.Box(-1.0, 1.0, (), np.float32), 0.25, np.float32),
        (spaces.Box(-5, 5, (), np.int64), 3, np.int64),
    ],
)
def test_check_converts_lists_to_box_dtype(
    space: spaces.Box, value: object, expected: type
) -> None:
    checked = check(space, value)
    assert isinstance(checked, np.ndarray)
    assert checked.dtype == expected
    assert checked.shape == space.shape
    np.testing.assert_array_equal(checked, np.asarray(value, dtype=expected))
    assert space.contains(checked)


def test_check_converts_integer_array_to_float_box_dtype() -> None:
    space = spaces.Box(-10.0, 10.0, (2,), np.float32)
    checked = check(space, np.array([1, -3], dtype=np.int16))
    assert checked.dtype == np.float32
    assert checked.tolist() == [1.0, -3.0]


# --- check: rejecting ------------------------------------------------------------------------

_F32 = spaces.Box(-1.0, 2.0, (3,), np.float32)
_UNBOUNDED = spaces.Box(-np.inf, np.inf, (2,), np.float64)
_INT_BOX = spaces.Box(-7, 7, (4,), np.int32)
_NESTED = spaces.Dict(
    {
        "pos": spaces.Box(-10.0, 10.0, (2,), np.float32),
        "gear": spaces.Discrete(3, start=1),
        "arm": spaces.Tuple((spaces.Discrete(2), spaces.MultiDiscrete([2, 3]))),
    }
)
_GOOD_NESTED = {"pos": [0.0, 1.0], "gear": 2, "arm": [1, [1, 2]]}


_REJECTED: list[tuple[spaces.Space, Any, str]] = [
    # shapes
    (
        spaces.Box(-1.0, 1.0, (1,), np.float32),
        [0.0, 0.5],
        "action has shape (2,), expected (1,)",
    ),
    (_F32, 0.5, "action has shape (), expected (3,)"),
    (_F32, [[0.0, 0.0, 0.0]], "action has shape (1, 3), expected (3,)"),
    (spaces.MultiDiscrete([3, 3]), [1], "action has shape (1,), expected (2,)"),
    (spaces.MultiBinary([2, 3]), [0, 1, 0], "action has shape (3,), expected (2, 3)"),
    # non-finite
    (_F32, [0.0, math.nan, 0.0], "action[1] is nan, expected a finite number"),
    (_UNBOUNDED, [0.0, math.inf], "action[1] is inf, expected a finite number"),
    (_UNBOUNDED, [-math.inf, 0.0], "action[0] is -inf, expected a finite number"),
    (
        spaces.Box(-1.0, 1.0, (), np.float32),
        math.nan,
        "action is nan, expected a finite number",
    ),
    # bounds
    (_F32, [0.0, 0.0, 2.5], "action[2] is 2.5, outside the bounds [-1.0, 2.0]"),
    (_F32, [-1.5, 0.0, 0.0], "action[0] is -1.5, outside the bounds [-1.0, 2.0]"),
    (
        spaces.Box(np.array([[0, 0], [0, -1]]), np.array([[1, 1], [1, 4]]), dtype=np.int64),
        [[0, 1], [1, 5]],
        "action[1, 1] is 5, outside the bounds [-1, 4]",
    ),
    (spaces.Box(-5, 5, (), np.int64), 6, "action is 6, outside the bounds [-5, 5]"),
    # integer boxes
    (_INT_BOX, [1.0, 0, 0, 0], "action must hold integers, got dtype float64"),
    (_INT_BOX, np.zeros(4, np.float32), "action must hold integers, got dtype float32"),
    # non-numeric
    (_F32, "abc", "action must be an array or a number, got str"),
    (_F32, None, "action must be an array or a number, got NoneType"),
    (_F32, {"x": 1}, "action must be an array or a number, got dict"),
    (_F32, b"\x00\x00\x00", "action must be an array or a number, got bytes"),
    (_F32, ["a", "b", "c"], "action must be numeric, got dtype <U1"),
    (_F32, np.array([1 + 1j, 0, 0]), "action must be numeric, got dtype complex128"),
    (_F32, [[1.0], [1.0, 2.0], 3.0], "action is not a rectangular array"),
    (spaces.MultiBinary(2), ["0", "1"], "action must be numeric, got dtype <U1"),
    # Discrete
    (spaces.Discrete(5), True, "action must be an integer, got bool"),
    (spaces.Discrete(5), np.bool_(False), "action must be an integer, got bool"),
    (spaces.Discrete(5), 1.0, "action must be an integer, got float"),
    (spaces.Discrete(5), "1", "action must be an integer, got str"),
    (spaces.Discrete(5), [1], "action must be an integer, got list"),
    (
        spaces.Discrete(5),
        np.array([1]),
        "action must be an integer (a Discrete value is one "
        "integer, not an array), got an array of shape (1,) and dtype int64",
    ),
    (
        spaces.Discrete(5),
        np.zeros((2, 3), np.float32),
        "action must be an integer (a Discrete "
        "value is one integer, not an array), got an array of shape (2, 3) and dtype float32",
    ),
    (spaces.Discrete(5), 5, "action is 5, outside [0, 4]"),
    (spaces.Discrete(5), -1, "action is -1, outside [0, 4]"),
    (spaces.Discrete(3, start=-1), 2, "action is 2, outside [-1, 1]"),
    (spaces.Discrete(3, start=-1), -2, "action is -2, outside [-1, 1]"),
    # MultiDiscrete
    (spaces.MultiDiscrete([3, 4]), [0, 4], "action[1] is 4, outside [0, 3]"),
    (spaces.MultiDiscrete([3, 4]), [-1, 0], "action[0] is -1, outside [0, 2]"),
    (
        spaces.MultiDiscrete(np.array([5, 2]), start=np.array([-2, 10])),
        [0, 12],
        "action[1] is 12, outside [10, 11]",
    ),
    (
        spaces.MultiDiscrete(np.array([[2, 3], [4, 5]])),
        [[0, 0], [4, 0]],
        "action[1, 0] is 4, outside [0, 3]",
    ),
    (spaces.MultiDiscrete([3, 3]), [1.0, 0.0], "action must hold integers, got dtype float64"),
    # MultiBinary
    (spaces.MultiBinary(4), [0, 1, 2, 1], "action[2] is 2, expected 0 or 1"),
    (spaces.MultiBinary(4), [0, -1, 0, 1], "action[1] is -1, expected 0 or 1"),
    (spaces.MultiBinary([2, 3]), [[0, 1, 0], [0, 2, 0]], "action[1, 1] is 2, expected 0 or 1"),
    (spaces.MultiBinary(2), [0.0, 1.0], "action must hold integers, got dtype float64"),
    # Tuple
    (
        spaces.Tuple((spaces.Discrete(2), spaces.Discrete(2))),
        [1],
        "action must be a sequence of 2 items",
    ),
    (
        spaces.Tuple((spaces.Discrete(2), spaces.Discrete(2))),
        [1, 1, 1],
        "action must be a sequence of 2 items",
    ),
    (
        spaces.Tuple((spaces.Discrete(2), spaces.Discrete(2))),
        {"0": 1, "1": 1},
        "action must be a sequence of 2 items",
    ),
    (
        spaces.Tuple((spaces.Discrete(2), spaces.Discrete(2))),
        [1, 2],
        "action[1] is 2, outside [0, 1]",
    ),
    # Dict
    (
        _NESTED,
        {"pos": [0.0, 0.0], "arm": [0, [0, 0]]},
        "action has missing keys ['gear'] and unknown keys []",
    ),
    (
        _NESTED,
        {**_GOOD_NESTED, "speed": 1},
        "action has missing keys [] and unknown keys ['speed']",
    ),
    (
        _NESTED,
        {"pos": [0.0, 0.0], "gear": 1, "speed": 1},
        "action has missing keys ['arm'] and unknown keys ['speed']",
    ),
    (_NESTED, [1, 2, 3], "action must be a map with keys ['arm', 'gear', 'pos']"),
    # nested paths
    (_NESTED, {**_GOOD_NESTED, "pos": [math.nan, 0.0]}, "action['pos'][0] is nan"),
    (
        _NESTED,
        {**_GOOD_NESTED, "pos": [0.0, 11.0]},
        "action['pos'][1] is 11.0, outside the bounds [-10.0, 10.0]",
    ),
    (_NESTED, {**_GOOD_NESTED, "pos": [0.0]}, "action['pos'] has shape (1,), expected (2,)"),
    (_NESTED, {**_GOOD_NESTED, "gear": 0}, "action['gear'] is 0, outside [1, 3]"),
    (_NESTED, {**_GOOD_NESTED, "arm": [2, [0, 0]]}, "action['arm'][0] is 2, outside [0, 1]"),
    (
        _NESTED,
        {**_GOOD_NESTED, "arm": [0, [0, 3]]},
        "action['arm'][1][1] is 3, outside [0, 2]",
    ),
    (_NESTED, {**_GOOD_NESTED, "arm": [0]}, "action['arm'] must be a sequence of 2 items"),
    (
        spaces.Tuple((spaces.Dict({"pos": spaces.Box(-1.0, 1.0, (2,), np.float32)}),)),
        [{"pos": [0.0, math.inf]}],
        "action[0]['pos'][1] is inf, expected a finite number",
    ),
]
"""(space, value, a part of the message) for values that ``check`` refuses."""


@pytest.mark.parametrize(("space", "value", "message"), _REJECTED)
def test_check_rejects_with_path_and_rule(space: spaces.Space, value: object, message: str) -> None:
    with pytest.raises(SpaceMismatch) as info:
        check(space, value)
    assert message in str(info.value)
    assert str(info.value).startswith("action")


def test_nested_good_value_is_accepted() -> None:
    checked = check(_NESTED, _GOOD_NESTED)
    assert _NESTED.contains(checked)
    assert type(checked["arm"]) is tuple


def test_space_mismatch_is_a_value_error() -> None:
    assert issubclass(SpaceMismatch, ValueError)


def test_check_uses_the_given_path() -> None:
    with pytest.raises(SpaceMismatch, match=re.escape("observation['agent'][1] is nan")):
        check(
            spaces.Box(-1.0, 1.0, (2,), np.float32),
            [0.0, math.nan],
            "observation['agent']",
        )
    with pytest.raises(SpaceMismatch, match=r"^obs\['x'\] is 9, outside \[0, 1\]$"):
        check(spaces.Dict({"x": spaces.Discrete(2)}), {"x": 9}, "obs")


def test_check_rejects_nan_in_wire_array() -> None:
    value = unpack(pack(np.array([0.0, 0.0, np.nan], dtype=np.float32)))
    with pytest.raises(SpaceMismatch, match=re.escape("action[2] is nan")):
        check(_F32, value)


def test_check_does_not_mutate_or_copy_a_valid_wire_array() -> None:
    value = unpack(pack(np.array([0.5, -1.0, 2.0], dtype=np.float32)))
    assert not value.flags.writeable
    checked = check(_F32, value)
    assert checked is value


@pytest.mark.parametrize(
    ("space", "value"),
    [
        (spaces.Box(0, 255, (2,), np.uint8), [300, 0]),
        (spaces.Box(0, 255, (2,), np.uint8), [-1, 0]),
        (spaces.Box(0, 255, (2,), np.uint8), np.array([256, 0], dtype=np.int64)),
        (spaces.Box(-7, 7, (1,), np.int32), [2**32 + 1]),
        (spaces.Box(-7, 7, (1,), np.int64), np.array([2**64 - 1], dtype=np.uint64)),
    ],
    ids=["uint8-300", "uint8-minus-1", "uint8-256-array", "int32-2**32+1", "int64-from-uint64"],
)
def test_check_rejects_integers_that_overflow_the_box_dtype(
    space: spaces.Box, value: object
) -> None:
    with pytest.raises(SpaceMismatch, match=r"outside the bounds"):
        check(space, value)


@pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")
def test_check_rejects_float64_that_overflows_float32_box() -> None:
    space = spaces.Box(-np.inf, np.inf, (2,), np.float32)
    with pytest.raises(SpaceMismatch):
        check(space, [1e300, 0.0])


# --- Codec.unpack ------------------------------------------------------------------------------


def test_unpack_rebuilds_native_types() -> None:
    space = spaces.Tuple(
        (
            spaces.Discrete(4),
            spaces.Box(-1.0, 1.0, (2,), np.float32),
            spaces.Dict({"m": spaces.MultiDiscrete([2, 2]), "b": spaces.MultiBinary(2)}),
        )
    )
    value = codec_for(space).unpack([3, [0.5, -0.5], {"m": [1, 0], "b": [0, 1]}])
    assert type(value) is tuple and len(value) == 3
    assert type(value[0]) is np.int64 and value[0] == 3
    assert isinstance(value[1], np.ndarray) and value[1].dtype == np.float32
    assert value[1].tolist() == [0.5, -0.5]
    assert type(value[2]) is dict
    assert value[2]["m"].dtype == np.int64 and value[2]["m"].tolist() == [1, 0]
    assert value[2]["b"].dtype == np.int8 and value[2]["b"].tolist() == [0, 1]
    assert space.contains(value)


def test_unpack_box_from_list_has_space_dtype() -> None:
    for dtype in (np.float32, np.float64, np.int32, np.uint8):
        space = spaces.Box(0, 10, (3,), dtype)
        value = codec_for(space).unpack([1, 2, 3])
        assert isinstance(value, np.ndarray)
        assert value.dtype == dtype
        assert value.tolist() == [1, 2, 3]


def test_unpack_scalar_box_and_discrete() -> None:
    scalar = spaces.Box(-1.0, 1.0, (), np.float32)
    for wire in (0.5, np.float32(0.5).tobytes()):
        box = codec_for(scalar).unpack(wire)
        assert isinstance(box, np.ndarray) and box.shape == () and box.dtype == np.float32
        assert box == 0.5
    disc = codec_for(spaces.Discrete(3, start=5)).unpack(6)
    assert type(disc) is np.int64 and disc == 6


def test_unpack_gives_writable_arrays_as_gymnasium_does() -> None:
    space = spaces.Box(-1.0, 1.0, (2, 2), np.float32)
    codec = codec_for(space)
    wire = unpack(pack(np.zeros((2, 2), np.float32)))
    assert not wire.flags.writeable  # decoded in place from the frame
    value = codec.unpack(wire)
    assert value.flags.writeable and not np.shares_memory(value, wire)
    assert np.array_equal(value, wire)
    mine = np.ones((2, 2), np.float32)
    assert codec.unpack(mine) is mine  # an array that is already writable is kept


def test_unpack_of_packed_bytes_is_writable_unless_told_otherwise() -> None:
    space = spaces.Box(-1.0, 1.0, (2, 2), np.float32)
    codec = codec_for(space)
    original = np.arange(4, dtype=np.float32).reshape(2, 2) / 4
    packed = codec.pack(original)
    value = codec.unpack(packed)
    assert value.flags.writeable and value.dtype == np.float32 and value.shape == (2, 2)
    assert np.array_equal(value, original)
    value[0, 0] = 9.0  # the caller's own copy: the received bytes are untouched
    assert codec.unpack(packed)[0, 0] == 0.0
    view = codec.unpack(packed, writable=False)
    assert np.array_equal(view, original) and view.dtype == np.float32 and view.shape == (2, 2)


def test_unpack_without_writable_may_return_a_view() -> None:
    space = spaces.Box(-1.0, 1.0, (2, 2), np.float32)
    wire = unpack(pack(np.zeros((2, 2), np.float32)))
    view = codec_for(space).unpack(wire, writable=False)
    assert np.array_equal(view, wire) and view.dtype == np.float32
    assert np.shares_memory(view, wire)  # no copy was needed, so none was made


@pytest.mark.parametrize("space", ALL_SPACES)
def test_unpack_of_samples_after_round_trip(space: spaces.Space) -> None:
    codec = codec_for(space)
    for sample in _samples(space):
        value = codec.unpack(unpack(pack(sample)))
        assert space.contains(value)
        _assert_same_value(value, sample)
        _assert_writable(value)


def _assert_writable(value: Any) -> None:
    if isinstance(value, dict):
        for item in value.values():
            _assert_writable(item)
    elif isinstance(value, tuple):
        for item in value:
            _assert_writable(item)
    elif isinstance(value, np.ndarray):
        assert value.flags.writeable


# --- Codec.pack and the packed form -----------------------------------------------------------


def _assert_packed_form(space: spaces.Space, packed: Any) -> None:
    """``packed`` has the packed form of ``space``: bytes, ints, lists and maps of them."""
    if isinstance(space, spaces.Dict):
        assert type(packed) is dict and packed.keys() == space.spaces.keys()
        for key, item in space.spaces.items():
            _assert_packed_form(item, packed[key])
    elif isinstance(space, spaces.Tuple):
        assert type(packed) is list and len(packed) == len(space.spaces)
        for item, value in zip(space.spaces, packed, strict=True):
            _assert_packed_form(item, value)
    elif isinstance(space, spaces.Discrete):
        assert type(packed) is int
    else:
        assert type(packed) is bytes
        assert len(packed) == int(np.prod(space.shape)) * space.dtype.itemsize


@pytest.mark.parametrize("space", ALL_SPACES)
def test_packed_round_trip(space: spaces.Space) -> None:
    codec = codec_for(space)
    for sample in _samples(space):
        packed = codec.pack(sample)
        _assert_packed_form(space, packed)
        value = codec.unpack(packed)
        assert space.contains(value)
        _assert_same_value(value, sample)
        _assert_writable(value)
        read_only = codec.unpack(packed, writable=False)
        assert space.contains(read_only)
        _assert_same_value(read_only, sample)


@pytest.mark.parametrize("space", ALL_SPACES)
def test_msgpack_carries_the_packed_form_unchanged(space: spaces.Space) -> None:
    codec = codec_for(space)
    for sample in _samples(space):
        packed = codec.pack(sample)
        carried = unpack(pack(packed))
        _assert_packed_form(space, carried)
        assert carried == packed
        _assert_same_value(codec.unpack(carried), sample)


@pytest.mark.parametrize("space", ALL_SPACES)
def test_pack_of_a_read_only_wire_value_is_the_same(space: spaces.Space) -> None:
    codec = codec_for(space)
    for sample in _samples(space):
        assert codec.pack(unpack(pack(sample))) == codec.pack(sample)


@pytest.mark.parametrize("k", [1, 3])
@pytest.mark.parametrize("space", ALL_SPACES)
def test_join_is_a_value_of_the_batch_space(space: spaces.Space, k: int) -> None:
    codec = codec_for(space)
    samples = _samples(space)[:k]
    joined = codec.join([codec.pack(s) for s in samples])
    batch = batch_space(space, k)
    _assert_packed_form(batch, joined)
    value = codec_for(batch).unpack(joined)
    expected = concatenate(space, samples, create_empty_array(space, k))
    _assert_same_value(value, expected)
    assert batch.contains(value)
    # a joined batch travels through msgpack like any packed value
    _assert_same_value(codec_for(batch).unpack(unpack(pack(joined))), expected)


def test_join_of_discrete_values_is_int64_bytes() -> None:
    codec = codec_for(spaces.Discrete(3, start=-1))
    joined = codec.join([codec.pack(v) for v in (-1, np.int64(1), 0)])
    assert joined == np.array([-1, 1, 0], np.int64).tobytes()


_NESTED_F64 = spaces.Tuple(
    (
        spaces.Dict(
            {
                "arm": spaces.Box(-1.0, 1.0, (3,), np.float64),
                "grip": spaces.Tuple((spaces.Discrete(2), spaces.MultiDiscrete([2, 3]))),
            }
        ),
        spaces.Discrete(7),
    )
)
_GOOD_NESTED_F64: list[Any] = [{"arm": [0.0, 0.5, -0.5], "grip": (1, [1, 2])}, 3]


@pytest.mark.parametrize(
    ("space", "value", "message"),
    [
        # shapes
        (_F32, [0.0, 0.5], "has shape (2,), its space declares (3,)"),
        (_F32, 0.5, "has shape (), its space declares (3,)"),
        (_F32, np.zeros((1, 3), np.float32), "has shape (1, 3), its space declares (3,)"),
        (
            spaces.MultiBinary([2, 3]),
            [0, 1, 0],
            "has shape (3,), its space declares (2, 3)",
        ),
        (spaces.Box(-1.0, 1.0, (), np.float32), [0.5], "has shape (1,), its space declares ()"),
        # non-finite
        (_F32, [0.0, math.nan, 0.0], "[1] is not finite"),
        (_F32, np.array([0.0, 0.0, -np.inf], np.float32), "[2] is not finite"),
        (_UNBOUNDED, [math.inf, 0.0], "[0] is not finite"),
        (
            spaces.Box(-np.inf, np.inf, (2, 2), np.float64),
            [[0.0, 1.0], [2.0, math.nan]],
            "[1, 1] is not finite",
        ),
        (spaces.Box(-1.0, 1.0, (40,), np.float32), [0.0] * 39 + [math.nan], "[39] is not finite"),
        # not numbers
        (_F32, "abc", "is not an array of float32"),
        (_F32, [[1.0], [1.0, 2.0], 3.0], "is not an array of float32"),
        (spaces.Discrete(3), 1.5, "is not an integer: 1.5"),
        (spaces.Discrete(3), True, "is not an integer: True"),
        (spaces.Discrete(3), "1", "is not an integer: '1'"),
        (spaces.Discrete(3), np.array([1]), "is not an integer"),
        # structure
        (
            spaces.Tuple((spaces.Discrete(2), spaces.Discrete(2))),
            [1],
            "is not a sequence of 2 items",
        ),
        (spaces.Tuple((spaces.Discrete(2),)), {"0": 1}, "is not a sequence of 1 items"),
        (_NESTED, [1, 2, 3], "is not a map with the keys ['arm', 'gear', 'pos']"),
        (
            _NESTED,
            {"pos": [0.0, 0.0], "gear": 1},
            "is not a map with the keys ['arm', 'gear', 'pos']",
        ),
        # nested locations
        (_NESTED, {**_GOOD_NESTED, "pos": [0.0, math.nan]}, "['pos'][1] is not finite"),
        (
            _NESTED,
            {**_GOOD_NESTED, "pos": [0.0]},
            "['pos'] has shape (1,), its space declares (2,)",
        ),
        (_NESTED, {**_GOOD_NESTED, "gear": 1.0}, "['gear'] is not an integer: 1.0"),
        (_NESTED, {**_GOOD_NESTED, "arm": [1]}, "['arm'] is not a sequence of 2 items"),
        (
            _NESTED,
            {**_GOOD_NESTED, "arm": [1, [1, 2, 0]]},
            "['arm'][1] has shape (3,), its space declares (2,)",
        ),
        (
            _NESTED_F64,
            [{**_GOOD_NESTED_F64[0], "arm": [0.0, 0.0, math.inf]}, 3],
            "[0]['arm'][2] is not finite",
        ),
        (
            _NESTED_F64,
            [{**_GOOD_NESTED_F64[0], "grip": (False, [1, 2])}, 3],
            "[0]['grip'][0] is not an integer: False",
        ),
        (_NESTED_F64, [_GOOD_NESTED_F64[0], None], "[1] is not an integer: None"),
    ],
)
def test_pack_refuses_with_location(space: spaces.Space, value: Any, message: str) -> None:
    with pytest.raises(SpaceMismatch) as info:
        codec_for(space).pack(value)
    assert str(info.value).startswith(message)


def test_pack_accepts_the_good_nested_values() -> None:
    packed = codec_for(_NESTED).pack(_GOOD_NESTED)
    _assert_packed_form(_NESTED, packed)
    assert _NESTED.contains(codec_for(_NESTED).unpack(packed))
    packed = codec_for(_NESTED_F64).pack(_GOOD_NESTED_F64)
    _assert_packed_form(_NESTED_F64, packed)
    assert _NESTED_F64.contains(codec_for(_NESTED_F64).unpack(packed))


@pytest.mark.parametrize(
    ("space", "value"),
    [
        (spaces.Box(-1.0, 2.0, (3,), np.float32), [0.5, -1, 2]),
        (spaces.Box(-1.0, 2.0, (3,), np.float32), (0.5, -1.0, 2.0)),
        (spaces.Box(-1.0, 2.0, (3,), np.float32), np.array([0.5, -1.0, 2.0])),
        (spaces.Box(-1.0, 2.0, (3,), np.float32), np.array([1, 0, 2], np.int16)),
        (spaces.Box(-np.inf, np.inf, (2, 2), np.float64), [[1, 2], [3, 4]]),
        (spaces.Box(-np.inf, np.inf, (2, 2), np.float64), np.ones((2, 2), np.float32)),
        (spaces.Box(-7, 7, (4,), np.int32), [1, -7, 7, 0]),
        (spaces.Box(-7, 7, (4,), np.int32), np.array([1, -7, 7, 0], np.int64)),
        (spaces.Box(0, 255, (2,), np.uint8), [0, 255]),
        (spaces.Box(-1.0, 1.0, (), np.float32), 0.25),
        (spaces.Box(-1.0, 1.0, (), np.float32), np.float64(0.25)),
        (spaces.MultiDiscrete([3, 3]), [2, 0]),
        (spaces.MultiDiscrete([3, 3]), np.array([2, 0], np.uint8)),
        (spaces.MultiBinary([2, 2]), [[1, 0], [0, 1]]),
        (spaces.MultiBinary([2, 2]), np.array([[True, False], [False, True]])),
        (
            spaces.Box(np.zeros((2, 3), np.float32), np.ones((2, 3), np.float32)),
            np.ones((3, 2)).T,  # not C-contiguous: still packed in C order
        ),
    ],
)
def test_pack_converts_to_the_space_dtype(space: spaces.Space, value: Any) -> None:
    codec = codec_for(space)
    packed = codec.pack(value)
    expected = np.asarray(value).astype(space.dtype)
    assert packed == expected.tobytes()
    unpacked = codec.unpack(packed)
    assert unpacked.dtype == space.dtype and unpacked.shape == space.shape
    np.testing.assert_array_equal(unpacked, expected)


@pytest.mark.parametrize("value", [2, np.int8(2), np.uint64(2), np.array(2), np.array(2, np.int16)])
def test_pack_converts_discrete_values_to_int(value: Any) -> None:
    packed = codec_for(spaces.Discrete(3)).pack(value)
    assert type(packed) is int and packed == 2


def test_pack_converts_tuples_and_dicts_to_lists_and_maps() -> None:
    space = spaces.Tuple((spaces.Discrete(2), spaces.Dict({"x": spaces.MultiBinary(2)})))
    packed = codec_for(space).pack((np.int64(1), {"x": [1, 0]}))
    assert packed == [1, {"x": np.array([1, 0], np.int8).tobytes()}]


def test_pack_keeps_huge_finite_float32_values() -> None:
    space = spaces.Box(-np.inf, np.inf, (2,), np.float32)
    value = np.array([3e38, 3e38], np.float32)
    assert codec_for(space).pack(value) == value.tobytes()


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_pack_keeps_huge_finite_float64_values() -> None:
    space = spaces.Box(-np.inf, np.inf, (2,), np.float64)
    value = np.array([1e308, 1e308])
    assert check(space, value) is value  # check accepts them
    assert codec_for(space).pack(value) == value.tobytes()


# --- Codec.pack_exact --------------------------------------------------------------------------


@pytest.mark.parametrize("space", ALL_SPACES)
def test_pack_exact_of_samples_is_their_packed_form(space: spaces.Space) -> None:
    codec = codec_for(space)
    for sample in _samples(space):
        packed = codec.pack_exact(sample)
        _assert_packed_form(space, packed)
        assert packed == codec.pack(sample)
        # read-only arrays decoded from a frame are exact too
        assert codec.pack_exact(unpack(pack(sample))) == packed


@pytest.mark.parametrize(
    "value",
    [
        pytest.param([0.0, 0.5, 1.0], id="list"),
        pytest.param((0.0, 0.5, 1.0), id="tuple"),
        pytest.param(np.array([0.0, 0.5, 1.0]), id="float64"),
        pytest.param(np.array([0, 1, 1], np.int32), id="int32"),
        pytest.param(np.zeros(4, np.float32), id="wrong-shape"),
        pytest.param(np.zeros((1, 3), np.float32), id="wrong-ndim"),
        pytest.param(np.zeros(3, np.float32).view(np.recarray), id="subclass"),
        pytest.param(np.zeros(3, np.dtype(">f4")), id="big-endian"),
        pytest.param("abc", id="text"),
        pytest.param(None, id="None"),
        pytest.param(np.zeros(3, np.float32).tobytes(), id="bytes"),
    ],
)
def test_pack_exact_returns_anything_inexact_unchanged(value: Any) -> None:
    assert codec_for(_F32).pack_exact(value) is value


def test_pack_exact_turns_exact_arrays_into_bytes() -> None:
    value = np.array([0.5, -1.0, 2.0], np.float32)
    assert codec_for(_F32).pack_exact(value) == value.tobytes()
    grid = np.arange(6, dtype=np.float32).reshape(3, 2).T  # exact, though not C-contiguous
    box = spaces.Box(-10.0, 10.0, (2, 3), np.float32)
    assert codec_for(box).pack_exact(grid) == np.ascontiguousarray(grid).tobytes()
    nan = np.array([math.nan, 0.0, 0.0], np.float32)  # not checked: the receiver refuses it
    assert codec_for(_F32).pack_exact(nan) == nan.tobytes()


def test_pack_exact_of_discrete_and_containers() -> None:
    discrete = codec_for(spaces.Discrete(3))
    assert type(discrete.pack_exact(np.int64(2))) is int and discrete.pack_exact(np.int64(2)) == 2
    for value in (2, 1.5, True, "1", None):
        assert discrete.pack_exact(value) is value
    exact = np.zeros(2, np.float32)
    inexact = [0.0, 1.0]
    dict_codec = codec_for(_NESTED)
    packed = dict_codec.pack_exact({"pos": exact, "gear": np.int64(2), "arm": (1, inexact)})
    assert packed == {"pos": exact.tobytes(), "gear": 2, "arm": [1, inexact]}
    assert packed["arm"][1] is inexact
    for value in ({"pos": exact}, [exact, 2, 1], None):
        assert dict_codec.pack_exact(value) is value
    tuple_codec = codec_for(spaces.Tuple((spaces.Discrete(2), _F32)))
    for value in ((1,), [1, exact, 2], {"0": 1}):
        assert tuple_codec.pack_exact(value) is value


# --- compile_check agrees with check ------------------------------------------------------------


def _outcome(checker: Callable[[Any], Any], value: Any) -> tuple[str, Any]:
    try:
        return "accepted", checker(value)
    except SpaceMismatch as error:
        return "refused", str(error)


def _assert_agree(space: spaces.Space, value: Any, path: str = "action") -> tuple[str, Any]:
    """``compile_check`` and ``check`` give the same verdict, message or value for ``value``."""
    careful = _outcome(lambda v: check(space, v, path), value)
    compiled = _outcome(compile_check(space, path), value)
    assert compiled[0] == careful[0], (compiled, careful)
    if careful[0] == "refused":
        assert compiled[1] == careful[1]
    else:
        _assert_same_value(compiled[1], careful[1])
    return careful


@pytest.mark.parametrize("space", ALL_SPACES)
def test_compile_check_agrees_on_samples(space: spaces.Space) -> None:
    compiled = compile_check(space)
    codec = codec_for(space)
    for sample in _samples(space):
        for value in (sample, unpack(pack(sample))):
            verdict, checked = _assert_agree(space, value)
            assert verdict == "accepted" and space.contains(checked)
            _assert_same_value(checked, sample)
        # the packed form, as the server receives it (``check`` only knows native values)
        expected = check(space, sample)
        packed = codec.pack(sample)
        for value in (packed, unpack(pack(packed))):
            checked = compiled(value)
            assert space.contains(checked)
            _assert_same_value(checked, expected)


def test_compile_check_keeps_a_valid_array() -> None:
    value = unpack(pack(np.array([0.5, -1.0, 2.0], dtype=np.float32)))
    assert compile_check(_F32)(value) is value


def test_compile_check_uses_the_given_path() -> None:
    with pytest.raises(SpaceMismatch, match=r"^obs\['x'\] is 9, outside \[0, 1\]$"):
        compile_check(spaces.Dict({"x": spaces.Discrete(2)}), "obs")({"x": 9})
    with pytest.raises(SpaceMismatch, match=r"^steps\.action\[1\] is nan"):
        compile_check(_F32, "steps.action")(np.array([0.0, math.nan, 0.0], np.float32))


def test_compile_check_of_an_unsupported_space_is_check() -> None:
    for path in ("action", "steps.action"):
        _assert_agree(spaces.Text(5), "hello", path)
        _assert_agree(spaces.Tuple((spaces.Discrete(2), spaces.Text(3))), [1, "abc"], path)


_U8 = spaces.Box(0, 255, (2,), np.uint8)
_F32_UNBOUNDED = spaces.Box(-np.inf, np.inf, (2,), np.float32)
_F64_BIG = spaces.Box(-np.inf, np.inf, (40,), np.float64)

_MORE_REJECTED: list[tuple[spaces.Space, Any]] = [
    # integer wrap-around: refused before a cast could wrap
    (_U8, [300, 0]),
    (_U8, [-1, 0]),
    (_U8, np.array([256, 0], np.int64)),
    (_U8, np.array([0, 300], np.uint16)),
    (spaces.Box(-7, 7, (1,), np.int32), [2**32 + 1]),
    (spaces.Box(-7, 7, (1,), np.int64), np.array([2**64 - 1], np.uint64)),
    (spaces.Box(-7, 7, (1,), np.int32), np.array([8], np.int32)),  # exact dtype, out of bounds
    # float32 overflow from float64
    (_F32_UNBOUNDED, [1e300, 0.0]),
    (_F32_UNBOUNDED, np.array([0.0, -1e39])),
    (_F32, np.array([0.0, 1e300, 0.0])),
    # exact dtype, but NaN, inf or out of bounds (the compiled fast path must step aside)
    (_F32, np.array([0.0, math.nan, 0.0], np.float32)),
    (_F32, np.array([0.0, 0.0, 2.5], np.float32)),
    (_F32, np.array([-math.inf, 0.0, 0.0], np.float32)),
    (_F32_UNBOUNDED, np.array([math.inf, 0.0], np.float32)),
    (_F32_UNBOUNDED, np.array([math.inf, -math.inf], np.float32)),
    (_UNBOUNDED, np.array([0.0, math.nan])),
    (_F64_BIG, np.concatenate([np.zeros(39), [math.inf]])),
    (_F64_BIG, np.concatenate([[math.nan], np.zeros(39)])),
    (spaces.Box(-1.0, 1.0, (5, 8), np.float32), np.full((5, 8), 1.5, np.float32)),
    (spaces.Box(-1.0, 1.0, (), np.float32), np.array(math.nan, np.float32)),
    (spaces.Box(-1.0, 1.0, (), np.float32), np.array(1.5, np.float32)),
    (spaces.MultiBinary(4), np.array([0, 1, 2, 1], np.int8)),
    (spaces.MultiDiscrete([3, 4]), np.array([0, 4], np.int64)),
    (spaces.MultiDiscrete(np.array([5, 2]), start=np.array([-2, 10])), np.array([-3, 10])),
    # bool where an int is expected
    (_INT_BOX, [True, False, True, False]),
    (_INT_BOX, np.array([True, False, True, False])),
    (spaces.Discrete(2), np.array(True)),
    (spaces.Tuple((spaces.Discrete(2),)), [True]),
    # wrong dtype kind, text, ragged
    (_F32, np.array(["a", "b", "c"])),
    (_F32, np.zeros(3, object)),
    (_INT_BOX, np.zeros(4, np.float16)),
    (spaces.MultiDiscrete([3, 3]), np.array([1.0, 0.0], np.float32)),
    (_INT_BOX, [[1, 2], [3]]),
    (spaces.MultiBinary(2), "01"),
    (spaces.Discrete(3), np.float32(1.0)),
    (spaces.Discrete(3), b"\x01"),
    # wrong shape, exact dtype
    (_F32, np.zeros(4, np.float32)),
    (_F32, np.zeros((3, 1), np.float32)),
    (spaces.MultiBinary([2, 3]), np.zeros((3, 2), np.int8)),
    # containers
    (spaces.Tuple((spaces.Discrete(2), spaces.Discrete(2))), (1, 1, 1)),
    (spaces.Tuple((spaces.Discrete(2), spaces.Discrete(2))), "ab"),
    (spaces.Tuple((spaces.Discrete(2), spaces.Discrete(2))), np.array([1, 1])),
    (spaces.Tuple((spaces.Discrete(2), _F32)), (1, [0.0, 0.0, math.inf])),
    (_NESTED, types.MappingProxyType({**_GOOD_NESTED, "gear": 7})),
    (_NESTED, {**_GOOD_NESTED, 3: 1}),
    (_NESTED, {}),
    (_NESTED, {**_GOOD_NESTED, "pos": np.array([0.0, math.nan], np.float32)}),
    (_NESTED, {**_GOOD_NESTED, "arm": (1, np.array([1, 3]))}),
    (_NESTED_F64, [{**_GOOD_NESTED_F64[0], "grip": [1, [2, 0]]}, 3]),
    (_NESTED_F64, [{**_GOOD_NESTED_F64[0], "arm": np.array([0.0, 0.0, 1.5])}, 3]),
    (_NESTED_F64, [_GOOD_NESTED_F64[0], 7]),
]
"""More values that ``check`` refuses, for the compiled checker's sake."""

_ODD_BUT_ACCEPTED: list[tuple[spaces.Space, Any]] = [
    (_F32, (0.5, -1.0, 2.0)),
    (_F32, [0, 1, 2]),
    (_F32, np.array([0.5, -1.0, 2.0])),
    (_F32, np.array([1, 0, 2], np.int16)),
    (_F32, np.array([0.5, -1.0, 2.0], np.dtype(">f4"))),
    (_F32, np.array([[0.5, -1.0, 2.0]], np.float32)[0]),
    (_F32, np.array([0.5, 9.0, -1.0, 9.0, 2.0], np.float32)[::2]),  # not contiguous
    (_F32_UNBOUNDED, np.array([3e38, -3e38], np.float32)),
    (_UNBOUNDED, np.array([1e308, 1e308])),  # finite, though their sum overflows
    (_F64_BIG, np.full(40, 1e308)),
    (_U8, np.array([255, 0], np.int64)),
    (spaces.Box(-1.0, 1.0, (), np.float32), 1),
    (spaces.Box(-1.0, 1.0, (), np.float32), np.float32(-1.0)),
    (spaces.Discrete(3, start=-1), np.int8(-1)),
    (spaces.Discrete(3, start=-1), np.uint64(1)),
    (spaces.Discrete(3, start=-1), np.array(0)),
    (spaces.MultiBinary(3), np.array([True, False, True])),
    (spaces.MultiBinary(3), [1, 0, 1]),
    (spaces.MultiDiscrete([3, 3]), np.array([2, 0], np.uint8)),
    (spaces.Tuple((spaces.Discrete(2), _F32)), (1, [0.0, 0.0, 0.0])),
    (_NESTED, types.MappingProxyType(_GOOD_NESTED)),
    (_NESTED, {"arm": [1, [1, 2]], "pos": [0.0, 1.0], "gear": 2}),  # keys in another order
    (_NESTED_F64, _GOOD_NESTED_F64),
    (_NESTED_F64, tuple(_GOOD_NESTED_F64)),
]
"""Values that ``check`` accepts without their being the packed form or of the exact dtype."""


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
@pytest.mark.parametrize(("space", "value", "message"), _REJECTED)
def test_compile_check_refuses_as_check_does(space: spaces.Space, value: Any, message: str) -> None:
    if type(value) is bytes and isinstance(space, spaces.Box):
        # ``check`` knows no packed form; the compiled checker reads bytes as one
        with pytest.raises(SpaceMismatch, match=r"^action is \d+ bytes, expected \d+: "):
            compile_check(space)(value)
        return
    verdict, refusal = _assert_agree(space, value)
    assert verdict == "refused" and message in refusal


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
@pytest.mark.parametrize(("space", "value"), _MORE_REJECTED)
def test_compile_check_refuses_more_as_check_does(space: spaces.Space, value: Any) -> None:
    for path in ("action", "obs['x']"):
        verdict, refusal = _assert_agree(space, value, path)
        assert verdict == "refused" and refusal.startswith(path)


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
@pytest.mark.parametrize(("space", "value"), _ODD_BUT_ACCEPTED)
def test_compile_check_accepts_as_check_does(space: spaces.Space, value: Any) -> None:
    verdict, checked = _assert_agree(space, value)
    assert verdict == "accepted" and space.contains(checked)


def _bad_values(space: spaces.Space) -> list[Any]:
    """Values that do not belong to ``space``, derived from its structure."""
    if isinstance(space, spaces.Discrete):
        first, end = int(space.start), int(space.start + space.n)
        return [
            end,
            first - 1,
            2**70,
            True,
            np.bool_(False),
            float(first),
            np.float64(first),
            str(first),
            None,
            [first],
            np.array([first]),
        ]
    if isinstance(space, spaces.Tuple):
        good = list(_samples(space)[0])
        bad: list[Any] = [good[:-1], [*good, good[0]], {"0": good[0]}, None]
        for index, item in enumerate(space.spaces):
            bad += [[*good[:index], v, *good[index + 1 :]] for v in _bad_values(item)]
        return bad
    if isinstance(space, spaces.Dict):
        good = dict(_samples(space)[0])
        first_key = next(iter(good))
        bad = [
            {k: v for k, v in good.items() if k != first_key},
            {**good, "unknown": 0},
            list(good.values()),
            None,
        ]
        for key, item in space.spaces.items():
            bad += [{**good, key: v} for v in _bad_values(item)]
        return bad
    return _bad_arrays(space)


def _bad_arrays(space: spaces.Space) -> list[Any]:
    dtype, shape = space.dtype, space.shape
    sample = _samples(space)[0]
    floats = dtype.kind == "f"
    bad: list[Any] = [
        np.zeros((*shape, 2), dtype),  # wrong shape
        np.zeros((2, *shape), dtype).tolist(),
        "text",
        None,
        {"x": 1},
        [[0], [0, 0]],  # ragged
        np.full(shape, "a"),
    ]
    if shape:
        bad.append(sample.reshape(-1)[:-1].tolist() if len(shape) == 1 else sample[0].tolist())
    if isinstance(space, spaces.Box):
        bad.append(np.full(shape, True))  # bool where a number is expected
    if floats:
        bad.append(sample.astype(np.complex64))
        for non_finite in (math.nan, math.inf, -math.inf):
            exact = sample.copy()
            exact.reshape(-1)[-1] = non_finite
            bad += [exact, exact.astype(np.float64), exact.tolist()]
        if dtype == np.float32:
            huge = sample.astype(np.float64)
            huge.reshape(-1)[0] = 1e300  # becomes inf in float32
            bad.append(huge)
    else:
        bad += [sample.astype(np.float64), sample.astype(np.float64).tolist()]
    if isinstance(space, spaces.Box):
        low, high = space.low, space.high
    elif isinstance(space, spaces.MultiDiscrete):
        low, high = space.start, space.start + space.nvec - 1
    else:
        low, high = np.zeros(shape, np.int64), np.ones(shape, np.int64)
    wide = np.float64 if floats else np.int64
    for bound, step in ((high, 1), (low, -1)):
        flat = bound.reshape(-1)
        if not np.isfinite(flat[-1]):
            continue
        outside = sample.astype(wide)
        outside.reshape(-1)[-1] = flat[-1].item() + step * (0.5 if floats else 1)
        bad += [outside, outside.tolist()]
        if outside.astype(dtype).astype(wide).tolist() == outside.tolist():
            bad.append(outside.astype(dtype))  # exact dtype, out of bounds
        if not floats and dtype.itemsize < 8:
            # a value that a cast to the space's dtype would wrap into the bounds
            wrapped = sample.astype(np.int64)
            wrapped.reshape(-1)[-1] = flat[-1].item() + step * 2 ** (8 * dtype.itemsize)
            bad += [wrapped, wrapped.tolist()]
    return bad


def _exact_arrays(value: Any, space: spaces.Space) -> bool:
    return (
        isinstance(space, spaces.Box | spaces.MultiDiscrete | spaces.MultiBinary)
        and type(value) is np.ndarray
        and value.dtype == space.dtype
        and value.shape == space.shape
    )


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
@pytest.mark.parametrize("space", ALL_SPACES)
def test_compile_check_refuses_bad_values_of_the_catalog_as_check_does(
    space: spaces.Space,
) -> None:
    compiled = compile_check(space)
    for value in _bad_values(space):
        verdict, refusal = _assert_agree(space, value)
        assert verdict == "refused", f"{value!r:.100} was accepted"
        assert refusal.startswith("action")
        if _exact_arrays(value, space):  # the same value in packed form
            with pytest.raises(SpaceMismatch) as info:
                compiled(value.tobytes())
            assert str(info.value) == refusal


@pytest.mark.parametrize("space", ALL_SPACES)
def test_compile_check_refuses_packed_bytes_of_the_wrong_size(space: spaces.Space) -> None:
    codec = codec_for(space)
    good = codec.pack(_samples(space)[0])
    compiled = compile_check(space)
    cases = _wrong_sizes(space, good)
    assert cases or isinstance(space, spaces.Discrete)
    for path, size, length, wrong in cases:
        with pytest.raises(SpaceMismatch) as info:
            compiled(wrong)
        message = str(info.value)
        assert message.startswith(f"{path} is {length} bytes, expected {size}: "), message
        assert "the packed form of shape " in message


def _wrong_sizes(
    space: spaces.Space, good: Any, path: str = "action"
) -> list[tuple[str, int, int, Any]]:
    """The packed ``good`` with one array's bytes of the wrong size.

    As (the array's path, its expected size, its wrong size, the whole value).
    """
    if isinstance(space, spaces.Discrete):
        return []
    if isinstance(space, spaces.Tuple):
        return [
            (where, size, length, [*good[:index], wrong, *good[index + 1 :]])
            for index, item in enumerate(space.spaces)
            for where, size, length, wrong in _wrong_sizes(item, good[index], f"{path}[{index}]")
        ]
    if isinstance(space, spaces.Dict):
        return [
            (where, size, length, {**good, key: wrong})
            for key, item in space.spaces.items()
            for where, size, length, wrong in _wrong_sizes(item, good[key], f"{path}[{key!r}]")
        ]
    size = int(np.prod(space.shape)) * space.dtype.itemsize
    assert len(good) == size
    return [
        (path, size, len(wrong), wrong)
        for wrong in (b"", good[:-1], good + b"\x00", good + good[: space.dtype.itemsize])
    ]


def test_compile_check_names_the_packed_form_it_expected() -> None:
    with pytest.raises(SpaceMismatch) as info:
        compile_check(_NESTED)({**_GOOD_NESTED, "pos": b"\x00" * 4})
    assert str(info.value) == (
        "action['pos'] is 4 bytes, expected 8: the packed form of shape (2,) and dtype float32"
    )


def test_compile_check_of_packed_bytes_matches_check_for_random_actions() -> None:
    """Not a timing test: the fast path gives check's answer for many in-bounds actions."""
    space = spaces.Box(-1.0, 1.0, (1,), np.float32)
    compiled = compile_check(space)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1.0, 1.0, size=(1000, 1)).astype(np.float32)
    actions[:2] = [[-1.0], [1.0]]  # the bounds themselves are inside
    for action in actions:
        expected = check(space, action)
        for value in (action.tobytes(), unpack(pack(action.tobytes())), action):
            got = compiled(value)
            assert type(got) is np.ndarray and got.dtype == np.float32 and got.shape == (1,)
            assert got.tobytes() == expected.tobytes()
            assert space.contains(got)


# --- find_non_finite -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "where"),
    [
        (np.array([1.0, np.nan]), "[1]"),
        (np.array([[1, 2], [3, np.inf]], np.float32), "[1, 1]"),
        (np.array([3e38, 3e38], np.float32), None),  # huge but finite: no false alarm
        (np.array([1e308, 1e308]), None),
        (np.array([1 + 1j, complex(np.nan, 0)], np.complex64), "[1]"),
        (np.array([1, 2], np.int64), None),
        ({"pos": [0.5, float("-inf")]}, "['pos'][1]"),
        ((1.0, np.float32(np.nan)), "[1]"),
        (float("nan"), ""),
        ("text", None),
    ],
)
def test_find_non_finite_names_the_first_bad_element(value: object, where: str | None) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert find_non_finite(value) == where
