"""The modules that moved to the tools (rlenv_tools) keep their old names for one release: an
old import gives the very module at its new place, with a ``DeprecationWarning`` naming it.

datasets, policies and onnx_actors need extras (minari; torch) to import at all: they are
forwarded as the others are (rlenv_client/__init__.py lists them). Each check runs in a new
interpreter: a module imported once is not imported (nor warned) again.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

MOVES = {
    "rlenv.cli": "rlenv_tools.cli",
    "rlenv.http": "rlenv_tools.http",
    "rlenv.http.app": "rlenv_tools.http.app",
    **{
        f"rlenv_client.{name}": f"rlenv_tools.{name}"
        for name in (
            "compliance",
            "demonstrations",
            "forking",
            "inspector",
            "observations",
            "timeline",
            "training_speed",
        )
    },
    # moved, then private: a chain resolves in one step, with one warning
    "rlenv_client.origins": "rlenv_tools._origins",
    "rlenv_client.bench": "rlenv_tools._bench",
    "rlenv_client.inspector.web": "rlenv_tools.inspector._web",
    # private (a leading underscore): the modules that are not the public API
    "rlenv.serving.parts": "rlenv.serving._parts",
    "rlenv.transport.procfs": "rlenv.transport._procfs",
    "rlenv_tools.http.routes": "rlenv_tools.http._routes",
}

_CHECK = """
import importlib, json, sys, warnings
old, new = sys.argv[1], sys.argv[2]
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    exec(f"import {old}")  # an import statement, as a user's
module = sys.modules[old]
print(json.dumps({"same": module is importlib.import_module(new), "name": module.__name__,
                  "warnings": [[w.category.__name__, str(w.message), w.filename]
                               for w in caught if issubclass(w.category, DeprecationWarning)]}))
"""


def _python(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(("old", "new"), sorted(MOVES.items()))
def test_an_old_import_gives_the_moved_module_and_warns_naming_its_place(
    old: str, new: str
) -> None:
    done = _python("-c", _CHECK, old, new)
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout)
    assert found["same"] and found["name"] == new
    messages = [message for _, message, _ in found["warnings"]]
    assert f"{old} moved to {new}; the old name goes in the next release" in messages
    assert {filename for *_, filename in found["warnings"]} == {"<string>"}  # the importer's line


def test_names_from_an_old_module_are_the_new_ones() -> None:
    code = (
        "import warnings\nwarnings.simplefilter('error', DeprecationWarning)\n"
        "from rlenv_tools.inspector import Inspector\nfrom rlenv_tools.cli import main\n"
        "warnings.simplefilter('ignore', DeprecationWarning)\n"
        "from rlenv_client.inspector import Inspector as Old\nfrom rlenv.cli import main as m\n"
        "from rlenv_client import forking\n"
        "assert Old is Inspector and m is main and forking.__name__ == 'rlenv_tools.forking'\n"
    )
    done = _python("-c", code)
    assert done.returncode == 0, done.stderr


def test_every_private_module_keeps_its_public_name_for_one_release() -> None:
    code = (
        "import importlib, warnings\nfrom rlenv._moves import MOVES\n"
        "warnings.simplefilter('ignore', DeprecationWarning)\n"
        "private = {old: new for old, new in MOVES.items() if '._' in new}\n"
        "for old, new in private.items():\n"
        "    try:\n"
        "        module = importlib.import_module(new)\n"
        "    except ModuleNotFoundError as missing:  # an extra's (torch) not installed\n"
        "        assert missing.name != new, new\n"
        "        continue\n"
        "    assert importlib.import_module(old) is module, old\n"
        "print(len(private))\n"
    )
    done = _python("-c", code)
    assert done.returncode == 0, done.stderr
    assert int(done.stdout) >= 50


def test_a_name_that_did_not_move_is_not_found_by_the_forwarder() -> None:
    done = _python("-c", "import rlenv_client.no_such_module")
    assert done.returncode == 1 and "ModuleNotFoundError" in done.stderr
    done = _python("-c", "import rlenv_client.inspector.no_such_module")
    assert (
        done.returncode == 1
        and "No module named 'rlenv_client.inspector.no_such_module'" in done.stderr
    ), done.stderr


def test_python_m_of_an_old_package_runs_its_new_main_and_python_m_rlenv_stays() -> None:
    old = _python("-W", "always::DeprecationWarning", "-m", "rlenv_client.inspector", "--help")
    assert old.returncode == 0, old.stderr
    assert old.stdout.startswith("usage: rlenv inspect")
    assert "rlenv_client.inspector moved to rlenv_tools.inspector" in old.stderr
    command = _python("-W", "error::DeprecationWarning", "-m", "rlenv", "--help")
    assert command.returncode == 0, command.stderr
    assert command.stdout.startswith("usage: rlenv") and "serve" in command.stdout
