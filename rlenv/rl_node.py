"""RLNode: what agents, worlds and environments share (client configuration, the episode's RNG).

Its own module, so that :mod:`rlenv.agent`, :mod:`rlenv.world` and :mod:`rlenv.environment` each
define one class without importing each other in a circle: a node finds its environment by
the class attribute ``_IS_ENVIRONMENT``, not by importing its class.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar, cast

import numpy as np

from rlenv.node import NOTIFICATION_EXIT_TREE, Node
from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.serving._properties import conform

if TYPE_CHECKING:
    from rlenv.environment import RLEnvironment

__all__ = ["RLNode"]


class RLNode(Node):
    """What agents, worlds and environments share: client configuration, the episode's RNG.

    Attributes:
        configurable: names of the attributes a client may set through ``configure``. The
            default :meth:`configure` sets them, keeping each attribute's type (an int may set a
            float), and refuses any other key.
    """

    configurable: ClassVar[tuple[str, ...]] = ()
    _IS_ENVIRONMENT: ClassVar[bool] = False  # True on RLEnvironment only
    _TREE_STATE = Node._TREE_STATE | {"_RLNode__environment"}  # a cache, valid in a tree

    __environment: RLEnvironment | None = None

    @property
    def environment(self) -> RLEnvironment:
        """The environment this node belongs to (its nearest RLEnvironment, itself included).

        Raises:
            RuntimeError: the node is not below an environment.
        """
        environment = self.__environment
        if environment is None:
            node: Node | None = self
            while not (node is None or getattr(node, "_IS_ENVIRONMENT", False)):
                node = node.parent
            if node is None:
                raise RuntimeError(f"{self!r} is not below an RLEnvironment")
            environment = cast("RLEnvironment", node)  # only RLEnvironment sets the flag
            if self.is_inside_tree():  # valid until the node leaves the tree
                self.__environment = environment
        return environment

    def notification(self, what: int) -> None:
        """Deliver a lifecycle notification (and forget the cached environment on exit)."""
        if what == NOTIFICATION_EXIT_TREE:
            self.__environment = None
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
            setattr(self, key, self._configured(key, value))

    def check_config(self, config: Mapping[str, Any]) -> None:
        """Check a configuration without applying it (the same rules as :meth:`configure`).

        Raises:
            RequestError: as :meth:`configure` would.
        """
        for key, value in config.items():
            self._configured(key, value)

    def _configured(self, key: Any, value: Any) -> Any:
        owner = type(self).__name__
        if key not in self.configurable:
            accepted = ", ".join(map(str, self.configurable)) or "nothing"
            raise RequestError(
                ErrorCode.INVALID_CONFIG,
                f"{owner} has no configurable {key!r}; it accepts {accepted}",
            )
        try:
            return conform(getattr(self, key), value)
        except TypeError as error:
            raise RequestError(ErrorCode.INVALID_CONFIG, f"{owner}.{key} {error}") from None
