"""A policy in an ONNX file, run by onnxruntime on the CPU (the ``onnx`` extra).

The file is one :func:`rlenv_client.policies.export_onnx` wrote: an input ``observation`` (a
batch), an output ``action``, and the spaces as rlenv's space specs in JSON in its metadata.
Files come from the command line, never from the network; a file that is not ONNX, or lacks the
spaces, is refused with a one-line error.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv.protocol.spaces import space_from_json

__all__ = ["ACTION_SPACE_KEY", "OBSERVATION_SPACE_KEY", "OnnxPolicy"]

OBSERVATION_SPACE_KEY = "rlenv.observation_space"
"""The metadata key of the observation space (its spec, as JSON)."""

ACTION_SPACE_KEY = "rlenv.action_space"
"""The metadata key of the action space (its spec, as JSON)."""


class OnnxPolicy:
    """A policy file, loaded into an onnxruntime session (one thread).

    Args:
        path: the ONNX file.

    Attributes:
        path: the file.
        observation_space: the observation space the file was exported for.
        action_space: its action space.

    Raises:
        ImportError: onnxruntime is missing (the message says to install ``rlenv[onnx]``).
        ValueError: the file cannot be read, is not an ONNX model, or does not hold rlenv's
            spaces (all in one line naming the file).
    """

    def __init__(self, path: str | Path) -> None:
        try:
            import onnxruntime
        except ImportError as error:
            raise ImportError(f"a policy file needs onnxruntime ({error}); install the onnx "
                              "extra: pip install 'rlenv[onnx]'") from None
        self.path = Path(path)
        try:
            model = self.path.read_bytes()
        except OSError as error:
            raise ValueError(f"cannot read the policy {path}: {error.strerror or error}") \
                from None
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = 1
        options.log_severity_level = 3  # errors only: the one line below says what went wrong
        try:
            self._session = onnxruntime.InferenceSession(
                model, options, providers=["CPUExecutionProvider"])
        except Exception as error:  # onnxruntime's own exception types
            reason = " ".join(str(error).split())[:200]
            raise ValueError(f"{path} is not an ONNX model ({reason})") from None
        metadata = self._session.get_modelmeta().custom_metadata_map
        missing = [key for key in (OBSERVATION_SPACE_KEY, ACTION_SPACE_KEY)
                   if key not in metadata]
        if missing:
            raise ValueError(f"{path} holds no {missing[0]} in its metadata; export it with "
                             "rlenv_client.policies.export_onnx")
        try:
            self.observation_space = space_from_json(metadata[OBSERVATION_SPACE_KEY])
            self.action_space = space_from_json(metadata[ACTION_SPACE_KEY])
        except ValueError as error:
            raise ValueError(f"{path}: its metadata's space is unreadable: {error}") from None
        inputs, outputs = self._session.get_inputs(), self._session.get_outputs()
        if [i.name for i in inputs] != ["observation"] or "action" not in \
                [o.name for o in outputs]:
            raise ValueError(f"{path} must take one input 'observation' and give 'action'")
        self._dtype = np.dtype(self.observation_space.dtype)
        self._output = ["action"]

    def run(self, observations: np.ndarray) -> np.ndarray:
        """The actions of a batch of observations (its first dimension)."""
        return self._session.run(self._output, {"observation": np.asarray(
            observations, self._dtype)})[0]

    def act(self, observation: Any) -> Any:
        """One observation's action, as a member of the action space."""
        action = self.run(np.asarray(observation, self._dtype)[None])[0]
        return action if isinstance(self.action_space, spaces.Box) else action.item()

    def check_spaces(self, agent: str, observation_space: spaces.Space,
                     action_space: spaces.Space) -> None:
        """Refuse to drive ``agent`` unless its spaces are the file's, bounds and dtype included.

        Raises:
            ValueError: one line naming the agent, the file, and both spaces that differ.
        """
        for which, theirs, ours in (("observation", observation_space, self.observation_space),
                                    ("action", action_space, self.action_space)):
            if not _same(theirs, ours):
                raise ValueError(f"--policy {agent}={self.path}: the file's {which} space is "
                                 f"{_one_line(ours)}, agent {agent!r}'s is {_one_line(theirs)}")


def _same(first: spaces.Space, second: spaces.Space) -> bool:
    """Whether two spaces are equal, dtype and exact bounds included."""
    if type(first) is not type(second) or first != second or first.dtype != second.dtype:
        return False
    if isinstance(first, spaces.Box):
        return bool(np.array_equal(first.low, second.low) and
                    np.array_equal(first.high, second.high))  # type: ignore[attr-defined]
    return True


def _one_line(space: spaces.Space) -> str:
    """A space as text on one line (with its dtype)."""
    text = " ".join(str(space).split())
    return text if "dtype" in text or str(space.dtype) in text else f"{text} {space.dtype}"
