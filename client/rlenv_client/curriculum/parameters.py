"""ML-Agents' ``environment_parameters``: samplers and curricula of lessons, for rlenv settings.

A user coming from Unity ML-Agents pastes the ``environment_parameters`` section of their
trainer config (or the whole config, ``behaviors:`` and all) into
:class:`EnvironmentParameters`, as YAML (:meth:`EnvironmentParameters.from_yaml`) or as the
same data in a dict. Each parameter names a setting a client may ``configure``: by its
configure key (``world.difficulty``), or by a bare name (``difficulty``) that exactly one
node's ``configurable`` attributes offer (:meth:`EnvironmentParameters.bind`).

A parameter is a plain number, a sampler or a curriculum, as ML-Agents writes them::

    environment_parameters:
      gravity: 9.81                                  # a plain value
      difficulty:                                    # a sampler
        sampler_type: uniform                        # gaussian: mean, st_dev
        sampler_parameters: {min_value: 0.1, max_value: 0.4}
      world.max_speed:                               # a curriculum
        curriculum:
          - name: Slow
            completion_criteria: {measure: reward, behavior: Catcher, threshold: 0.8,
                                  min_lesson_length: 100, signal_smoothing: true}
            value: 2.0
          - name: Fast                               # the last lesson has no criteria
            value: {sampler_type: multirangeuniform,
                    sampler_parameters: {intervals: [[4.0, 5.0], [7.0, 8.0]]}}

The trainer draws values with :meth:`~EnvironmentParameters.sample` before each reset,
configures them (:func:`configure_arguments` gives ``client.configure``'s keywords) and reports
each finished episode with :meth:`~EnvironmentParameters.add_episode`, which moves curricula on
as ML-Agents' ``EnvironmentParameterManager`` does. ``docs/environment-parameters.md`` says what
differs from ML-Agents.
"""

from __future__ import annotations

import logging
import math
import os
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "EnvironmentParameters",
    "EnvironmentParametersError",
    "configurable_keys",
    "configure_arguments",
]

logger = logging.getLogger(__name__)

SECTIONS = ("environment", "agent", "world")
"""The sections of a ``config`` request: the first part of a configure key."""

_MEASURES = ("reward", "progress")
_CRITERIA_KEYS = {"measure", "behavior", "threshold", "min_lesson_length", "signal_smoothing",
                  "require_reset"}

_Draw = Callable[[np.random.Generator], float]


class EnvironmentParametersError(ValueError):
    """A config ML-Agents' format does not allow, or a parameter no setting matches.

    The message names the key (``environment_parameters.difficulty.sampler_parameters...``)
    or the parameter.
    """


@dataclass(frozen=True, slots=True)
class _Criteria:
    """A lesson's ``completion_criteria``, with ML-Agents' defaults."""

    behavior: str
    measure: str = "reward"
    threshold: float = 0.0
    min_lesson_length: int = 0
    signal_smoothing: bool = True
    require_reset: bool = False


@dataclass(frozen=True, slots=True)
class _Lesson:
    """A lesson: its name, how its value is drawn, and when it is complete (``None``: last)."""

    name: str
    draw: _Draw
    rng: np.random.Generator
    criteria: _Criteria | None


class _Parameter:
    """A parameter's lessons (one, named after it, unless it is a curriculum) and its state."""

    __slots__ = ("name", "lessons", "index", "smoothed", "key")

    def __init__(self, name: str, lessons: list[_Lesson]) -> None:
        self.name = name
        self.lessons = lessons
        self.index = 0
        self.smoothed = 0.0  # ML-Agents' smoothed measure, kept across lessons
        section = name.split(".", 1)[0]
        self.key: str | None = name if section in SECTIONS and "." in name else None

    @property
    def current(self) -> _Lesson:
        return self.lessons[self.index]


class EnvironmentParameters:
    """ML-Agents' ``environment_parameters``: values to configure, drawn per reset, in lessons.

    Args:
        config: the ``environment_parameters`` section, or a whole ML-Agents trainer config
            (a map with ``behaviors`` and ``environment_parameters``), as plain data.
        seed: seeds every sampler (each draws from its own generator, in config order, unless
            its ``sampler_parameters`` give a ``seed`` of its own); ``None``: fresh entropy.

    Raises:
        EnvironmentParametersError: the config is not ML-Agents' format; the message names the
            key (an unknown ``sampler_type``, a missing ``min_value``, ``min_value`` above
            ``max_value``, a lesson without ``value``, criteria on the last lesson, an unknown
            ``measure``, a negative ``min_lesson_length``, a ``behavior`` the config's
            ``behaviors`` lack...).
    """

    def __init__(self, config: Mapping[str, Any], seed: int | None = None) -> None:
        if not isinstance(config, Mapping):
            raise EnvironmentParametersError(
                f"environment_parameters must be a map, got {type(config).__name__}")
        behaviors: Mapping[str, Any] | None = None
        section: Any = config
        if "environment_parameters" in config or "behaviors" in config:  # a whole config
            behaviors = config.get("behaviors")
            if behaviors is not None and not isinstance(behaviors, Mapping):
                raise EnvironmentParametersError("behaviors must be a map of behavior names")
            section = config.get("environment_parameters") or {}
            if not isinstance(section, Mapping):
                raise EnvironmentParametersError("environment_parameters must be a map, got "
                                                 f"{type(section).__name__}")
        seeds = iter(np.random.SeedSequence(seed).spawn(_count_samplers(section)))
        self._parameters = [_parameter(str(name), value, seeds, behaviors)
                            for name, value in section.items()]
        capacity: dict[str, int] = {}
        for parameter in self._parameters:
            for lesson in parameter.lessons:
                if lesson.criteria is not None:
                    criteria = lesson.criteria
                    capacity[criteria.behavior] = max(capacity.get(criteria.behavior, 1),
                                                      criteria.min_lesson_length)
        self._rewards = {behavior: deque(maxlen=size) for behavior, size in capacity.items()}
        self._by_name = {parameter.name: parameter for parameter in self._parameters}
        self._reset_required = False

    @classmethod
    def from_yaml(cls, source: str | os.PathLike[str], seed: int | None = None
                  ) -> EnvironmentParameters:
        """Read a config from YAML text or a YAML file (needs PyYAML).

        Args:
            source: a path (a ``Path``, or a str naming an existing file), or YAML text.
            seed: as for the constructor.

        Raises:
            ImportError: PyYAML is not installed (``pip install pyyaml``).
            EnvironmentParametersError: the YAML is not a map, or not ML-Agents' format.
        """
        try:
            import yaml
        except ImportError:
            raise ImportError("reading YAML needs PyYAML: pip install pyyaml (or pass the "
                              "config as a dict)") from None
        text = str(source)
        if isinstance(source, os.PathLike) or _names_file(text):
            text = Path(source).read_text(encoding="utf-8")
        data = yaml.safe_load(text)
        if not isinstance(data, Mapping):
            raise EnvironmentParametersError(
                f"the YAML must be a map of environment parameters, got {data!r:.60} "
                "(a str that names no existing file is read as YAML text)")
        return cls(data, seed)

    @property
    def names(self) -> tuple[str, ...]:
        """The parameters' names, as the config writes them, in its order."""
        return tuple(self._by_name)

    @property
    def reset_required(self) -> bool:
        """Whether the caller must reset the environment now, before its next step.

        True from an :meth:`add_episode` that moved a parameter to a lesson whose completed
        lesson said ``require_reset: true``, until the next :meth:`sample`: the caller ends the
        episodes under way (in a vector, every sub-environment), configures the new lesson's
        values and resets, as ML-Agents resets its environments at once. Without
        ``require_reset`` a new lesson's values apply at the next reset the caller makes anyway.
        """
        return self._reset_required

    def bind(self, keys: Iterable[str]) -> None:
        """Resolve the parameters' names against an environment's configure keys.

        A name that is a configure key (``world.difficulty``) must be one of ``keys``; a bare
        name (``difficulty``) must end exactly one of them.

        Args:
            keys: the configure keys the environment offers: ``configurable_keys(client.tree())``.

        Raises:
            EnvironmentParametersError: a name is unknown or ambiguous (naming the parameter
                and the candidates), or two parameters name the same setting. Nothing is bound.
        """
        offered = sorted(set(keys))
        resolved: dict[str, str] = {}
        for parameter in self._parameters:
            name = parameter.name
            if name in offered:
                key = name
            else:
                candidates = [key for key in offered if key.partition(".")[2] == name]
                if len(candidates) != 1:
                    listed = ", ".join(candidates or offered) or "none"
                    problem = "is ambiguous: it could be" if candidates else \
                        "names no configurable setting; the environment offers"
                    raise EnvironmentParametersError(
                        f"environment parameter {name!r} {problem} {listed}"
                        + (" (name it by its configure key)" if candidates else ""))
                key = candidates[0]
            if key in resolved.values():
                other = next(n for n, k in resolved.items() if k == key)
                raise EnvironmentParametersError(
                    f"environment parameters {other!r} and {name!r} both set {key}")
            resolved[name] = key
        for parameter in self._parameters:
            parameter.key = resolved[parameter.name]

    def key(self, name: str) -> str:
        """The configure key parameter ``name`` sets (``world.difficulty``).

        Raises:
            KeyError: no parameter is named ``name``.
            EnvironmentParametersError: ``name`` is a bare name and :meth:`bind` was not called.
        """
        parameter = self._parameter(name)
        if parameter.key is None:
            raise EnvironmentParametersError(
                f"environment parameter {name!r} is a bare name: call "
                "bind(configurable_keys(client.tree())) first, or name it by its configure key "
                f"(such as world.{name})")
        return parameter.key

    def sample(self) -> dict[str, float]:
        """Draw every parameter's value from its current lesson, for the next reset.

        Returns:
            ``{configure key: value}``, e.g. ``{"world.difficulty": 0.37}``; pass it through
            :func:`configure_arguments` to ``client.configure``. Plain and ``constant``
            values come as the config writes them (an int stays an int), drawn ones as floats.

        Raises:
            EnvironmentParametersError: a bare name is not bound yet (see :meth:`key`).
        """
        keys = [self.key(parameter.name) for parameter in self._parameters]
        self._reset_required = False
        return {key: parameter.current.draw(parameter.current.rng)
                for key, parameter in zip(keys, self._parameters, strict=True)}

    def add_episode(self, reward: float, progress: float | None = None,
                    behavior: str | None = None) -> bool:
        """Count a finished episode and move on the curricula whose lesson is complete.

        As ML-Agents documents it: a lesson is complete once its behavior finished at least
        ``min_lesson_length`` episodes in it and its measure is above ``threshold``:
        ``progress`` itself for ``measure: progress``; for ``measure: reward`` the mean reward
        of the last ``min_lesson_length`` episodes (at least the last one), smoothed when
        ``signal_smoothing`` is on (``0.25 * previous + 0.75 * mean``, the parameter's previous
        smoothed value starting at 0). Any change of lesson
        empties every behavior's rewards, so the next lesson counts its own episodes.

        Args:
            reward: the episode's total reward.
            progress: the fraction of training done, in [0, 1]; needed while a current lesson
                measures progress.
            behavior: the ML-Agents behavior the episode is of; ``None``: every behavior (an
                environment with one kind of agent).

        Returns:
            Whether some parameter changed lesson (its values apply at the next :meth:`sample`;
            see :attr:`reset_required`).

        Raises:
            ValueError: a reward or progress that is not a finite number (or a progress outside
                [0, 1]), no progress while a lesson measures it, or a behavior no criteria
                name; nothing was counted.
        """
        reward = _finite(reward, "add_episode: reward")
        if progress is not None:
            progress = _finite(progress, "add_episode: progress")
            if not 0.0 <= progress <= 1.0:
                raise ValueError(f"add_episode: progress must be in [0, 1], got {progress}")
        if behavior is not None and behavior not in self._rewards:
            raise ValueError(f"add_episode: no completion_criteria names behavior {behavior!r}; "
                             f"they name {', '.join(self._rewards) or 'none'}")
        counted = [b for b in self._rewards if behavior is None or b == behavior]
        checked = [(parameter, criteria) for parameter in self._parameters
                   if (criteria := parameter.current.criteria) is not None
                   and criteria.behavior in counted]
        if progress is None:
            for parameter, criteria in checked:
                if criteria.measure == "progress":
                    raise ValueError(
                        f"environment parameter {parameter.name!r}: lesson "
                        f"{parameter.current.name!r} measures progress; pass "
                        "add_episode(reward, progress=fraction of training done)")
        for name in counted:
            self._rewards[name].append(reward)
        changed = False
        for parameter, criteria in checked:
            if self._complete(parameter, criteria, progress):
                completed = parameter.current
                parameter.index += 1
                changed = True
                self._reset_required |= criteria.require_reset
                logger.info("environment parameter %r: lesson %r complete, now %r",
                            parameter.name, completed.name, parameter.current.name)
        if changed:
            for rewards in self._rewards.values():
                rewards.clear()
        return changed

    def lesson(self, name: str) -> str:
        """The name of parameter ``name``'s current lesson (the new one as soon as it changed).

        A parameter that is not a curriculum has one lesson, named after the parameter (as
        in ML-Agents).

        Raises:
            KeyError: no parameter is named ``name``.
        """
        return self._parameter(name).current.name

    def _parameter(self, name: str) -> _Parameter:
        try:
            return self._by_name[name]
        except KeyError:
            raise KeyError(f"no environment parameter {name!r}; there are "
                           f"{', '.join(self._by_name) or 'none'}") from None

    def _complete(self, parameter: _Parameter, criteria: _Criteria,
                  progress: float | None) -> bool:
        """ML-Agents' ``CompletionCriteriaSettings.need_increment``, smoothing kept here.

        Its buffer holds as many rewards as the largest ``min_lesson_length`` of the behavior's
        criteria; the mean is over this lesson's own ``min_lesson_length``, as documented.
        """
        rewards = self._rewards[criteria.behavior]
        if len(rewards) < criteria.min_lesson_length:
            return False
        if criteria.measure == "progress":
            return progress is not None and progress > criteria.threshold
        if not rewards:
            return False
        window = max(1, criteria.min_lesson_length)
        measure = float(np.mean(list(rewards)[-window:]))
        if criteria.signal_smoothing:
            measure = parameter.smoothed = 0.25 * parameter.smoothed + 0.75 * measure
        return measure > criteria.threshold


def configurable_keys(tree: Iterable[Mapping[str, Any]]) -> set[str]:
    """The configure keys an environment offers, from its node tree.

    Args:
        tree: ``client.tree()``: the nodes a ``config`` reaches say their section and their
            ``configurable`` attributes.

    Returns:
        ``{"environment.repeat_action", "agent.max_speed", "world.difficulty", ...}``.
    """
    return {f"{node['config']}.{name}" for node in tree if "config" in node
            for name in node.get("configurable", ())}


def configure_arguments(values: Mapping[str, Any]) -> dict[str, Any]:
    """``{configure key: value}`` as ``client.configure(**...)`` takes it.

    ``{"world.difficulty": 0.37, "environment.repeat_action": 4}`` gives
    ``{"world": {"difficulty": 0.37}, "repeat_action": 4}``: the environment's settings are
    keywords of their own.

    Raises:
        ValueError: a key is not ``SECTION.NAME`` with a section of :data:`SECTIONS`.
    """
    arguments: dict[str, Any] = {}
    for key, value in values.items():
        section, _, name = key.partition(".")
        if section not in SECTIONS or not name:
            raise ValueError(f"{key!r} is not a configure key (one of "
                             f"{', '.join(s + '.NAME' for s in SECTIONS)})")
        if section == "environment":
            arguments[name] = value
        else:
            arguments.setdefault(section, {})[name] = value
    return arguments


def _count_samplers(section: Mapping[str, Any]) -> int:
    """How many generators a config's samplers need (one per lesson, at most)."""
    count = 0
    for value in section.values():
        curriculum = value.get("curriculum") if isinstance(value, Mapping) else None
        count += len(curriculum) if isinstance(curriculum, list) else 1
    return count


def _parameter(name: str, value: Any, seeds: Any,
               behaviors: Mapping[str, Any] | None) -> _Parameter:
    """One parameter of the section: a plain value, a sampler or a curriculum."""
    where = f"environment_parameters.{name}"
    if not (isinstance(value, Mapping) and "curriculum" in value):
        draw, rng = _sampler(value, where, next(seeds))
        return _Parameter(name, [_Lesson(name, draw, rng, None)])
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
            raise EnvironmentParametersError(f"{at} must be a map (name, value, "
                                             "completion_criteria)")
        _only(lesson, {"name", "value", "completion_criteria"}, at)
        for required in ("name", "value"):
            if required not in lesson:
                raise EnvironmentParametersError(f"{at} has no {required}")
        criteria = lesson.get("completion_criteria")
        if criteria is None and not last:
            raise EnvironmentParametersError(
                f"{at}.completion_criteria is missing: every lesson but the last needs one")
        if criteria is not None and last:
            raise EnvironmentParametersError(
                f"{at}.completion_criteria: the last lesson has none (it never ends)")
        draw, rng = _sampler(lesson["value"], f"{at}.value", next(seeds))
        lessons.append(_Lesson(str(lesson["name"]), draw, rng, None if criteria is None else
                               _criteria(criteria, f"{at}.completion_criteria", behaviors)))
    return _Parameter(name, lessons)


def _criteria(data: Any, where: str, behaviors: Mapping[str, Any] | None) -> _Criteria:
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
            f"{', '.join(map(str, behaviors)) or 'none'})")
    measure = data.get("measure", "reward")
    if measure not in _MEASURES:
        raise EnvironmentParametersError(
            f"{where}.measure must be reward or progress, got {measure!r:.40}")
    threshold = _number(data, "threshold", where) if "threshold" in data else 0.0
    if measure == "progress" and not 0.0 <= threshold <= 1.0:
        raise EnvironmentParametersError(
            f"{where}.threshold must be in [0, 1] when the measure is progress, got {threshold}")
    length = data.get("min_lesson_length", 0)
    if type(length) is not int or length < 0:
        raise EnvironmentParametersError(
            f"{where}.min_lesson_length must be an integer >= 0, got {length!r:.40}")
    flags = {}
    for flag, default in (("signal_smoothing", True), ("require_reset", False)):
        flags[flag] = data.get(flag, default)
        if not isinstance(flags[flag], bool):
            raise EnvironmentParametersError(
                f"{where}.{flag} must be true or false, got {flags[flag]!r:.40}")
    return _Criteria(behavior, measure, threshold, length, **flags)


def _sampler(value: Any, where: str, seed: np.random.SeedSequence
             ) -> tuple[_Draw, np.random.Generator]:
    """A value as ML-Agents writes it: a number, or ``{sampler_type, sampler_parameters}``."""
    rng = np.random.default_rng(seed)
    if not isinstance(value, Mapping):
        if not _is_number(value):
            raise EnvironmentParametersError(
                f"{where} must be a number or a sampler (sampler_type, sampler_parameters), "
                f"got {value!r:.40}")
        return (lambda _rng: value), rng
    _only(value, {"sampler_type", "sampler_parameters"}, where)
    for required in ("sampler_type", "sampler_parameters"):
        if required not in value:
            raise EnvironmentParametersError(f"{where} has no {required}")
    kind = value["sampler_type"]
    if kind not in _SAMPLERS:
        raise EnvironmentParametersError(
            f"{where}.sampler_type: unknown sampler {kind!r:.40}; ML-Agents' are "
            f"{', '.join(_SAMPLERS)}")
    parameters = value["sampler_parameters"]
    where = f"{where}.sampler_parameters"
    if not isinstance(parameters, Mapping):
        raise EnvironmentParametersError(f"{where} must be a map")
    fields, build = _SAMPLERS[kind]
    _only(parameters, {*fields, "seed"}, where)
    for field in fields:
        if field not in parameters:
            raise EnvironmentParametersError(f"{where} has no {field} ({kind} needs "
                                             f"{', '.join(fields)})")
    if "seed" in parameters:
        own = parameters["seed"]
        if type(own) is not int or own < 0:
            raise EnvironmentParametersError(f"{where}.seed must be an integer >= 0")
        rng = np.random.default_rng(own)
    return build(parameters, where), rng


def _uniform(parameters: Mapping[str, Any], where: str) -> _Draw:
    low, high = _number(parameters, "min_value", where), _number(parameters, "max_value", where)
    if low > high:
        raise EnvironmentParametersError(
            f"{where}.min_value ({low}) is greater than max_value ({high})")
    return lambda rng: float(rng.uniform(low, high))


def _gaussian(parameters: Mapping[str, Any], where: str) -> _Draw:
    mean, deviation = _number(parameters, "mean", where), _number(parameters, "st_dev", where)
    if deviation < 0:
        raise EnvironmentParametersError(f"{where}.st_dev must be >= 0, got {deviation}")
    return lambda rng: float(rng.normal(mean, deviation))


def _multirange(parameters: Mapping[str, Any], where: str) -> _Draw:
    intervals = parameters["intervals"]
    where = f"{where}.intervals"
    if not isinstance(intervals, list) or not intervals:
        raise EnvironmentParametersError(f"{where} must be a non-empty list of [min, max]")
    ranges = []
    for index, interval in enumerate(intervals):
        if not isinstance(interval, list | tuple) or len(interval) != 2 \
                or not all(map(_is_number, interval)):
            raise EnvironmentParametersError(
                f"{where}[{index}] must be [min, max], two numbers, got {interval!r:.40}")
        low, high = map(float, interval)
        if low > high:
            raise EnvironmentParametersError(
                f"{where}[{index}]: min ({low}) is greater than max ({high})")
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


def _constant(parameters: Mapping[str, Any], where: str) -> _Draw:
    value = parameters["value"]
    if not _is_number(value):
        raise EnvironmentParametersError(f"{where}.value must be a finite number, got "
                                         f"{value!r:.40}")
    return lambda rng: value


_SAMPLERS: dict[str, tuple[tuple[str, ...], Callable[[Mapping[str, Any], str], _Draw]]] = {
    "uniform": (("min_value", "max_value"), _uniform),
    "gaussian": (("mean", "st_dev"), _gaussian),
    "multirangeuniform": (("intervals",), _multirange),
    "constant": (("value",), _constant),
}


def _names_file(text: str) -> bool:
    """Whether ``text`` is the path of an existing file rather than YAML text."""
    if "\n" in text:
        return False
    try:
        return Path(text).is_file()
    except OSError:  # too long to be a file name
        return False


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and \
        math.isfinite(value)


def _number(data: Mapping[str, Any], key: str, where: str) -> float:
    value = data[key]
    if not _is_number(value):
        raise EnvironmentParametersError(f"{where}.{key} must be a finite number, got "
                                         f"{value!r:.40}")
    return float(value)


def _finite(value: Any, what: str) -> float:
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
                f"{where}.{key}: unknown key; allowed: {', '.join(sorted(allowed))}")
