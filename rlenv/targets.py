"""``MODULE:CLASS`` targets, and the two names of the shipped examples.

The examples are one set of files with two names. A checkout keeps them at its top, in
``examples/``, and imports them as ``examples.cartpole``; an installed rlenv has them inside its
own package, as ``rlenv.examples.cartpole`` (the wheel installs no top-level ``examples``, which
other distributions and users' own folders use). The registered ids name the installed form.

So that a file is never loaded under both names in one process (two classes of the same
name), each situation has one canonical form, and :func:`import_module` takes it:

- **in a checkout** whose ``examples/`` is importable as ``examples`` (the checkout's folder,
  beside its ``rlenv/``): ``examples.X``; ``rlenv.examples.X`` (a registered id) is loaded as
  ``examples.X``;
- **anywhere else** (an installed rlenv, or a checkout's editable install used from another
  folder): ``rlenv.examples.X``; ``examples.X`` (say, a recording made in a checkout) is loaded
  as ``rlenv.examples.X`` when no module of that name imports (a user's own ``examples``
  package wins).

Nothing here imports the runtime, so the client uses it too.
"""

from __future__ import annotations

import importlib
import importlib.util
from pathlib import Path
from types import ModuleType

__all__ = ["CHECKOUT_EXAMPLES", "EXAMPLES", "import_module", "module_name", "same_target"]

EXAMPLES = "rlenv.examples"
"""The examples' package in an installed rlenv (and what the registered ids name)."""
CHECKOUT_EXAMPLES = "examples"
"""The examples' package in a checkout (``examples/``, beside ``rlenv/``)."""

_RLENV_DIR = Path(__file__).resolve().parent


def _split(name: str) -> tuple[str, str] | None:
    """``(package, rest)`` when ``name`` is an example's module under either name, else None."""
    for package in (EXAMPLES, CHECKOUT_EXAMPLES):
        if name == package or name.startswith(f"{package}."):
            return package, name[len(package) :]
    return None


def _in_checkout() -> bool:
    """Whether this rlenv is a checkout whose ``examples/`` imports as ``examples`` here."""
    if (_RLENV_DIR / "examples").is_dir():
        return False  # installed: the examples are inside the package
    try:
        spec = importlib.util.find_spec(CHECKOUT_EXAMPLES)
    except (ImportError, ValueError):  # a module without a spec in sys.modules
        return False
    if spec is None or not spec.submodule_search_locations:
        return False
    checkout = _RLENV_DIR.parent / CHECKOUT_EXAMPLES
    return any(Path(folder).resolve() == checkout for folder in spec.submodule_search_locations)


def module_name(name: str) -> str:
    """The name the module ``name`` is imported under in this process (see above).

    ``rlenv.examples.X`` becomes ``examples.X`` in a checkout; every other name stays as it is
    (``examples.X`` falls back to ``rlenv.examples.X`` only on import, in :func:`import_module`).
    """
    split = _split(name)
    if split is not None and split[0] == EXAMPLES and _in_checkout():
        return CHECKOUT_EXAMPLES + split[1]
    return name


def _names_missing(error: ModuleNotFoundError, name: str) -> bool:
    """Whether ``error`` says ``name`` itself (or a package above it) does not exist."""
    return error.name is not None and f"{name}.".startswith(f"{error.name}.")


def import_module(name: str) -> ModuleType:
    """Import ``name``, an example under its canonical name here (see the module's docstring).

    Raises:
        ModuleNotFoundError: the module exists under neither name (the error for ``name``).
        ImportError: anything else the module's own import raised.
    """
    name = module_name(name)
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as error:
        split = _split(name)
        if split is None or not _names_missing(error, name):
            raise  # not an example, or the module imports something missing: say so
        package, rest = split
        other = (CHECKOUT_EXAMPLES if package == EXAMPLES else EXAMPLES) + rest
        try:
            return importlib.import_module(other)
        except ModuleNotFoundError as second:
            if _names_missing(second, other):
                raise error from None
            raise


def same_target(first: str, second: str) -> bool:
    """Whether two ``MODULE:CLASS`` targets name the same class.

    Both names of an example count as one (``examples.cartpole:X`` and
    ``rlenv.examples.cartpole:X``).
    """

    def installed(target: str) -> str:
        module, colon, attribute = target.partition(":")
        split = _split(module)
        return (EXAMPLES + split[1] if split else module) + colon + attribute

    return installed(first) == installed(second)
