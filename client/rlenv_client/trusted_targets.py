"""Whether the target that a recording or a server names may be imported (importing runs it).

A recording's ``target`` (and a served hello's, which the inspector's recent episodes carry) is
text from outside: importing the module it names runs that module's code. So ``rlenv replay``,
:class:`~rlenv_tools.timeline.Timeline`, ``rlenv dataset create``, ``rlenv replay --inspect``
and ``rlenv inspect`` import such a target only when its top-level package is **installed**,
which here means both:

1. Python's import system finds it with the current folder and the recording's folder (and
   ``''``) left out of ``sys.path``: in site-packages, an editable install, a ``PYTHONPATH``
   folder other than those two; and
2. neither of those two folders holds a module or package of that name of its own (a
   ``python -m`` process, which the tools start, puts the current folder first, and a module
   planted beside a recording would be the one imported when run there).

rlenv's own packages count as installed: ``rlenv`` and its examples (``rlenv.examples.X``, a
checkout's ``examples.X``), where what the two folders hold of them is rlenv's own files.

Anything else is imported only when the person running the tool says so, in one of two ways:
naming the target (``--target MODULE:CLASS``, ``target=`` in Python), or trusting the file
(``--trust-target``, ``trust_target=True``), as Hugging Face's ``trust_remote_code`` works.
No environment variable does it: a downloaded folder could set one. Either way, a target that
is not an :class:`~rlenv.RLEnvironment` subclass is refused when it loads.
"""

from __future__ import annotations

import importlib.machinery
import os
import sys
from collections.abc import Iterable
from importlib.machinery import ModuleSpec
from pathlib import Path

import rlenv

__all__ = ["UntrustedTargetError", "check_target"]

_RLENV = Path(rlenv.__file__).resolve().parent
_OWN = frozenset({_RLENV, _RLENV / "examples", _RLENV.parent / "examples"})  # rlenv's own files
_LOADERS = (
    (importlib.machinery.ExtensionFileLoader, importlib.machinery.EXTENSION_SUFFIXES),
    (importlib.machinery.SourceFileLoader, importlib.machinery.SOURCE_SUFFIXES),
    (importlib.machinery.SourcelessFileLoader, importlib.machinery.BYTECODE_SUFFIXES),
)


class UntrustedTargetError(ValueError):
    """A file or a server names a target that is not installed; the message says what to do."""


def check_target(target: str, *, named_by: str, folder: Path | None) -> None:
    """Refuse ``target`` unless its top-level package is installed (see the module docstring).

    Args:
        target: ``MODULE:CLASS``, as the file or the server names it.
        named_by: who names it, for the message (``the recording PATH``).
        folder: the recording's folder (``None``: a server's, or an episode made in Python).

    Raises:
        UntrustedTargetError: saying why, and the two ways on (``--target``, ``--trust-target``).
    """
    module = target.partition(":")[0]
    top = module.partition(".")[0]
    folders = _untrusted_folders(folder)
    own = top in ("rlenv", "examples")  # examples.X loads rlenv.examples.X where none is found
    allowed = _OWN if own else frozenset(_installed(top, folders))
    why = None if own or allowed else f"no installed package {top!r:.60} has it"
    for place in folders:
        planted = _source(importlib.machinery.FileFinder(str(place), *_LOADERS).find_spec(top))
        if planted is not None and planted not in allowed:
            why = f"{planted} holds it, not an installed package"
            break
    if why is not None:
        raise UntrustedTargetError(
            f"{named_by} names the target {target!r:.120}: {why}, and importing it would run "
            "its code. Name the environment to run with --target MODULE:CLASS (target= in "
            "Python), or trust the file with --trust-target (trust_target=True)"
        )


def _untrusted_folders(folder: Path | None) -> list[Path]:
    places = [Path(os.getcwd()).resolve()]
    if folder is not None and folder.resolve() not in places:
        places.append(folder.resolve())
    return places


def _installed(top: str, folders: Iterable[Path]) -> list[Path]:
    """Where the import system finds ``top`` with ``folders`` left out of ``sys.path``."""
    left_out = set(folders)
    path = [entry for entry in sys.path if entry and Path(entry).resolve() not in left_out]
    found = []
    for finder in sys.meta_path:
        find = getattr(finder, "find_spec", None)
        if find is None:
            continue
        try:
            spec = find(top, path) if finder is importlib.machinery.PathFinder else find(top, None)
        except (ImportError, ValueError, TypeError):  # a finder with views of its own
            continue
        source = _source(spec)
        if source is not None:
            found.append(source)
        elif spec is not None:  # built in, frozen: nothing on disk to plant
            found.append(Path(top))
    return found[:1]


def _source(spec: ModuleSpec | None) -> Path | None:
    """The file or folder a spec loads from (a package's folder), resolved."""
    if spec is None:
        return None
    if spec.submodule_search_locations:
        return Path(next(iter(spec.submodule_search_locations))).resolve()
    if spec.origin and spec.has_location:
        return Path(spec.origin).resolve()
    return None
