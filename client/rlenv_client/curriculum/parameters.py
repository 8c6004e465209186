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
as ML-Agents' ``EnvironmentParameterManager`` does. ``docs/curriculum.md`` ("ML-Agents
environment parameters") says what differs from ML-Agents.
"""

from __future__ import annotations

import logging
import os
from collections import deque
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from rlenv_client.curriculum.ml_agents import (
    SECTIONS,
    Criteria,
    EnvironmentParametersError,
    Parameter,
    count_samplers,
    finite,
    names_file,
    read_parameter,
)

__all__ = [
    "EnvironmentParameters",
    "EnvironmentParametersError",
    "configurable_keys",
    "configure_arguments",
]

logger = logging.getLogger(__name__)


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
                f"environment_parameters must be a map, got {type(config).__name__}"
            )
        behaviors: Mapping[str, Any] | None = None
        section: Any = config
        if "environment_parameters" in config or "behaviors" in config:  # a whole config
            behaviors = config.get("behaviors")
            if behaviors is not None and not isinstance(behaviors, Mapping):
                raise EnvironmentParametersError("behaviors must be a map of behavior names")
            section = config.get("environment_parameters") or {}
            if not isinstance(section, Mapping):
                raise EnvironmentParametersError(
                    f"environment_parameters must be a map, got {type(section).__name__}"
                )
        seeds = iter(np.random.SeedSequence(seed).spawn(count_samplers(section)))
        self._parameters = [
            read_parameter(str(name), value, seeds, behaviors) for name, value in section.items()
        ]
        capacity: dict[str, int] = {}
        for parameter in self._parameters:
            for lesson in parameter.lessons:
                if lesson.criteria is not None:
                    criteria = lesson.criteria
                    capacity[criteria.behavior] = max(
                        capacity.get(criteria.behavior, 1), criteria.min_lesson_length
                    )
        self._rewards: dict[str, deque[float]] = {
            behavior: deque(maxlen=size) for behavior, size in capacity.items()
        }
        self._by_name = {parameter.name: parameter for parameter in self._parameters}
        self._reset_required = False

    @classmethod
    def from_yaml(
        cls, source: str | os.PathLike[str], seed: int | None = None
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
            raise ImportError(
                "reading YAML needs PyYAML: pip install pyyaml (or pass the config as a dict)"
            ) from None
        text = str(source)
        if isinstance(source, os.PathLike) or names_file(text):
            text = Path(source).read_text(encoding="utf-8")
        data = yaml.safe_load(text)
        if not isinstance(data, Mapping):
            raise EnvironmentParametersError(
                f"the YAML must be a map of environment parameters, got {data!r:.60} "
                "(a str that names no existing file is read as YAML text)"
            )
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
                    problem = (
                        "is ambiguous: it could be"
                        if candidates
                        else "names no configurable setting; the environment offers"
                    )
                    raise EnvironmentParametersError(
                        f"environment parameter {name!r} {problem} {listed}"
                        + (" (name it by its configure key)" if candidates else "")
                    )
                key = candidates[0]
            if key in resolved.values():
                other = next(n for n, k in resolved.items() if k == key)
                raise EnvironmentParametersError(
                    f"environment parameters {other!r} and {name!r} both set {key}"
                )
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
                f"(such as world.{name})"
            )
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
        return {
            key: parameter.current.draw(parameter.current.rng)
            for key, parameter in zip(keys, self._parameters, strict=True)
        }

    def add_episode(
        self, reward: float, progress: float | None = None, behavior: str | None = None
    ) -> bool:
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
        reward = finite(reward, "add_episode: reward")
        if progress is not None:
            progress = finite(progress, "add_episode: progress")
            if not 0.0 <= progress <= 1.0:
                raise ValueError(f"add_episode: progress must be in [0, 1], got {progress}")
        if behavior is not None and behavior not in self._rewards:
            raise ValueError(
                f"add_episode: no completion_criteria names behavior {behavior!r}; "
                f"they name {', '.join(self._rewards) or 'none'}"
            )
        counted = [b for b in self._rewards if behavior is None or b == behavior]
        checked = [
            (parameter, criteria)
            for parameter in self._parameters
            if (criteria := parameter.current.criteria) is not None and criteria.behavior in counted
        ]
        if progress is None:
            for parameter, criteria in checked:
                if criteria.measure == "progress":
                    raise ValueError(
                        f"environment parameter {parameter.name!r}: lesson "
                        f"{parameter.current.name!r} measures progress; pass "
                        "add_episode(reward, progress=fraction of training done)"
                    )
        for name in counted:
            self._rewards[name].append(reward)
        changed = False
        for parameter, criteria in checked:
            if self._complete(parameter, criteria, progress):
                completed = parameter.current
                parameter.index += 1
                changed = True
                self._reset_required |= criteria.require_reset
                logger.info(
                    "environment parameter %r: lesson %r complete, now %r",
                    parameter.name,
                    completed.name,
                    parameter.current.name,
                )
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

    def _parameter(self, name: str) -> Parameter:
        try:
            return self._by_name[name]
        except KeyError:
            raise KeyError(
                f"no environment parameter {name!r}; there are {', '.join(self._by_name) or 'none'}"
            ) from None

    def _complete(self, parameter: Parameter, criteria: Criteria, progress: float | None) -> bool:
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
    return {
        f"{node['config']}.{name}"
        for node in tree
        if "config" in node
        for name in node.get("configurable", ())
    }


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
            raise ValueError(
                f"{key!r} is not a configure key (one of "
                f"{', '.join(s + '.NAME' for s in SECTIONS)})"
            )
        if section == "environment":
            arguments[name] = value
        else:
            arguments.setdefault(section, {})[name] = value
    return arguments
