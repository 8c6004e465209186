"""Names that moved out of the protocol's modules, kept at their old place for one release.

A module whose names moved answers an old one from its ``__getattr__`` (PEP 562) with
:func:`moved_name`: the object at its new place, with a ``DeprecationWarning`` naming that place.
The new module is imported by its name, and only then: it usually imports the old one
(``space_json`` imports ``spaces``), so an import statement would close a cycle. Modules that
moved as a whole are ``rlenv/_moves.py``'s.
"""

from __future__ import annotations

import importlib
import warnings
from typing import Any

__all__ = ["MOVED_NAMES", "moved_name"]

MOVED_NAMES: dict[str, dict[str, tuple[str, str, str]]] = {
    "rlenv.protocol.spaces": {
        "space_to_json": (
            "rlenv.protocol.space_json",
            "space_to_json_text",  # (the text)
            "a space's one JSON form",
        ),
        "space_from_json": (
            "rlenv.protocol.space_json",
            "space_from_json",
            "a space's one JSON form",
        ),
    },
}
"""By old module, each moved name's new module, its new name, and why it moved."""


def moved_name(module: str, name: str) -> Any:
    """``module``'s old ``name`` at its new place, with a ``DeprecationWarning`` naming it.

    Call it from ``module``'s ``__getattr__``: the warning points at the line that asked for
    the name.

    Raises:
        AttributeError: ``name`` did not move out of ``module`` (as for any missing attribute).
    """
    moved = MOVED_NAMES.get(module, {}).get(name)
    if moved is None:
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    new_module, new_name, why = moved
    place = importlib.import_module(new_module)
    warnings.warn(
        f"{module}.{name} moved to {new_module}.{new_name} ({why}); the old name goes "
        "in the next release",
        DeprecationWarning,
        stacklevel=3,
    )
    return getattr(place, new_name)
