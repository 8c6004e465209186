"""Deprecated: tree views moved to :mod:`rlenv.views` (a query of any tree, not only 2D).

``from rlenv.scene2d.views import View`` keeps working for one release, with a
:class:`DeprecationWarning` naming the new place; ``rlenv.View`` and ``rlenv.view`` warn nothing.
"""

from __future__ import annotations

import warnings
from typing import Any

_MOVED = frozenset({"View", "view"})
__all__: list[str] = []


def __getattr__(name: str) -> Any:
    if name not in _MOVED:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(f"rlenv.scene2d.views.{name} moved to rlenv.views.{name} (also rlenv.{name}); "
                  "import it from there", DeprecationWarning, stacklevel=2)
    from rlenv import views

    return getattr(views, name)
