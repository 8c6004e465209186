"""A policy in an ONNX file, run by onnxruntime on the CPU (the ``onnx`` extra).

The file is one :func:`rlenv_tools.policies.export_onnx` wrote: an input ``observation`` (a
batch), an output ``action``, and the spaces as rlenv's space specs in JSON in its metadata.
Files come from the command line, never from the network; a file that is not ONNX, or lacks the
spaces, is refused with a one-line error.

**A file is code.** Whatever its graph does, a policy call is bounded: it runs under a deadline
(:data:`POLICY_DEADLINE`; onnxruntime's ``RunOptions.terminate``, set by a watchdog thread,
stops a graph that loops), its tensors come from one arena of at most :data:`POLICY_MEMORY`
bytes shared by the process's policies (a graph asking for more fails), and what it returns is
checked against its action space (:func:`fit_action`): clipped into a ``Box`` (NaN refused), a
member of any other space or refused. Each failure raises :class:`PolicyError`; whoever runs the
policy decides what a failure costs (:mod:`rlenv.serving.policy_driver`: the episode).
"""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv.protocol.space_json import space_from_json

__all__ = [
    "ACTION_SPACE_KEY",
    "OBSERVATION_SPACE_KEY",
    "POLICY_DEADLINE",
    "POLICY_MEMORY",
    "OnnxPolicy",
    "PolicyError",
    "fit_action",
]

OBSERVATION_SPACE_KEY = "rlenv.observation_space"
"""The metadata key of the observation space (its spec, as JSON)."""

ACTION_SPACE_KEY = "rlenv.action_space"
"""The metadata key of the action space (its spec, as JSON)."""

POLICY_DEADLINE = 1.0
"""Seconds one policy call may take before onnxruntime is told to stop it (a failure)."""

POLICY_MEMORY = 256 << 20
"""Bytes the process's policies may hold in tensors at once (one onnxruntime arena)."""


class PolicyError(ValueError):
    """A policy call failed (one line saying why).

    The graph raised or ran past its deadline, or its action is not one of its action space.
    """


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
            raise ImportError(
                f"a policy file needs onnxruntime ({error}); install the onnx "
                "extra: pip install 'rlenv[onnx]'"
            ) from None
        self.path = Path(path)
        try:
            model = self.path.read_bytes()
        except OSError as error:
            raise ValueError(f"cannot read the policy {path}: {error.strerror or error}") from None
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = 1
        options.log_severity_level = 4  # fatal only: failures are ours to report, once
        _share_bounded_arena(onnxruntime)
        options.add_session_config_entry("session.use_env_allocators", "1")
        try:
            self._session = onnxruntime.InferenceSession(
                model, options, providers=["CPUExecutionProvider"]
            )
        except Exception as error:  # onnxruntime's own exception types
            reason = " ".join(str(error).split())[:200]
            raise ValueError(f"{path} is not an ONNX model ({reason})") from None
        metadata = self._session.get_modelmeta().custom_metadata_map
        missing = [key for key in (OBSERVATION_SPACE_KEY, ACTION_SPACE_KEY) if key not in metadata]
        if missing:
            raise ValueError(
                f"{path} holds no {missing[0]} in its metadata; export it with "
                "rlenv_tools.policies.export_onnx"
            )
        try:
            self.observation_space = space_from_json(metadata[OBSERVATION_SPACE_KEY])
            self.action_space = space_from_json(metadata[ACTION_SPACE_KEY])
        except ValueError as error:
            raise ValueError(f"{path}: its metadata's space is unreadable: {error}") from None
        inputs, outputs = self._session.get_inputs(), self._session.get_outputs()
        if [i.name for i in inputs] != ["observation"] or "action" not in [o.name for o in outputs]:
            raise ValueError(f"{path} must take one input 'observation' and give 'action'")
        self._dtype = np.dtype(self.observation_space.dtype)
        self._output = ["action"]
        self._run_options = onnxruntime.RunOptions
        self._watchdog = _Watchdog(POLICY_DEADLINE)

    def run(self, observations: np.ndarray) -> np.ndarray:
        """The actions of a batch of observations (its first dimension), as the graph gave them.

        Raises:
            PolicyError: the graph failed (a tensor beyond :data:`POLICY_MEMORY`, say) or ran
                past :data:`POLICY_DEADLINE` (one line, naming the file).
        """
        feed = {"observation": np.asarray(observations, self._dtype)}
        options = self._run_options()
        options.log_severity_level = 4
        try:
            with self._watchdog.watching(options):
                return np.asarray(self._session.run(self._output, feed, options)[0])
        except Exception as error:  # onnxruntime's own exception types
            if options.terminate:
                raise PolicyError(
                    f"policy {self.path.name} ran past its deadline of "
                    f"{POLICY_DEADLINE} s and was stopped"
                ) from None
            reason = " ".join(str(error).split())
            raise PolicyError(f"policy {self.path.name} failed: {reason[-200:]}") from None

    def act(self, observation: Any) -> Any:
        """One observation's action, as a member of the action space (see :func:`fit_action`).

        Raises:
            PolicyError: the graph failed, or gave what no action of the space is.
        """
        actions = self.run(np.asarray(observation, self._dtype)[None])
        if actions.ndim == 0 or len(actions) != 1:
            raise PolicyError(
                f"policy {self.path.name} gave {_shape(actions)} for one "
                "observation; its first dimension must be the batch's (1)"
            )
        return fit_action(self.action_space, actions[0], f"policy {self.path.name}")

    def check_spaces(
        self, agent: str, observation_space: spaces.Space, action_space: spaces.Space
    ) -> None:
        """Refuse to drive ``agent`` unless its spaces are the file's, bounds and dtype included.

        Raises:
            ValueError: one line naming the agent, the file, and both spaces that differ.
        """
        for which, theirs, ours in (
            ("observation", observation_space, self.observation_space),
            ("action", action_space, self.action_space),
        ):
            if not _same(theirs, ours):
                raise ValueError(
                    f"--policy {agent}={self.path}: the file's {which} space is "
                    f"{_one_line(ours)}, agent {agent!r}'s is {_one_line(theirs)}"
                )


def fit_action(space: spaces.Space, action: Any, who: str = "the policy") -> Any:
    """``action`` as a member of ``space``: clipped into a ``Box``, else checked as it is.

    A ``Box`` action must have the space's shape and no NaN; it is cast to the space's dtype
    and clipped to its bounds (``inf`` and 1e30 become the bound). A ``Discrete`` action is one
    whole number (of any numeric dtype) in the space. Any other space's action must be its
    member (``space.contains``).

    Raises:
        PolicyError: one line saying what ``who`` gave and what the space is.
    """
    if isinstance(space, spaces.Box):
        values = np.asarray(action)
        if values.shape != space.shape or values.dtype.kind not in "biuf":
            raise PolicyError(
                f"{who} gave {_shape(values)}; its action space is {_one_line(space)}"
            )
        if values.dtype.kind == "f" and values.size and math.isnan(values.min()):  # NaN wins
            raise PolicyError(
                f"{who} gave NaN in its action; no action of {_one_line(space)} is NaN"
            )
        return np.minimum(np.maximum(values, space.low), space.high).astype(space.dtype, copy=False)
    if isinstance(space, spaces.Discrete):
        values = np.asarray(action)
        if values.size == 1 and values.dtype.kind in "biuf":
            value = values.reshape(()).item()
            if float(value).is_integer() and space.start <= value < space.start + space.n:
                return int(value)
        raise PolicyError(f"{who} gave {_shape(values)}; its action space is {_one_line(space)}")
    try:
        member = space.contains(action)
    except Exception:  # an action of another kind altogether
        member = False
    if not member:
        raise PolicyError(
            f"{who} gave {_shape(np.asarray(action))}, not an action of {_one_line(space)}"
        )
    return action


class _Watchdog:
    """A thread that stops a policy call still running past ``seconds`` (``terminate``)."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self._current: tuple[Any, float] | None = None  # (run options, started at)
        thread = threading.Thread(target=self._watch, name="policy watchdog", daemon=True)
        thread.start()

    def watching(self, options: Any) -> _Watched:
        """A context in which a call made with ``options`` is watched."""
        return _Watched(self, options)

    def _watch(self) -> None:
        interval = self.seconds / 8
        while True:
            time.sleep(interval)  # a daemon: the process ends it
            current = self._current
            if current is not None and time.monotonic() - current[1] >= self.seconds:
                current[0].terminate = True


class _Watched:
    __slots__ = ("_options", "_watchdog")

    def __init__(self, watchdog: _Watchdog, options: Any) -> None:
        self._watchdog, self._options = watchdog, options

    def __enter__(self) -> None:
        self._watchdog._current = (self._options, time.monotonic())

    def __exit__(self, *exc: object) -> None:
        self._watchdog._current = None


_arena_lock = threading.Lock()
_arena_shared = False


def _share_bounded_arena(onnxruntime: Any) -> None:
    """Register, once per process, the arena of :data:`POLICY_MEMORY` bytes sessions share."""
    global _arena_shared
    with _arena_lock:
        if _arena_shared:
            return
        memory = onnxruntime.OrtMemoryInfo(
            "Cpu",
            onnxruntime.OrtAllocatorType.ORT_ARENA_ALLOCATOR,
            0,
            onnxruntime.OrtMemType.DEFAULT,
        )
        onnxruntime.create_and_register_allocator(
            memory, onnxruntime.OrtArenaCfg(POLICY_MEMORY, -1, -1, -1)
        )
        _arena_shared = True


def _shape(values: np.ndarray) -> str:
    """What an output was, for an error: its values if few, else its shape and dtype."""
    if values.size <= 4:
        return f"{np.array2string(values.reshape(-1), precision=4)} ({values.dtype})"
    return f"an array of shape {values.shape} ({values.dtype})"


def _same(first: spaces.Space, second: spaces.Space) -> bool:
    """Whether two spaces are equal, dtype and exact bounds included."""
    if type(first) is not type(second) or first != second or first.dtype != second.dtype:
        return False
    if isinstance(first, spaces.Box) and isinstance(second, spaces.Box):  # (the same type)
        return bool(
            np.array_equal(first.low, second.low) and np.array_equal(first.high, second.high)
        )
    return True


def _one_line(space: spaces.Space) -> str:
    """A space as text on one line (with its dtype)."""
    text = " ".join(str(space).split())
    return text if "dtype" in text or str(space.dtype) in text else f"{text} {space.dtype}"
