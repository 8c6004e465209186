"""An environment's spaces as dm_env_rpc tensor specs, and values both ways.

The hello's spaces become dm_env_rpc ``TensorSpec`` records: every array leaf of a ``Dict`` or
``Tuple`` space is one tensor, named by its path joined with dots (dm_env_rpc's own separator,
which ``DmEnvAdaptor(nested_tensors=True)`` folds back). One agent's tensors are named
``action`` and ``observation`` (``observation.camera`` for a ``Dict`` key); several agents'
are named by agent (``Red``, ``Blue.camera``). Beside the observations come ``reward`` and
``discount`` (the names ``DmEnvAdaptor`` reads), and with several agents each agent's own reward,
``rewards.NAME``.

A tensor's dtype, shape and bounds are the space's: a ``Discrete(n, start)`` is a scalar in
``[start, start + n - 1]``, a ``MultiBinary`` an int8 array in ``[0, 1]``, a ``Box`` its own
bounds (infinite ones included). An action is checked against its spec exactly (dtype, shape
after dm_env_rpc's broadcasting, bounds) before anything reaches the environment.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from dm_env_rpc.v1 import dm_env_rpc_pb2, tensor_spec_utils, tensor_utils
from gymnasium import spaces

__all__ = ["ActionRefused", "Leaf", "Specs"]

Path = tuple[str | int, ...]

_SCALARS = ("reward", "discount")
_REWARD = spaces.Box(-np.inf, np.inf, (), np.float64)  # unbounded: no bounds in its spec
_DISCOUNT = spaces.Box(0.0, 1.0, (), np.float64)
_ARRAYS = (spaces.Box, spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)


class ActionRefused(ValueError):
    """An action that does not fit its spec (the message says how)."""


class Leaf:
    """One tensor: its uid, name, path into the joint space, and the space it stands for."""

    def __init__(self, uid: int, name: str, path: Path, space: spaces.Space) -> None:
        self.uid, self.name, self.path, self.space = uid, name, path, space
        self.dtype = np.dtype(space.dtype)
        self.shape: tuple[int, ...] = tuple(space.shape or ())
        self.spec = dm_env_rpc_pb2.TensorSpec(
            name=name, shape=self.shape, dtype=tensor_utils.np_type_to_data_type(self.dtype)
        )
        low, high = _bounds(space)
        if low is not None and not (np.all(np.isneginf(low)) and np.all(np.isposinf(high))):
            tensor_spec_utils.set_bounds(self.spec, _compact(low), _compact(high))

    def pack(self, value: Any) -> dm_env_rpc_pb2.Tensor:
        """``value`` as this leaf's tensor."""
        return tensor_utils.pack_tensor(np.asarray(value, dtype=self.dtype), dtype=self.dtype)

    def unpack(self, tensor: dm_env_rpc_pb2.Tensor) -> Any:
        """The action in ``tensor``, checked against this leaf's spec.

        Raises:
            ActionRefused: another dtype, another shape, a value out of bounds, or no tensor.
        """
        shape = list(tensor.shape)  # checked first: a one-element tensor broadcasts to it
        if shape and (
            len(shape) != len(self.shape)
            or shape.count(-1) > 1
            or any(n not in (m, -1) for n, m in zip(shape, self.shape, strict=True))
        ):
            raise ActionRefused(
                f"action {self.name!r} has shape {shape[:8]}, its spec says {list(self.shape)}"
            )
        try:
            dtype = tensor_utils.get_tensor_type(tensor)
            if dtype != self.dtype:
                raise ActionRefused(f"action {self.name!r} is {dtype}, its spec says {self.dtype}")
            value = np.asarray(tensor_utils.unpack_tensor(tensor), dtype=self.dtype)
        except (ValueError, TypeError) as error:
            if isinstance(error, ActionRefused):
                raise
            raise ActionRefused(f"action {self.name!r} cannot be read: {error}") from None
        if value.shape != self.shape:
            raise ActionRefused(
                f"action {self.name!r} has shape {list(value.shape)}, its spec says "
                f"{list(self.shape)}"
            )
        action = value.item() if isinstance(self.space, spaces.Discrete) else value
        if not self.space.contains(action):
            raise ActionRefused(
                f"action {self.name!r} is out of its bounds: {value.tolist()!r:.200}"
            )
        return action

    def rest(self) -> Any:
        """What acts for this leaf before a step sends it: zeros, clipped into its bounds."""
        if isinstance(self.space, spaces.Discrete):
            return int(self.space.start)
        low, high = _bounds(self.space)
        zeros = np.zeros(self.shape, self.dtype)
        return zeros if low is None else np.clip(zeros, low, high).astype(self.dtype)


class Specs:
    """The tensors of an environment's hello: actions, observations, rewards and discount.

    Args:
        action_space: the hello's (joint) action space.
        observation_space: the hello's (joint) observation space.
        agents: the hello's agents; with more than one, the spaces are ``Dict`` spaces keyed
            by agent.

    Raises:
        ValueError: a space kind dm_env_rpc's tensors cannot carry.
    """

    def __init__(
        self, action_space: spaces.Space, observation_space: spaces.Space, agents: Sequence[str]
    ) -> None:
        several = len(agents) > 1
        self.action_space = action_space
        self.agents = tuple(agents) if several else ()
        self.actions = _numbered(_leaves(action_space, () if several else ("action",)))
        self.observations = _numbered(
            _leaves(observation_space, () if several else ("observation",))
        )
        scalars = [*_SCALARS, *(f"rewards.{agent}" for agent in self.agents)]
        start = len(self.observations) + 1
        self.scalars = {
            name: Leaf(uid, name, (), _DISCOUNT if name == "discount" else _REWARD)
            for uid, name in enumerate(scalars, start)
        }
        self.by_uid = {leaf.uid: leaf for leaf in (*self.observations, *self.scalars.values())}
        self.proto = dm_env_rpc_pb2.ActionObservationSpecs(
            actions={leaf.uid: leaf.spec for leaf in self.actions},
            observations={uid: leaf.spec for uid, leaf in self.by_uid.items()},
        )

    def action(self, tensors: Mapping[int, dm_env_rpc_pb2.Tensor], last: dict[int, Any]) -> Any:
        """The environment's action from a step's tensors; a leaf not sent repeats ``last``'s.

        ``last`` (uid to value) is updated only once every tensor has been accepted.

        Raises:
            ActionRefused: an unknown uid, or a tensor that does not fit its spec.
        """
        by_uid = {leaf.uid: leaf for leaf in self.actions}
        unknown = sorted(set(tensors) - set(by_uid))
        if unknown:
            raise ActionRefused(f"no action has uid {unknown[0]}: the actions are {sorted(by_uid)}")
        values = {uid: by_uid[uid].unpack(tensor) for uid, tensor in tensors.items()}
        last.update(values)
        chosen = {leaf.path: last.get(leaf.uid, leaf.rest()) for leaf in self.actions}
        return _assemble(self.action_space, (), chosen)

    def observation_tensors(
        self, uids: Iterable[int], observation: Any, scalars: Mapping[str, float]
    ) -> dict[int, dm_env_rpc_pb2.Tensor]:
        """The tensors asked for (``uids``, checked by :meth:`Specs.check_requested`)."""
        tensors = {}
        for uid in uids:
            leaf = self.by_uid[uid]
            value = scalars[leaf.name] if leaf.name in self.scalars else _at(observation, leaf.path)
            tensors[uid] = leaf.pack(value)
        return tensors

    def check_requested(self, uids: Iterable[int]) -> list[int]:
        """The distinct observation uids asked for, in order.

        Raises:
            ValueError: a uid no observation has.
        """
        distinct = list(dict.fromkeys(uids))
        for uid in distinct:
            if uid not in self.by_uid:
                raise ValueError(
                    f"no observation has uid {uid}: the observations are {sorted(self.by_uid)}"
                )
        return distinct


def _leaves(
    space: spaces.Space, prefix: tuple[str, ...], path: Path = ()
) -> list[tuple[str, Path, spaces.Space]]:
    """Every array leaf of ``space``: its name (``prefix`` and path, dotted), path and space."""
    if isinstance(space, spaces.Dict):
        return [
            leaf for key, sub in space.spaces.items() for leaf in _leaves(sub, prefix, (*path, key))
        ]
    if isinstance(space, spaces.Tuple):
        return [
            leaf for i, sub in enumerate(space.spaces) for leaf in _leaves(sub, prefix, (*path, i))
        ]
    if not isinstance(space, _ARRAYS):
        raise ValueError(f"dm_env_rpc's tensors cannot carry a {type(space).__name__} space")
    return [(".".join(map(str, (*prefix, *path))), path, space)]


def _numbered(leaves: list[tuple[str, Path, spaces.Space]]) -> list[Leaf]:
    """The leaves with uids from 1, as dm_env_rpc numbers tensors."""
    return [Leaf(uid, name, path, space) for uid, (name, path, space) in enumerate(leaves, 1)]


def _assemble(space: spaces.Space, path: Path, values: Mapping[Path, Any]) -> Any:
    """The value of ``space`` whose leaves are ``values`` (by path)."""
    if isinstance(space, spaces.Dict):
        return {key: _assemble(sub, (*path, key), values) for key, sub in space.spaces.items()}
    if isinstance(space, spaces.Tuple):
        return tuple(_assemble(sub, (*path, i), values) for i, sub in enumerate(space.spaces))
    return values[path]


def _at(value: Any, path: Path) -> Any:
    """The leaf of ``value`` at ``path``."""
    for key in path:
        value = value[key]
    return value


def _bounds(space: spaces.Space) -> tuple[Any, Any]:
    """A leaf space's inclusive bounds (``None, None`` where it has none)."""
    if isinstance(space, spaces.Box):
        return space.low, space.high
    if isinstance(space, spaces.Discrete):
        return int(space.start), int(space.start + space.n - 1)
    if isinstance(space, spaces.MultiDiscrete):
        return space.start, space.start + space.nvec - 1
    if isinstance(space, spaces.MultiBinary):
        return 0, 1
    return None, None


def _compact(bound: Any) -> Any:
    """A bound as one scalar where every element is the same (a smaller spec on the wire)."""
    array = np.asarray(bound)
    if array.size and np.all(array == array.flat[0]):
        return array.flat[0]
    return array
