"""Old import paths of moved modules, kept for one release with a ``DeprecationWarning``.

:func:`forward` maps an old module name (and every module under it) to its new place:
``import rlenv.http.app`` then gives the module ``rlenv_tools.http.app`` itself (one module, not
a copy: its classes are the same objects) and warns, naming the new place. Nothing is imported
until an old name is; a name that was not moved is left to Python's own finders.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import warnings
from collections.abc import Mapping, Sequence
from types import CodeType, FrameType, ModuleType

__all__ = ["forward"]


class _Forwarder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old name's module at its new place (first on ``sys.meta_path``)."""

    def __init__(self) -> None:
        self.moves: dict[str, str] = {}

    def new_name(self, name: str) -> str | None:
        """The new name of module ``name``, or None when it did not move.

        A module moved twice resolves to its last place in one step.
        """
        moved = None
        for _ in range(len(self.moves)):  # no chain is longer than the table
            step = self._moved_once(moved or name)
            if step is None:
                break
            moved = step
        return moved

    def _moved_once(self, name: str) -> str | None:
        for old, new in self.moves.items():
            if name == old or name.startswith(old + "."):
                return new + name[len(old) :]
        return None

    def find_spec(
        self, fullname: str, path: Sequence[str] | None = None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        """A spec that this loader fulfils for a moved name; None for any other."""
        new = self.new_name(fullname)
        found = importlib.util.find_spec(new) if new is not None else None
        if found is None:
            return None
        spec = importlib.machinery.ModuleSpec(
            fullname, self, is_package=found.submodule_search_locations is not None
        )
        spec.loader_state = new
        return spec

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        """The module at its new place, with a warning that names it."""
        new = spec.loader_state
        warnings.warn(
            f"{spec.name} moved to {new}; the old name goes in the next release",
            DeprecationWarning,
            stacklevel=_caller_level(),
        )
        return importlib.import_module(new)

    def exec_module(self, module: ModuleType) -> None:
        """Nothing: the module ran at its new place."""

    def get_code(self, fullname: str) -> CodeType | None:
        """The code of the new place's module (``python -m OLD`` runs it)."""
        new = self.new_name(fullname)
        if new is None:
            return None
        spec = importlib.util.find_spec(new)
        loader = spec.loader if spec is not None else None
        return loader.get_code(new) if isinstance(loader, importlib.abc.InspectLoader) else None


def _caller_level() -> int:
    """The ``stacklevel`` of the first frame outside this module and the import machinery.

    ``warnings.warn`` does not count the machinery's frames (``importlib._bootstrap``); this
    does not either.
    """
    frame: FrameType | None = sys._getframe(1)
    level = 1
    while frame is not None:
        filename = frame.f_code.co_filename
        if filename == __file__:
            level += 1
        elif not ("importlib" in filename and "_bootstrap" in filename):
            break
        frame = frame.f_back
    return level


_FORWARDER = _Forwarder()


def forward(moves: Mapping[str, str]) -> None:
    """Keep each old module name of ``moves`` (old name to new name) importable, with a warning.

    The modules under an old name follow it: ``{"rlenv.http": "rlenv_tools.http"}`` forwards
    ``rlenv.http.app`` to ``rlenv_tools.http.app`` too.
    """
    _FORWARDER.moves.update(moves)
    if _FORWARDER not in sys.meta_path:
        sys.meta_path.insert(0, _FORWARDER)
