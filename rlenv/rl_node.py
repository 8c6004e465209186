"""RLNode: what agents and worlds share: configuration by the client, and the episode's RNG."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from rlenv.errors import ErrorCode, RequestError
from rlenv.node import NOTIFICATION_EXIT_TREE, Node

if TYPE_CHECKING:
    from rlenv.environment import RLEnvironment

__all__ = ["RLNode"]


class RLNode(Node):
    """Base of :class:`~rlenv.agent.RLAgent` and :class:`~rlenv.world.RLEnvWorld`.

    Attributes:
        configurable: names of the attributes a client may set through ``configure``. The
            default :meth:`configure` sets them, keeping each attribute's type (an int may set a
            float), and refuses any other key.
    """

    configurable: ClassVar[tuple[str, ...]] = ()

    _environment: RLEnvironment | None = None

    @property
    def environment(self) -> RLEnvironment:
        """The environment this node belongs to (its nearest RLEnvironment ancestor).

        Raises:
            RuntimeError: the node is not below an environment.
        """
        environment = self._environment
        if environment is None:
            from rlenv.environment import RLEnvironment

            ancestor = self.parent
            while not (ancestor is None or isinstance(ancestor, RLEnvironment)):
                ancestor = ancestor.parent
            if ancestor is None:
                raise RuntimeError(f"{self!r} is not below an RLEnvironment")
            environment = ancestor
            if self.is_inside_tree():  # valid until the node leaves the tree
                self._environment = environment
        return environment

    def notification(self, what: int) -> None:
        """Deliver a lifecycle notification (and forget the cached environment on exit)."""
        if what == NOTIFICATION_EXIT_TREE:
            self._environment = None
        super().notification(what)

    @property
    def np_random(self) -> np.random.Generator:
        """The episode's random generator, seeded by ``reset(seed=...)``.

        Use it for all randomness, so that episodes are reproducible.
        """
        return self.environment.np_random

    def configure(self, config: Mapping[str, Any]) -> None:
        """Apply a configuration sent by the client.

        Raises:
            RequestError: ``invalid_config``, naming the key, for a key not in
                :attr:`configurable` or a value of the wrong type.
        """
        for key, value in config.items():
            setattr(self, key, _configured_value(self, key, value))

    def check_config(self, config: Mapping[str, Any]) -> None:
        """Check a configuration without applying it (the same rules as :meth:`configure`).

        Raises:
            RequestError: as :meth:`configure` would.
        """
        for key, value in config.items():
            _configured_value(self, key, value)


def _configured_value(node: RLNode, key: Any, value: Any) -> Any:
    owner = type(node).__name__
    if key not in node.configurable:
        accepted = ", ".join(node.configurable) or "nothing"
        raise RequestError(
            ErrorCode.INVALID_CONFIG, f"{owner} has no configurable {key!r}; it accepts {accepted}"
        )
    current = getattr(node, key)
    if current is None:
        ok = True
    elif isinstance(current, bool):
        ok = isinstance(value, bool)
    elif isinstance(current, int | float):
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        if ok and isinstance(current, int):
            ok = isinstance(value, int)
        elif ok:
            value = float(value)
    else:
        ok = isinstance(value, type(current))
    if not ok:
        raise RequestError(
            ErrorCode.INVALID_CONFIG,
            f"{owner}.{key} must be a {type(current).__name__}, got {value!r:.60}",
        )
    return value
