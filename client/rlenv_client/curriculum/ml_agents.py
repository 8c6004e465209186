"""ML-Agents' ``environment_parameters`` as data: checked, and made into lessons to draw from.

:func:`read_parameter` reads one parameter of the section (a plain value, a sampler, or a curriculum
of lessons with their ``completion_criteria``), refusing what ML-Agents' format does not allow
with a message that names the key; :class:`Parameter` is the state a
:class:`~rlenv_client.curriculum.parameters.EnvironmentParameters` keeps of it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "SECTIONS",
    "Criteria",
    "Draw",
    "EnvironmentParametersError",
    "Lesson",
    "Parameter",
    "count_samplers",
    "finite",
    "names_file",
    "read_parameter",
]


SECTIONS = ("environment", "agent", "world")
"""The sections of a ``config`` request: the first part of a configure key."""

_MEASURES = ("reward", "progress")
_CRITERIA_KEYS = {
    "measure",
    "behavior",
    "threshold",
    "min_lesson_length",
    "signal_smoothing",
    "require_reset",
}

Draw = Callable[[np.random.Generator], float]


class EnvironmentParametersError(ValueError):
    """A config ML-Agents' format does not allow, or a parameter no setting matches.

    The message names the key (``environment_parameters.difficulty.sampler_parameters...``)
    or the parameter.
    """


@dataclass(frozen=True, slots=True)
class Criteria:
    """A lesson's ``completion_criteria``, with ML-Agents' defaults."""

    behavior: str
    measure: str = "reward"
    threshold: float = 0.0
    min_lesson_length: int = 0
    signal_smoothing: bool = True
    require_reset: bool = False


@dataclass(frozen=True, slots=True)
class Lesson:
    """A lesson: its name, how its value is drawn, and when it is complete (``None``: last)."""

    name: str
    draw: Draw
    rng: np.random.Generator
    criteria: Criteria | None


class Parameter:
    """A parameter's lessons (one, named after it, unless it is a curriculum) and its state."""

    __slots__ = ("name", "lessons", "index", "smoothed", "key")

    def __init__(self, name: str, lessons: list[Lesson]) -> None:
        self.name = name
        self.lessons = lessons
        self.index = 0
        self.smoothed = 0.0  # ML-Agents' smoothed measure, kept across lessons
        section = name.split(".", 1)[0]
        self.key: str | None = name if section in SECTIONS and "." in name else None

    @property
    def current(self) -> Lesson:
        """The lesson in force."""
        return self.lessons[self.index]


def count_samplers(section: Mapping[str, Any]) -> int:
    """How many generators a config's samplers need (one per lesson, at most)."""
    count = 0
    for value in section.values():
        curriculum = value.get("curriculum") if isinstance(value, Mapping) else None
        count += len(curriculum) if isinstance(curriculum, list) else 1
    return count


def read_parameter(
    name: str, value: Any, seeds: Any, behaviors: Mapping[str, Any] | None
) -> Parameter:
    """One parameter of the section: a plain value, a sampler or a curriculum."""
    where = f"environment_parameters.{name}"
    if not (isinstance(value, Mapping) and "curriculum" in value):
        draw, rng = _sampler(value, where, next(seeds))
        return Parameter(name, [Lesson(name, draw, rng, None)])
    _only(value, {"curriculum"}, where)
    curriculum = value["curriculum"]
    where = f"{where}.curriculum"
    if not isinstance(curriculum, list) or not curriculum:
        raise EnvironmentParametersError(f"{where} must be a non-empty list of lessons")
    lessons = []
    for index, lesson in enumerate(curriculum):
        at = f"{where}[{index}]"
        last = index == len(curriculum) - 1
        if not isinstance(lesson, Mapping):
            raise EnvironmentParametersError(
                f"{at} must be a map (name, value, completion_criteria)"
            )
        _only(lesson, {"name", "value", "completion_criteria"}, at)
        for required in ("name", "value"):
            if required not in lesson:
                raise EnvironmentParametersError(f"{at} has no {required}")
        criteria = lesson.get("completion_criteria")
        if criteria is None and not last:
            raise EnvironmentParametersError(
                f"{at}.completion_criteria is missing: every lesson but the last needs one"
            )
        if criteria is not None and last:
            raise EnvironmentParametersError(
                f"{at}.completion_criteria: the last lesson has none (it never ends)"
            )
        draw, rng = _sampler(lesson["value"], f"{at}.value", next(seeds))
        lessons.append(
            Lesson(
                str(lesson["name"]),
                draw,
                rng,
                None
                if criteria is None
                else _criteria(criteria, f"{at}.completion_criteria", behaviors),
            )
        )
    return Parameter(name, lessons)


def _criteria(data: Any, where: str, behaviors: Mapping[str, Any] | None) -> Criteria:
    """A ``completion_criteria`` map, checked."""
    if not isinstance(data, Mapping):
        raise EnvironmentParametersError(f"{where} must be a map")
    _only(data, _CRITERIA_KEYS, where)
    if "behavior" not in data:
        raise EnvironmentParametersError(f"{where} has no behavior")
    behavior = str(data["behavior"])
    if behaviors is not None and behavior not in behaviors:
        raise EnvironmentParametersError(
            f"{where}.behavior: {behavior!r} is not in behaviors ("
            f"{', '.join(map(str, behaviors)) or 'none'})"
        )
    measure = data.get("measure", "reward")
    if measure not in _MEASURES:
        raise EnvironmentParametersError(
            f"{where}.measure must be reward or progress, got {measure!r:.40}"
        )
    threshold = _number(data, "threshold", where) if "threshold" in data else 0.0
    if measure == "progress" and not 0.0 <= threshold <= 1.0:
        raise EnvironmentParametersError(
            f"{where}.threshold must be in [0, 1] when the measure is progress, got {threshold}"
        )
    length = data.get("min_lesson_length", 0)
    if type(length) is not int or length < 0:
        raise EnvironmentParametersError(
            f"{where}.min_lesson_length must be an integer >= 0, got {length!r:.40}"
        )
    flags = {}
    for flag, default in (("signal_smoothing", True), ("require_reset", False)):
        flags[flag] = data.get(flag, default)
        if not isinstance(flags[flag], bool):
            raise EnvironmentParametersError(
                f"{where}.{flag} must be true or false, got {flags[flag]!r:.40}"
            )
    return Criteria(behavior, measure, threshold, length, **flags)


def _sampler(
    value: Any, where: str, seed: np.random.SeedSequence
) -> tuple[Draw, np.random.Generator]:
    """A value as ML-Agents writes it: a number, or ``{sampler_type, sampler_parameters}``."""
    rng = np.random.default_rng(seed)
    if not isinstance(value, Mapping):
        if not _is_number(value):
            raise EnvironmentParametersError(
                f"{where} must be a number or a sampler (sampler_type, sampler_parameters), "
                f"got {value!r:.40}"
            )
        return (lambda _rng: value), rng
    _only(value, {"sampler_type", "sampler_parameters"}, where)
    for required in ("sampler_type", "sampler_parameters"):
        if required not in value:
            raise EnvironmentParametersError(f"{where} has no {required}")
    kind = value["sampler_type"]
    if kind not in _SAMPLERS:
        raise EnvironmentParametersError(
            f"{where}.sampler_type: unknown sampler {kind!r:.40}; ML-Agents' are "
            f"{', '.join(_SAMPLERS)}"
        )
    parameters = value["sampler_parameters"]
    where = f"{where}.sampler_parameters"
    if not isinstance(parameters, Mapping):
        raise EnvironmentParametersError(f"{where} must be a map")
    fields, build = _SAMPLERS[kind]
    _only(parameters, {*fields, "seed"}, where)
    for field in fields:
        if field not in parameters:
            raise EnvironmentParametersError(
                f"{where} has no {field} ({kind} needs {', '.join(fields)})"
            )
    if "seed" in parameters:
        own = parameters["seed"]
        if type(own) is not int or own < 0:
            raise EnvironmentParametersError(f"{where}.seed must be an integer >= 0")
        rng = np.random.default_rng(own)
    return build(parameters, where), rng


def _uniform(parameters: Mapping[str, Any], where: str) -> Draw:
    low, high = _number(parameters, "min_value", where), _number(parameters, "max_value", where)
    if low > high:
        raise EnvironmentParametersError(
            f"{where}.min_value ({low}) is greater than max_value ({high})"
        )
    return lambda rng: float(rng.uniform(low, high))


def _gaussian(parameters: Mapping[str, Any], where: str) -> Draw:
    mean, deviation = _number(parameters, "mean", where), _number(parameters, "st_dev", where)
    if deviation < 0:
        raise EnvironmentParametersError(f"{where}.st_dev must be >= 0, got {deviation}")
    return lambda rng: float(rng.normal(mean, deviation))


def _multirange(parameters: Mapping[str, Any], where: str) -> Draw:
    intervals = parameters["intervals"]
    where = f"{where}.intervals"
    if not isinstance(intervals, list) or not intervals:
        raise EnvironmentParametersError(f"{where} must be a non-empty list of [min, max]")
    ranges = []
    for index, interval in enumerate(intervals):
        if (
            not isinstance(interval, list | tuple)
            or len(interval) != 2
            or not all(map(_is_number, interval))
        ):
            raise EnvironmentParametersError(
                f"{where}[{index}] must be [min, max], two numbers, got {interval!r:.40}"
            )
        low, high = map(float, interval)
        if low > high:
            raise EnvironmentParametersError(
                f"{where}[{index}]: min ({low}) is greater than max ({high})"
            )
        ranges.append((low, high))
    total = sum(high - low for low, high in ranges)

    def draw(rng: np.random.Generator) -> float:
        """A point of the intervals, uniformly over their total length (as ML-Agents)."""
        point = float(rng.uniform(0.0, total))
        for low, high in ranges:
            if point < high - low:
                return low + point
            point -= high - low
        return ranges[-1][1]

    return draw


def _constant(parameters: Mapping[str, Any], where: str) -> Draw:
    value = parameters["value"]
    if not _is_number(value):
        raise EnvironmentParametersError(
            f"{where}.value must be a finite number, got {value!r:.40}"
        )
    return lambda rng: value


_SAMPLERS: dict[str, tuple[tuple[str, ...], Callable[[Mapping[str, Any], str], Draw]]] = {
    "uniform": (("min_value", "max_value"), _uniform),
    "gaussian": (("mean", "st_dev"), _gaussian),
    "multirangeuniform": (("intervals",), _multirange),
    "constant": (("value",), _constant),
}


def names_file(text: str) -> bool:
    """Whether ``text`` is the path of an existing file rather than YAML text."""
    if "\n" in text:
        return False
    try:
        return Path(text).is_file()
    except OSError:  # too long to be a file name
        return False


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _number(data: Mapping[str, Any], key: str, where: str) -> float:
    value = data[key]
    if not _is_number(value):
        raise EnvironmentParametersError(
            f"{where}.{key} must be a finite number, got {value!r:.40}"
        )
    return float(value)


def finite(value: Any, what: str) -> float:
    """``value`` as a float, refused (``ValueError`` naming ``what``) unless a finite number."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise ValueError(f"{what} must be a number, got {value!r:.40}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{what} must be finite, got {value}")
    return value


def _only(data: Mapping[str, Any], allowed: set[str], where: str) -> None:
    """Refuse keys ML-Agents would refuse (its ``strict_to_cls``), naming the first."""
    for key in data:
        if key not in allowed:
            raise EnvironmentParametersError(
                f"{where}.{key}: unknown key; allowed: {', '.join(sorted(allowed))}"
            )
