"""Curricula over procedural levels: which level a trainer plays next.

- :mod:`~rlenv_client.curriculum.sampler`: :class:`LevelSampler`, prioritized level replay
  (PLR, Robust PLR, ACCEL) over a buffer of scored levels;
- :mod:`~rlenv_client.curriculum.scores`: the scores it ranks by (:func:`positive_value_loss`,
  :func:`max_mc`, :func:`learnability`);
- :mod:`~rlenv_client.curriculum.levels`: what a level is (an int seed or plain data);
- :mod:`~rlenv_client.curriculum.parameters`: ML-Agents' ``environment_parameters``
  (:class:`EnvironmentParameters`: samplers, and lessons with completion criteria);
- :mod:`~rlenv_client.curriculum.vector`: :class:`CurriculumVectorEnv`, a gymnasium vector
  wrapper that plays each sub-environment's next level (new or replayed) and keeps the buffer.

numpy only (gymnasium too for the wrapper), and no trainer: every call takes and returns plain
values.
"""

from rlenv_client.curriculum.levels import Level as Level
from rlenv_client.curriculum.parameters import EnvironmentParameters as EnvironmentParameters
from rlenv_client.curriculum.parameters import (
    EnvironmentParametersError as EnvironmentParametersError,
)
from rlenv_client.curriculum.parameters import configurable_keys as configurable_keys
from rlenv_client.curriculum.parameters import configure_arguments as configure_arguments
from rlenv_client.curriculum.sampler import PRIORITIZATIONS as PRIORITIZATIONS
from rlenv_client.curriculum.sampler import LevelSampler as LevelSampler
from rlenv_client.curriculum.scores import learnability as learnability
from rlenv_client.curriculum.scores import max_mc as max_mc
from rlenv_client.curriculum.scores import positive_value_loss as positive_value_loss
from rlenv_client.curriculum.vector import CurriculumVectorEnv as CurriculumVectorEnv
from rlenv_client.curriculum.vector import Episode as Episode

__all__ = [
    "PRIORITIZATIONS",
    "CurriculumVectorEnv",
    "EnvironmentParameters",
    "EnvironmentParametersError",
    "Episode",
    "Level",
    "LevelSampler",
    "configurable_keys",
    "configure_arguments",
    "learnability",
    "max_mc",
    "positive_value_loss",
]
