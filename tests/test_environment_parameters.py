"""ML-Agents' environment_parameters: configs as ML-Agents writes them, samplers, lessons."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rlenv_client import Client
from rlenv_client.curriculum import (
    EnvironmentParameters,
    EnvironmentParametersError,
    configurable_keys,
    configure_arguments,
)
from tests.conftest import Serve

SECTION = """\
difficulty:
  sampler_type: uniform
  sampler_parameters:
    min_value: 0.1
    max_value: 0.4
agent.max_speed:
  curriculum:
    - name: Slow
      completion_criteria:
        measure: reward
        behavior: Catcher
        signal_smoothing: true
        min_lesson_length: 100
        threshold: 0.8
        require_reset: false
      value: 2.0
    - name: Fast
      value:
        sampler_type: multirangeuniform
        sampler_parameters:
          intervals: [[4.0, 5.0], [7.0, 8.0]]
"""

WHOLE = """\
behaviors:
  Catcher:
    trainer_type: ppo
    hyperparameters:
      batch_size: 64
    max_steps: 500000
environment_parameters:
""" + textwrap.indent(SECTION, "  ")

PLINKO_KEYS = {"environment.repeat_action", "agent.max_speed", "world.difficulty"}


def curriculum(*lessons: dict[str, Any], name: str = "world.difficulty") -> dict[str, Any]:
    """A section with one curriculum parameter."""
    return {name: {"curriculum": list(lessons)}}


def criteria(**given: Any) -> dict[str, Any]:
    """completion_criteria of behavior Catcher, over ``given``."""
    return {"behavior": "Catcher", **given}


def draws(parameters: EnvironmentParameters, key: str, count: int) -> np.ndarray:
    """``count`` values of ``key`` from ``parameters.sample()``."""
    return np.array([parameters.sample()[key] for _ in range(count)])


@pytest.mark.parametrize(
    "form",
    ["yaml whole", "yaml section", "yaml file", "yaml file str", "dict whole", "dict section"],
)
def test_every_form_of_an_ml_agents_config_gives_the_same_parameters(
    form: str, tmp_path: Path
) -> None:
    import yaml

    file = tmp_path / "trainer_config.yaml"
    file.write_text(WHOLE)
    source: Any = {
        "yaml whole": WHOLE,
        "yaml section": SECTION,
        "yaml file": file,
        "yaml file str": str(file),
        "dict whole": yaml.safe_load(WHOLE),
        "dict section": yaml.safe_load(SECTION),
    }[form]
    build = EnvironmentParameters if form.startswith("dict") else EnvironmentParameters.from_yaml
    parameters = build(source, seed=7)
    reference = EnvironmentParameters.from_yaml(SECTION, seed=7)
    for each in (parameters, reference):
        each.bind(PLINKO_KEYS)
    assert parameters.names == ("difficulty", "agent.max_speed")
    assert parameters.lesson("agent.max_speed") == "Slow"
    assert parameters.lesson("difficulty") == "difficulty"  # a sampler is one lesson, as ML-Agents
    samples = [parameters.sample() for _ in range(5)]
    assert samples == [reference.sample() for _ in range(5)]
    assert set(samples[0]) == {"world.difficulty", "agent.max_speed"}
    assert samples[0]["agent.max_speed"] == 2.0
    assert len({sample["world.difficulty"] for sample in samples}) == 5


def test_without_pyyaml_dicts_work_and_yaml_says_what_to_install(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(sys.modules, "yaml", None)  # import yaml raises ImportError
    with pytest.raises(ImportError, match="pip install pyyaml"):
        EnvironmentParameters.from_yaml(SECTION)
    parameters = EnvironmentParameters({"world.difficulty": 0.3})
    assert parameters.sample() == {"world.difficulty": 0.3}


def test_yaml_that_is_not_a_map_is_refused() -> None:
    with pytest.raises(EnvironmentParametersError, match="names no existing file"):
        EnvironmentParameters.from_yaml("missing_config.yaml")


def test_uniform_draws_cover_its_range_and_stay_in_it() -> None:
    parameters = EnvironmentParameters(
        {
            "world.difficulty": {
                "sampler_type": "uniform",
                "sampler_parameters": {"min_value": 0.1, "max_value": 0.4},
            }
        },
        seed=1,
    )
    values = draws(parameters, "world.difficulty", 5000)
    assert values.min() >= 0.1 and values.max() <= 0.4
    assert values.min() < 0.101 and values.max() > 0.399
    assert abs(values.mean() - 0.25) < 0.01


def test_gaussian_draws_have_its_mean_and_deviation() -> None:
    parameters = EnvironmentParameters(
        {
            "world.difficulty": {
                "sampler_type": "gaussian",
                "sampler_parameters": {"mean": 2.0, "st_dev": 0.5},
            }
        },
        seed=1,
    )
    values = draws(parameters, "world.difficulty", 20000)
    assert abs(values.mean() - 2.0) < 0.02
    assert abs(values.std() - 0.5) < 0.02


def test_multirangeuniform_draws_fall_in_its_intervals_by_their_length() -> None:
    parameters = EnvironmentParameters(
        {
            "world.difficulty": {
                "sampler_type": "multirangeuniform",
                "sampler_parameters": {"intervals": [[0.0, 1.0], [10, 13]]},
            }
        },
        seed=1,
    )
    values = draws(parameters, "world.difficulty", 8000)
    low, high = values[values <= 1.0], values[values >= 10.0]
    assert len(low) + len(high) == len(values)
    assert high.max() <= 13.0 and high.min() < 10.01 and low.max() > 0.99
    assert abs(len(high) / len(values) - 0.75) < 0.02  # 3 of the 4 units of length


def test_constant_and_plain_values_are_given_as_written() -> None:
    parameters = EnvironmentParameters(
        {
            "world.difficulty": {"sampler_type": "constant", "sampler_parameters": {"value": 0.7}},
            "environment.repeat_action": 2,
        },
        seed=1,
    )
    for _ in range(3):
        sample = parameters.sample()
        assert sample == {"world.difficulty": 0.7, "environment.repeat_action": 2}
        assert type(sample["environment.repeat_action"]) is int


def test_a_seed_gives_the_same_draws_and_a_sampler_seed_its_own() -> None:
    config = {
        "world.difficulty": {
            "sampler_type": "gaussian",
            "sampler_parameters": {"mean": 0.0, "st_dev": 1.0},
        },
        "agent.max_speed": {
            "sampler_type": "uniform",
            "sampler_parameters": {"min_value": 1, "max_value": 9, "seed": 42},
        },
    }
    first, again, other = (EnvironmentParameters(config, seed=s) for s in (3, 3, 4))
    a, b, c = ([p.sample() for _ in range(20)] for p in (first, again, other))
    assert a == b
    assert [s["world.difficulty"] for s in a] != [s["world.difficulty"] for s in c]
    assert [s["agent.max_speed"] for s in a] == [s["agent.max_speed"] for s in c]


def test_reward_lessons_advance_on_the_mean_of_the_last_min_lesson_length_episodes() -> None:
    parameters = EnvironmentParameters(
        curriculum(
            {
                "name": "Easy",
                "value": 0.1,
                "completion_criteria": criteria(
                    threshold=0.9, min_lesson_length=2, signal_smoothing=False
                ),
            },
            {
                "name": "Hard",
                "value": 0.8,
                "completion_criteria": criteria(
                    threshold=0.5, min_lesson_length=3, signal_smoothing=False
                ),
            },
            {"name": "Last", "value": 1.0},
        )
    )
    assert parameters.add_episode(1.0) is False  # 1 episode < min_lesson_length 2
    assert parameters.add_episode(0.0) is False  # last 2: [1, 0], mean 0.5
    assert parameters.add_episode(1.0) is False  # [0, 1]: 0.5, not > 0.9
    assert parameters.add_episode(1.0) is True  # [1, 1]: 1.0
    assert parameters.lesson("world.difficulty") == "Hard"
    assert parameters.sample() == {"world.difficulty": 0.8}
    # The change emptied the rewards: Hard counts 3 episodes of its own.
    assert [parameters.add_episode(1.0) for _ in range(3)] == [False, False, True]
    assert parameters.lesson("world.difficulty") == "Last"
    assert [parameters.add_episode(1.0) for _ in range(3)] == [False] * 3  # the last never ends


def test_the_mean_is_over_the_window_not_the_whole_lesson() -> None:
    parameters = EnvironmentParameters(
        curriculum(
            {
                "name": "Easy",
                "value": 0.1,
                "completion_criteria": criteria(
                    threshold=0.9, min_lesson_length=2, signal_smoothing=False
                ),
            },
            {"name": "Last", "value": 1.0},
        )
    )
    # The window is 2: [0, 0] 0; [0, 1] 0.5; [1, 1] 1.0 > 0.9 (the lesson's mean is only 0.5).
    assert [parameters.add_episode(r) for r in (0.0, 0.0, 1.0, 1.0)] == [False, False, False, True]


def test_signal_smoothing_as_ml_agents_computes_it() -> None:
    lessons = (
        {
            "name": "Easy",
            "value": 0.1,
            "completion_criteria": criteria(threshold=0.8, min_lesson_length=2),
        },
        {"name": "Last", "value": 1.0},
    )
    smoothed = EnvironmentParameters(curriculum(*lessons))
    # Episode 2: mean 1, smoothed 0.25 * 0 + 0.75 * 1 = 0.75, not > 0.8; episode 3: mean 1,
    # smoothed 0.25 * 0.75 + 0.75 = 0.9375 > 0.8.
    assert [smoothed.add_episode(1.0) for _ in range(3)] == [False, False, True]
    plain = {
        **lessons[0],
        "completion_criteria": criteria(threshold=0.8, min_lesson_length=2, signal_smoothing=False),
    }
    unsmoothed = EnvironmentParameters(curriculum(plain, lessons[1]))
    assert [unsmoothed.add_episode(1.0) for _ in range(2)] == [False, True]


def test_smoothing_carries_a_low_start() -> None:
    parameters = EnvironmentParameters(
        curriculum(
            {
                "name": "Easy",
                "value": 0.1,
                "completion_criteria": criteria(threshold=0.6, min_lesson_length=1),
            },
            {"name": "Last", "value": 1.0},
        )
    )
    # smoothed: 0.75 * 0 = 0; 0.25 * 0 + 0.75 * 1 = 0.75 > 0.6.
    assert [parameters.add_episode(r) for r in (0.0, 1.0)] == [False, True]
    again = EnvironmentParameters(
        curriculum(
            {
                "name": "Easy",
                "value": 0.1,
                "completion_criteria": criteria(threshold=0.7, min_lesson_length=1),
            },
            {"name": "Last", "value": 1.0},
        )
    )
    # 0.75 * 0.5 = 0.375; 0.25 * 0.375 + 0.75 * 0.8 = 0.69375, not > 0.7; then
    # 0.25 * 0.69375 + 0.75 * 0.8 = 0.7734 > 0.7.
    assert [again.add_episode(r) for r in (0.5, 0.8, 0.8)] == [False, False, True]


def test_progress_lessons_advance_past_their_threshold() -> None:
    parameters = EnvironmentParameters(
        curriculum(
            {
                "name": "First",
                "value": 0.1,
                "completion_criteria": criteria(
                    measure="progress", threshold=0.3, min_lesson_length=2
                ),
            },
            {
                "name": "Second",
                "value": 0.5,
                "completion_criteria": criteria(measure="progress", threshold=0.6),
            },
            {"name": "Last", "value": 0.9},
        )
    )
    assert parameters.add_episode(-5.0, progress=0.5) is False  # 1 episode < 2
    assert parameters.add_episode(-5.0, progress=0.3) is False  # not > 0.3
    assert parameters.add_episode(-5.0, progress=0.31) is True  # whatever the reward
    assert parameters.lesson("world.difficulty") == "Second"
    assert parameters.add_episode(0.0, progress=0.6) is False
    assert parameters.add_episode(0.0, progress=0.61) is True
    assert parameters.sample() == {"world.difficulty": 0.9}


def test_a_progress_lesson_without_progress_is_refused_and_counts_nothing() -> None:
    parameters = EnvironmentParameters(
        curriculum(
            {
                "name": "First",
                "value": 0.1,
                "completion_criteria": criteria(
                    measure="progress", threshold=0.3, min_lesson_length=2
                ),
            },
            {"name": "Last", "value": 0.9},
        )
    )
    with pytest.raises(ValueError, match="'First' measures progress"):
        parameters.add_episode(1.0)
    with pytest.raises(ValueError, match=r"progress must be in \[0, 1\]"):
        parameters.add_episode(1.0, progress=1.5)
    with pytest.raises(ValueError, match="reward must be finite"):
        parameters.add_episode(float("nan"), progress=0.5)
    assert parameters.lesson("world.difficulty") == "First"
    assert parameters.add_episode(1.0, progress=0.5) is False  # the first episode counted
    assert parameters.add_episode(1.0, progress=0.5) is True


def test_episodes_count_for_their_behavior() -> None:
    parameters = EnvironmentParameters(
        {
            "behaviors": {"Catcher": {}, "Thrower": {}},
            "environment_parameters": {
                **curriculum(
                    {
                        "name": "A0",
                        "value": 0.1,
                        "completion_criteria": criteria(threshold=0.5, signal_smoothing=False),
                    },
                    {"name": "A1", "value": 0.2},
                ),
                **curriculum(
                    {
                        "name": "B0",
                        "value": 1.0,
                        "completion_criteria": {
                            "behavior": "Thrower",
                            "threshold": 0.5,
                            "signal_smoothing": False,
                        },
                    },
                    {"name": "B1", "value": 2.0},
                    name="agent.max_speed",
                ),
            },
        }
    )
    assert parameters.add_episode(1.0, behavior="Thrower") is True
    assert (parameters.lesson("world.difficulty"), parameters.lesson("agent.max_speed")) == (
        "A0",
        "B1",
    )
    with pytest.raises(ValueError, match="no completion_criteria names behavior 'Pitcher'"):
        parameters.add_episode(1.0, behavior="Pitcher")
    assert parameters.add_episode(1.0) is True  # None: every behavior's episode
    assert parameters.lesson("world.difficulty") == "A1"


@pytest.mark.parametrize("require_reset", [True, False])
def test_require_reset_tells_the_caller_to_reset_now(require_reset: bool) -> None:
    parameters = EnvironmentParameters(
        curriculum(
            {
                "name": "Easy",
                "value": 0.1,
                "completion_criteria": criteria(threshold=0.5, require_reset=require_reset),
            },
            {"name": "Last", "value": 0.9},
        )
    )
    assert parameters.reset_required is False
    assert parameters.add_episode(1.0) is True
    assert parameters.reset_required is require_reset
    assert parameters.sample() == {"world.difficulty": 0.9}  # the values for that reset
    assert parameters.reset_required is False


def test_bare_names_resolve_to_the_one_setting_that_offers_them() -> None:
    parameters = EnvironmentParameters(
        {"difficulty": 0.2, "max_speed": 3.0, "environment.repeat_action": 2}
    )
    with pytest.raises(EnvironmentParametersError, match="'difficulty' is a bare name: call bind"):
        parameters.sample()
    parameters.bind(PLINKO_KEYS)
    assert parameters.key("max_speed") == "agent.max_speed"
    assert parameters.sample() == {
        "world.difficulty": 0.2,
        "agent.max_speed": 3.0,
        "environment.repeat_action": 2,
    }


@pytest.mark.parametrize(
    ("config", "keys", "message"),
    [
        (
            {"speed": 1.0},
            {"agent.speed", "world.speed", "world.difficulty"},
            "'speed' is ambiguous: it could be agent.speed, world.speed",
        ),
        (
            {"gravity": 1.0},
            PLINKO_KEYS,
            "'gravity' names no configurable setting; the environment "
            "offers agent.max_speed, environment.repeat_action, world.difficulty",
        ),
        ({"world.gravity": 1.0}, PLINKO_KEYS, "'world.gravity' names no configurable setting"),
        (
            {"difficulty": 1.0, "world.difficulty": 0.5},
            PLINKO_KEYS,
            "'difficulty' and 'world.difficulty' both set world.difficulty",
        ),
    ],
)
def test_unknown_or_ambiguous_names_are_refused(
    config: dict[str, Any], keys: set[str], message: str
) -> None:
    with pytest.raises(EnvironmentParametersError, match=message):
        EnvironmentParameters(config).bind(keys)


def test_configure_arguments_nest_keys_as_configure_takes_them() -> None:
    assert configure_arguments(
        {"world.difficulty": 0.37, "agent.max_speed": 3.0, "environment.repeat_action": 4}
    ) == {"world": {"difficulty": 0.37}, "agent": {"max_speed": 3.0}, "repeat_action": 4}
    with pytest.raises(ValueError, match="'difficulty' is not a configure key"):
        configure_arguments({"difficulty": 0.3})


def sampler(kind: str, **parameters: Any) -> dict[str, Any]:
    """A sampler as ML-Agents writes it."""
    return {"sampler_type": kind, "sampler_parameters": parameters}


P = "environment_parameters.d"
LAST = {"name": "Last", "value": 1.0}


@pytest.mark.parametrize(
    ("section", "message"),
    [
        (
            {"d": sampler("triangular", low=0)},
            f"{P}.sampler_type: unknown sampler 'triangular'; "
            "ML-Agents' are uniform, gaussian, multirangeuniform, constant",
        ),
        ({"d": sampler("uniform", max_value=1.0)}, f"{P}.sampler_parameters has no min_value"),
        (
            {"d": sampler("uniform", min_value=2, max_value=1.0)},
            rf"{P}.sampler_parameters.min_value \(2.0\) is greater than max_value \(1.0\)",
        ),
        (
            {"d": sampler("uniform", min_value=0, max_value=1, maximum=3)},
            f"{P}.sampler_parameters.maximum: unknown key",
        ),
        ({"d": sampler("gaussian", mean=0)}, f"{P}.sampler_parameters has no st_dev"),
        (
            {"d": sampler("gaussian", mean=0, st_dev=-1)},
            f"{P}.sampler_parameters.st_dev must be >= 0",
        ),
        (
            {"d": sampler("multirangeuniform", intervals=[[0, 1], [3, 2]])},
            rf"{P}.sampler_parameters.intervals\[1\]: min \(3.0\) is greater than max \(2.0\)",
        ),
        (
            {"d": sampler("multirangeuniform", intervals=[[0, 1, 2]])},
            rf"{P}.sampler_parameters.intervals\[0\] must be \[min, max\]",
        ),
        ({"d": sampler("constant")}, f"{P}.sampler_parameters has no value"),
        ({"d": {"sampler_type": "uniform"}}, f"{P} has no sampler_parameters"),
        ({"d": "hard"}, f"{P} must be a number or a sampler"),
        ({"d": {"curriculum": []}}, f"{P}.curriculum must be a non-empty list of lessons"),
        (
            {"d": {"curriculum": [{"name": "A", "completion_criteria": criteria()}, LAST]}},
            rf"{P}.curriculum\[0\] has no value",
        ),
        (
            {"d": {"curriculum": [{"name": "A", "value": 0.1}, LAST]}},
            rf"{P}.curriculum\[0\].completion_criteria is missing",
        ),
        (
            {"d": {"curriculum": [{**LAST, "completion_criteria": criteria()}]}},
            rf"{P}.curriculum\[0\].completion_criteria: the last lesson has none",
        ),
        (
            {
                "d": {
                    "curriculum": [
                        {
                            "name": "A",
                            "value": 0.1,
                            "completion_criteria": criteria(measure="entropy"),
                        },
                        LAST,
                    ]
                }
            },
            rf"{P}.curriculum\[0\].completion_criteria.measure must be reward or progress",
        ),
        (
            {
                "d": {
                    "curriculum": [
                        {
                            "name": "A",
                            "value": 0.1,
                            "completion_criteria": criteria(min_lesson_length=-1),
                        },
                        LAST,
                    ]
                }
            },
            rf"{P}.curriculum\[0\].completion_criteria.min_lesson_length must be an integer >= 0",
        ),
        (
            {
                "d": {
                    "curriculum": [
                        {
                            "name": "A",
                            "value": 0.1,
                            "completion_criteria": criteria(measure="progress", threshold=1.5),
                        },
                        LAST,
                    ]
                }
            },
            r"threshold must be in \[0, 1\] when the measure is progress",
        ),
        (
            {
                "d": {
                    "curriculum": [
                        {"name": "A", "value": 0.1, "completion_criteria": {"threshold": 0.5}},
                        LAST,
                    ]
                }
            },
            rf"{P}.curriculum\[0\].completion_criteria has no behavior",
        ),
        (
            {
                "d": {
                    "curriculum": [
                        {
                            "name": "A",
                            "value": 0.1,
                            "completion_criteria": criteria(signal_smoothing="yes"),
                        },
                        LAST,
                    ]
                }
            },
            "signal_smoothing must be true or false",
        ),
        (
            {"d": {"curriculum": [{"name": "A", "value": sampler("uniform", min_value=0)}]}},
            rf"{P}.curriculum\[0\].value.sampler_parameters has no max_value",
        ),
    ],
)
def test_invalid_configs_are_refused_naming_the_key(section: dict[str, Any], message: str) -> None:
    with pytest.raises(EnvironmentParametersError, match=message):
        EnvironmentParameters(section)


def test_a_behavior_the_whole_config_lacks_is_refused() -> None:
    with pytest.raises(
        EnvironmentParametersError,
        match=r"completion_criteria.behavior: 'Catcher' is not in behaviors "
        r"\(Thrower\)",
    ):
        EnvironmentParameters(
            {
                "behaviors": {"Thrower": {}},
                "environment_parameters": curriculum(
                    {"name": "A", "value": 0.1, "completion_criteria": criteria()}, LAST
                ),
            }
        )


def test_sampled_values_configure_plinko_over_a_real_server(serve: Serve) -> None:
    server = serve("examples.plinko:PlinkoEnvironment")
    parameters = EnvironmentParameters.from_yaml(
        """\
environment_parameters:
  repeat_action: 2
  difficulty:
    curriculum:
      - name: Easy
        completion_criteria: {measure: reward, behavior: Catcher, threshold: 0.5,
                              min_lesson_length: 1, signal_smoothing: false}
        value: 0.1
      - name: Hard
        value: {sampler_type: uniform, sampler_parameters: {min_value: 0.6, max_value: 0.9}}
""",
        seed=5,
    )
    with Client(server.host, server.port, timeout=30) as client:
        tree = client.tree()
        parameters.bind(configurable_keys(tree))
        assert parameters.key("difficulty") == "world.difficulty"
        environment = next(node["path"] for node in tree if node.get("config") == "environment")
        for lesson in ("Easy", "Hard"):
            values = parameters.sample()
            client.configure(**configure_arguments(values))
            client.reset(seed=1)
            assert parameters.lesson("difficulty") == lesson
            assert client.get_property("World", "difficulty") == values["world.difficulty"]
            assert client.get_property(environment, "repeat_action") == 2
            parameters.add_episode(1.0)
        assert 0.6 <= values["world.difficulty"] <= 0.9
