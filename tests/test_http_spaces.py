"""Spaces, JSON Schemas and values as the HTTP gateway writes them; its PNG encoder."""

from __future__ import annotations

import base64
import json
import math

import jsonschema
import numpy as np
import pytest
from gymnasium import spaces
from http_gateway import decode_png
from spaces_catalog import TESTING_SPACES

from rlenv_tools.http._png import encode_png
from rlenv_tools.http.json_spaces import (
    action_decoder,
    dumps,
    is_image,
    json_schema,
    space_from_json,
    space_to_json,
    to_json,
    value_encoder,
)


@pytest.mark.parametrize("space", TESTING_SPACES, ids=str)
def test_spaces_round_trip_through_json(space: spaces.Space) -> None:
    described = json.loads(json.dumps(space_to_json(space), allow_nan=False))
    assert space_from_json(described) == space


@pytest.mark.parametrize("space", TESTING_SPACES, ids=str)
def test_every_value_matches_its_schema_and_outsiders_do_not(space: spaces.Space) -> None:
    schema = json_schema(space)
    jsonschema.Draft202012Validator.check_schema(schema)
    encode = value_encoder(space)
    space.seed(0)
    for _ in range(20):
        value = json.loads(dumps(encode(space.sample())))
        jsonschema.validate(value, schema)
    if not is_image(space):  # actions: the same schema, images as lists
        assert json_schema(space, images=False) == schema
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(
            {"not": "a value"} if not isinstance(space, spaces.Dict) else [], schema
        )


def test_a_box_is_described_in_gymnasium_terms() -> None:
    box = spaces.Box(np.array([-1.0, -np.inf], np.float32), np.array([1.0, np.inf], np.float32))
    assert space_to_json(box) == {
        "type": "Box",
        "shape": [2],
        "low": [-1.0, "-Infinity"],
        "high": [1.0, "Infinity"],
        "dtype": "float32",
    }
    assert space_to_json(spaces.Box(0, 255, (2, 3), np.uint8)) == {
        "type": "Box",
        "shape": [2, 3],
        "low": 0,
        "high": 255,
        "dtype": "uint8",
    }
    assert space_to_json(spaces.Discrete(3, start=-1)) == {
        "type": "Discrete",
        "n": 3,
        "start": -1,
        "dtype": "int64",
    }
    assert json_schema(box) == {
        "type": "array",
        "prefixItems": [{"type": "number", "minimum": -1.0, "maximum": 1.0}, {"type": "number"}],
        "items": False,
        "minItems": 2,
        "maxItems": 2,
    }


def test_images_travel_as_png_and_actions_as_lists() -> None:
    space = spaces.Box(0, 255, (4, 5, 3), np.uint8)
    image = np.arange(60, dtype=np.uint8).reshape(4, 5, 3)
    text = value_encoder(space)(image)
    assert np.array_equal(decode_png(base64.b64decode(text)), image)
    assert value_encoder(space, images=False)(image) == image.tolist()
    assert json_schema(space)["contentMediaType"] == "image/png"
    assert json_schema(space, images=False)["items"]["items"]["items"]["maximum"] == 255
    assert np.array_equal(decode_png(base64.b64decode(to_json({"frame": image})["frame"])), image)


def test_values_json_lacks_are_converted() -> None:
    info = {
        "nan": math.nan,
        "arrays": np.array([1.0, np.inf]),
        "scalar": np.float32(0.5),
        "bytes": b"\x00\x01",
        3: (np.int64(2), True),
        "none": None,
    }
    assert json.loads(dumps(info)) == {
        "nan": "NaN",
        "arrays": [1.0, "Infinity"],
        "scalar": 0.5,
        "bytes": "AAE=",
        "3": [2, True],
        "none": None,
    }
    assert dumps({"plain": [1, 2.5]}) == b'{"plain":[1,2.5]}'


def test_json_actions_become_arrays_only_when_the_check_would_convert_them() -> None:
    decode = action_decoder(spaces.Box(-1.0, 1.0, (2,), np.float32))
    decoded = decode([0.5, -1])
    assert decoded.dtype == np.float32 and decoded.tolist() == [0.5, -1.0]
    for unchanged in ([0.5], [True, 0.5], ["0.5", 0.5], [1e300, 0.0], "left", None):
        assert decode(unchanged) is unchanged  # for the environment to refuse precisely
    grid = action_decoder(spaces.Box(-1.0, 1.0, (2, 2), np.float64))
    assert grid([[0, 1], [1, 0]]).dtype == np.float64
    assert grid([[0, 1], [1]]) == [[0, 1], [1]]
    joint = action_decoder(
        spaces.Dict({"a": spaces.Box(-1.0, 1.0, (1,), np.float32), "b": spaces.Discrete(2)})
    )
    decoded = joint({"a": [0.25], "b": 1})
    assert decoded["a"].dtype == np.float32 and decoded["b"] == 1
    integers = action_decoder(spaces.Box(0, 255, (1,), np.uint8))
    assert integers([300]) == [300]  # never cast where a cast could wrap


def test_space_descriptions_that_are_not_spaces_are_refused() -> None:
    for bad in (
        [],
        {"type": "Box"},
        {"type": "Nope"},
        {"type": "Box", "shape": [1], "low": 0, "high": 1, "dtype": "object"},
    ):
        with pytest.raises(ValueError):
            space_from_json(bad)


@pytest.mark.parametrize("shape", [(3, 4), (3, 4, 1), (2, 7, 2), (5, 1, 3), (1, 1, 4)])
def test_png_encodes_every_channel_count(shape: tuple[int, ...]) -> None:
    image = np.random.default_rng(0).integers(0, 256, shape, dtype=np.uint8)
    decoded = decode_png(encode_png(image))
    assert np.array_equal(decoded.reshape(image.shape), image)


def test_png_refuses_what_is_not_an_image() -> None:
    for bad in (
        np.zeros((2, 2, 3), np.float32),
        np.zeros((2, 2, 5), np.uint8),
        np.zeros((0, 2, 3), np.uint8),
        np.zeros(4, np.uint8),
    ):
        with pytest.raises(ValueError):
            encode_png(bad)


@pytest.mark.parametrize("space", TESTING_SPACES, ids=str)
def test_the_gateway_and_onnx_policies_read_each_others_space(space: spaces.Space) -> None:
    from rlenv.protocol import space_json
    from rlenv.serving import onnx_policy
    from rlenv_tools import policies

    assert space_json.space_from_json is onnx_policy.space_from_json  # what a policy file reads
    assert space_json.space_to_json_text is policies.space_to_json_text  # what export_onnx writes
    served = json.loads(dumps({"space": space_to_json(space)}))["space"]  # the gateway's
    assert space_json.space_from_json(served) == space  # read as a policy's file is
    stored = space_json.space_to_json_text(space)  # as export_onnx stores it
    assert space_from_json(json.loads(stored)) == space == space_from_json(stored)
    assert json.loads(stored) == served  # one form


def test_the_specs_that_rlenv_0_1s_policies_hold_are_read() -> None:
    from rlenv.protocol.space_json import space_from_json as read

    assert read(
        '{"type": "Box", "dtype": "<f4", "low": ["-inf", "-inf"], "high": [1.0, 1.0]}'
    ) == spaces.Box(-np.inf, 1.0, (2,), np.float32)
    assert read('{"type": "Discrete", "n": 3, "start": -1, "dtype": "<i8"}') == spaces.Discrete(
        3, start=-1
    )
    assert read(
        '{"type": "MultiDiscrete", "dtype": "<i8", "nvec": [2, 3], "start": [0, 0]}'
    ) == spaces.MultiDiscrete([2, 3])
    with pytest.raises(ValueError, match="not a space in JSON"):
        read("{not json")


def test_the_old_names_in_protocol_spaces_warn_and_keep_their_text() -> None:
    from rlenv.protocol import space_json
    from rlenv.protocol import spaces as protocol_spaces

    with pytest.warns(DeprecationWarning, match="moved to rlenv.protocol.space_json.space_to_"):
        old_writer = protocol_spaces.space_to_json
    with pytest.warns(DeprecationWarning, match="moved to rlenv.protocol.space_json.space_from"):
        old_reader = protocol_spaces.space_from_json
    box = spaces.Box(0.0, 1.0, (3,), np.float32)
    assert old_writer is space_json.space_to_json_text and isinstance(old_writer(box), str)
    assert old_reader(old_writer(box)) == box
