"""Policies as ONNX files: :func:`export_onnx` (the ``onnx`` extra, and torch).

A file written here takes a batch of observations (input ``observation``, its first dimension
dynamic, the observation space's dtype) and gives their actions (output ``action``, the action
space's dtype): deterministic actions, post-processed inside the graph as Stable-Baselines3's
``predict(deterministic=True)`` does (the argmax of a ``Discrete`` space; a ``Box`` action
clipped to its bounds, or unscaled from [-1, 1] when the policy squashes, as SAC's). The
observation and action spaces travel in the file's ``metadata_props``
(:data:`~rlenv.serving.onnx_policy.OBSERVATION_SPACE_KEY`,
:data:`~rlenv.serving.onnx_policy.ACTION_SPACE_KEY`), in the space's one JSON form
(:func:`rlenv.protocol.space_json.space_to_json_text`), so that ``rlenv serve --policy AGENT=FILE``
can check them against the agent's.

Before it returns, the export runs the file with onnxruntime on a seeded batch of observations
sampled from the observation space and compares its actions with the torch policy's: a
difference beyond :data:`TOLERANCE` is an error naming the largest one.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, cast

import numpy as np
from gymnasium import spaces

from rlenv.protocol.space_json import space_to_json_text
from rlenv.protocol.spaces import space_from_spec, space_to_spec
from rlenv.serving.onnx_policy import ACTION_SPACE_KEY, OBSERVATION_SPACE_KEY, OnnxPolicy

__all__ = ["CHECKED_OBSERVATIONS", "TOLERANCE", "ExportMismatch", "export_onnx"]

CHECKED_OBSERVATIONS = 64
"""How many observations (sampled from the space, seeded) the export checks."""

TOLERANCE = 1e-4
"""The largest difference allowed between a torch action and its ONNX counterpart (``Box``)."""

_SEED = 0


class ExportMismatch(ValueError):
    """The ONNX file's actions differ from the torch policy's (the message names the largest)."""


def export_onnx(
    model: Any,
    path: str | Path,
    observation_space: spaces.Space | None = None,
    action_space: spaces.Space | None = None,
) -> Path:
    """Write ``model``'s deterministic policy to ``path`` as ONNX, and check it.

    Args:
        model: a Stable-Baselines3 model (PPO, A2C, DQN, SAC) or its policy; or a
            ``torch.nn.Module`` whose ``forward(observation)`` takes a batch of observations and
            returns their actions (for a ``Discrete`` action space, the logits: the file takes
            their argmax), as a CleanRL actor; a ``Box`` action is clipped to the space's bounds.
        path: the file to write.
        observation_space: the observation space (a ``Box`` or ``Discrete``); taken from an SB3
            model when not given, required for a plain module.
        action_space: the action space (a ``Box`` or ``Discrete``); as ``observation_space``.

    Returns:
        ``path``, as a :class:`~pathlib.Path`.

    Raises:
        ImportError: torch, onnx or onnxruntime is missing (the ``onnx`` extra).
        TypeError: a plain module without its spaces, or spaces of another kind.
        ExportMismatch: the file's actions differ from the torch policy's by more than
            :data:`TOLERANCE` (or, for ``Discrete``, at all); the file is removed.
    """
    import onnx
    import torch

    from rlenv_tools._onnx_actors import Actor

    policy = getattr(model, "policy", model)
    sb3 = hasattr(policy, "predict") and hasattr(policy, "observation_space")
    observation_space = observation_space or (policy.observation_space if sb3 else None)
    action_space = action_space or (policy.action_space if sb3 else None)
    if observation_space is None or action_space is None:
        raise TypeError(
            "export_onnx needs observation_space and action_space for a module "
            "that is not a Stable-Baselines3 policy"
        )
    for which, space in (("observation", observation_space), ("action", action_space)):
        if not isinstance(space, spaces.Box | spaces.Discrete):
            raise TypeError(
                f"export_onnx takes Box and Discrete spaces; the {which} space is {space}"
            )
    actor = Actor(policy, cast(spaces.Box | spaces.Discrete, action_space), sb3)  # checked above
    observations = _sample(observation_space, CHECKED_OBSERVATIONS)
    path = Path(path)
    with warnings.catch_warnings():  # the TorchScript exporter: torch.export cannot trace SB3
        warnings.simplefilter("ignore")
        torch.onnx.export(
            actor,
            (torch.as_tensor(observations[:1]),),
            str(path),
            input_names=["observation"],
            output_names=["action"],
            dynamic_axes={"observation": {0: "batch"}, "action": {0: "batch"}},
            dynamo=False,
        )
    graph = onnx.load(str(path))
    onnx.helper.set_model_props(
        graph,
        {
            OBSERVATION_SPACE_KEY: space_to_json_text(observation_space),
            ACTION_SPACE_KEY: space_to_json_text(action_space),
        },
    )
    onnx.checker.check_model(graph)
    onnx.save(graph, str(path))
    try:
        _check(path, actor.reference(observations), observations)
    except BaseException:
        path.unlink(missing_ok=True)
        raise
    return path


def _sample(space: spaces.Space, count: int) -> np.ndarray:
    """``count`` observations of ``space``, seeded, stacked into a batch."""
    space = space_from_spec(space_to_spec(space))  # a copy: the caller's generator stays
    space.seed(_SEED)
    return np.stack([space.sample() for _ in range(count)])


def _check(path: Path, expected: np.ndarray, observations: np.ndarray) -> None:
    """Refuse the file at ``path`` unless its actions on ``observations`` are ``expected``."""
    got = OnnxPolicy(path).run(observations)
    expected = np.asarray(expected).reshape(got.shape)
    if got.dtype != expected.dtype:
        raise ExportMismatch(
            f"{path}: the ONNX actions are {got.dtype}, the policy's {expected.dtype}"
        )
    difference = np.abs(got.astype(np.float64) - expected.astype(np.float64))
    largest = int(np.argmax(difference))
    limit = 0.0 if got.dtype.kind in "iub" else TOLERANCE
    if difference.flat[largest] > limit:
        row = np.unravel_index(largest, difference.shape)[0]
        raise ExportMismatch(
            f"{path}: the ONNX actions differ from the torch policy's on "
            f"{int((difference > limit).any(axis=tuple(range(1, difference.ndim))).sum())} of "
            f"{len(observations)} observations; the largest difference is "
            f"{difference.flat[largest]:.6g} (observation {row}: ONNX "
            f"{got.flat[largest]!r}, torch {expected.flat[largest]!r}; tolerance {limit:g})"
        )
