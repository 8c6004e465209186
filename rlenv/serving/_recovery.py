"""Recovery: an instance's environment rebuilt from its class after user code raised.

Once user code raised while serving the controller (or was stopped half way), the environment
is not to be trusted: it is marked broken (:meth:`Recovery.mark_broken`), and the next request
that starts an episode builds it again from its class first (:meth:`Recovery.rebuild`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from rlenv.environment import RLEnvironment
from rlenv.serving._settings import Settings
from rlenv.tree import SceneTree

__all__ = ["Recovery"]

logger = logging.getLogger(__name__)


class Recovery:
    """Why an instance's environment is broken, and its rebuild from its class.

    Args:
        given: the environment the instance was given, or its class. Only a class can be
            built again, and only if it did not opt out (``rebuild_after_error = False``).

    Attributes:
        broken: why the next reset rebuilds the environment from its class (user code raised
            while serving the controller), or ``None``.
    """

    __slots__ = ("_class", "broken")

    def __init__(self, given: RLEnvironment | type[RLEnvironment]) -> None:
        self._class: type[RLEnvironment] | None = None  # what a rebuild builds (or none)
        if isinstance(given, type) and given.rebuild_after_error:
            self._class = given
        self.broken: str | None = None

    def mark_broken(self, error: BaseException | str) -> None:
        """User code raised ``error`` (or stopped half way, ``why``): the next reset rebuilds.

        Nothing happens if the environment opted out (``rebuild_after_error = False``) or was
        given as an object rather than its class (there is nothing to build it again from).
        """
        if self._class is not None and self.broken is None:
            why = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
            self.broken = why[:_MAX_WHY]

    def rebuild(
        self,
        old: RLEnvironment,
        old_tree: SceneTree,
        settings: Settings,
        enter: Callable[[RLEnvironment], SceneTree],
    ) -> str:
        """Build the environment again from its class, in a new tree; why it was rebuilt.

        The new environment is constructed, enters its tree and is ready, as at the start; it
        takes over the configuration, the random generator and real time of the one it
        replaces (as a reset keeps them), and no episode runs. If building raises, the
        instance keeps the environment it had (and stays :attr:`broken`).

        Args:
            old: the environment it replaces.
            old_tree: the tree ``old`` is in (the new one takes over its real time).
            settings: the instance's configuration, which the new environment takes over.
            enter: makes the new environment the instance's, in a new tree that it returns
                (nothing of the instance changes if it raises).

        Raises:
            RuntimeError: the instance has no class to rebuild from.
        """
        if self._class is None:
            raise RuntimeError(
                "this instance was given an environment object: it has no class to rebuild it from"
            )
        why = self.broken or "asked"
        config = settings.state()
        generator = old.np_random
        environment = self._class()
        tree = enter(environment)
        environment.np_random = generator
        tree.real_time = old_tree.real_time
        settings.carry(config)
        self.broken = None
        try:
            old_tree.root.remove_child(old)
        except Exception as error:  # the broken environment's _exit_tree: its own business
            logger.warning(
                "the replaced %s raised leaving its tree", type(old).__name__, exc_info=error
            )
        logger.warning("%s rebuilt from its class after %s", type(old).__name__, why)
        return why


_MAX_WHY = 500  # characters of an error kept to say why an environment was rebuilt
