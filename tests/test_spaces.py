"""Tests of rlenv.spaces: space specs, checking values against spaces, rebuilding values."""

from __future__ import annotations

import math
import re
import warnings

import numpy as np
import pytest
from gymnasium import spaces
from spaces_catalog import TESTING_SPACES

from rlenv.protocol import pack, unpack
from rlenv.spaces import SpaceMismatch, check, from_wire, space_from_spec, space_to_spec

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
    assert spec == {"type": "Dict", "spaces": {"a": {"type": "Discrete", "n": 3, "start": 2}}}
    assert type(spec["spaces"]["a"]["n"]) is int


def test_different_spaces_give_different_specs() -> None:
    a = space_from_spec(space_to_spec(spaces.Discrete(3)))
    b = space_from_spec(space_to_spec(spaces.Discrete(3, start=1)))
    assert a != b
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
    """Exact structural equality of two values of a space (arrays compared bit for bit)."""
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


@pytest.mark.parametrize(
    ("space", "value", "message"),
    [
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
        (spaces.Discrete(5), np.array([1]), "action must be an integer, got ndarray"),
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
    ],
)
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


# --- from_wire -------------------------------------------------------------------------------


def test_from_wire_rebuilds_native_types() -> None:
    space = spaces.Tuple(
        (
            spaces.Discrete(4),
            spaces.Box(-1.0, 1.0, (2,), np.float32),
            spaces.Dict({"m": spaces.MultiDiscrete([2, 2]), "b": spaces.MultiBinary(2)}),
        )
    )
    value = from_wire(space, [3, [0.5, -0.5], {"m": [1, 0], "b": [0, 1]}])
    assert type(value) is tuple and len(value) == 3
    assert isinstance(value[0], np.integer) and type(value[0]) is np.int64 and value[0] == 3
    assert isinstance(value[1], np.ndarray) and value[1].dtype == np.float32
    assert value[1].tolist() == [0.5, -0.5]
    assert type(value[2]) is dict
    assert value[2]["m"].dtype == np.int64 and value[2]["m"].tolist() == [1, 0]
    assert value[2]["b"].dtype == np.int8 and value[2]["b"].tolist() == [0, 1]
    assert space.contains(value)


def test_from_wire_box_from_list_has_space_dtype() -> None:
    for dtype in (np.float32, np.float64, np.int32, np.uint8):
        space = spaces.Box(0, 10, (3,), dtype)
        value = from_wire(space, [1, 2, 3])
        assert isinstance(value, np.ndarray)
        assert value.dtype == dtype
        assert value.tolist() == [1, 2, 3]


def test_from_wire_scalar_box_and_discrete() -> None:
    box = from_wire(spaces.Box(-1.0, 1.0, (), np.float32), 0.5)
    assert isinstance(box, np.ndarray) and box.shape == () and box.dtype == np.float32
    disc = from_wire(spaces.Discrete(3, start=5), 6)
    assert isinstance(disc, np.integer) and disc == 6


def test_from_wire_gives_writable_arrays_as_gymnasium_does() -> None:
    space = spaces.Box(-1.0, 1.0, (2, 2), np.float32)
    wire = unpack(pack(np.zeros((2, 2), np.float32)))
    assert not wire.flags.writeable  # decoded in place from the frame
    value = from_wire(space, wire)
    assert value.flags.writeable and not np.shares_memory(value, wire)
    assert np.array_equal(value, wire)
    mine = np.ones((2, 2), np.float32)
    assert from_wire(space, mine) is mine  # an array that is already writable is kept


@pytest.mark.parametrize("space", ALL_SPACES)
def test_from_wire_of_samples_after_round_trip(space: spaces.Space) -> None:
    for sample in _samples(space):
        value = from_wire(space, unpack(pack(sample)))
        assert space.contains(value)
        _assert_same_value(value, sample)


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
    from rlenv.spaces import find_non_finite

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert find_non_finite(value) == where
