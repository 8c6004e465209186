"""Why a ``MODULE:CLASS`` target did not load, with what was probably meant.

``examples/cartpole.py:CartPoleEnvironment`` names a file, not a module ("drop .py":
``examples.cartpole``); ``examples.cartpole:CartpoleEnvironment`` is one letter off a class
that exists ("did you mean CartPoleEnvironment?", found with :mod:`difflib`).
"""

from __future__ import annotations

import difflib
import sys

from rlenv.targets import module_name as canonical_name

__all__ = ["explain_target_error"]


def explain_target_error(error: Exception, target: str) -> str | None:
    """``error`` (from loading ``target``) in words with a hint, or ``None`` if none helps."""
    module_name, _, class_name = target.partition(":")
    if module_name.endswith(".py") or "/" in module_name or "\\" in module_name:
        dotted = module_name.replace("\\", "/").removeprefix("./").removesuffix(".py")
        return (
            f"{target!r} names a file; MODULE:CLASS names a module as Python imports it: "
            f"drop .py ({dotted.replace('/', '.')}:{class_name})"
        )
    if isinstance(error, ModuleNotFoundError):
        if error.name is None or not f"{module_name}.".startswith(f"{error.name}."):
            return None  # the module itself imports something missing: the message says what
        return (
            f"{error}: run rlenv from the folder that holds the module, or put that folder "
            "on PYTHONPATH"
        )
    module = sys.modules.get(canonical_name(module_name))
    if not isinstance(error, ImportError) or module is None or hasattr(module, class_name):
        return None
    classes = [name for name in dir(module) if isinstance(getattr(module, name), type)]
    close = difflib.get_close_matches(class_name, classes, n=1)
    return f"{error}: did you mean {close[0]}?" if close else None
