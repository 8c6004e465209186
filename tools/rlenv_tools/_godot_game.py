"""The game's process for Godot RL Agents: a server of TARGET, the bridge, and the launcher.

:func:`play` serves TARGET (a registered id, ``MODULE:CLASS`` or a running server's
``HOST:PORT``) and answers a godot-rl trainer with :class:`~rlenv_tools._godot_bridge.GodotBridge`.
:func:`write_launcher` writes an executable that godot-rl runs as its ``env_path``, as it runs
an exported game: it reads the command line as a Godot game's ``Sync`` node does
(:func:`godot_arguments`).
"""

from __future__ import annotations

import json
import os
import stat
import sys
from collections.abc import Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import rlenv
import rlenv_client
import rlenv_tools
from rlenv_client._addresses import is_address
from rlenv_client.client import Client
from rlenv_client.launcher import ServerProcess
from rlenv_client.registration import ENVIRONMENTS
from rlenv_tools._godot_bridge import GodotBridge, dial_trainer

__all__ = [
    "GODOT_FLAGS",
    "Game",
    "config_value",
    "godot_arguments",
    "launcher_command",
    "play",
    "write_launcher",
]

DEFAULT_PORT = 11008
"""godot-rl's trainer's port unless told otherwise (``GodotEnv.DEFAULT_PORT``)."""

GODOT_FLAGS = frozenset({"disable-render-loop", "headless", "fixed-fps", "speedup"})
"""Flags godot-rl gives a game that mean nothing to a lockstep server (it runs as fast as it
can, renders nothing unless asked): taken and ignored."""


@dataclass
class Game:
    """What one game process plays: the launcher's settings and the command line's.

    Attributes:
        target: a registered id, ``MODULE:CLASS`` or ``HOST:PORT``.
        port: the trainer's port on 127.0.0.1.
        instances: instances of the server started for TARGET (not for ``HOST:PORT``).
        env_seed: seeds the instances' first resets; ``None``: unseeded.
        repeat_action: ticks per action; ``None``: the server's.
        max_episode_steps: a time limit (steps); ``None``: a registered id's, if any.
        config: settings given to the environment first (``--KEY=VALUE``).
        timeout: seconds to reach the trainer, and for each of the server's answers.
    """

    target: str
    port: int = DEFAULT_PORT
    instances: int = 1
    env_seed: int | None = None
    repeat_action: int | None = None
    max_episode_steps: int | None = None
    config: dict[str, Any] = field(default_factory=dict)
    timeout: float = 60.0


def play(game: Game) -> None:
    """Serve ``game.target`` and answer the trainer on ``game.port`` until it closes.

    Raises:
        ConnectionRefusedError: no trainer listened within ``game.timeout``.
        ServerStartError: TARGET's server did not start.
        RemoteError: the server refused a setting of ``game.config`` or a request.
        GodotWireError: TARGET's spaces do not fit godot-rl's wire, or the trainer sent
            something it never sends.
    """
    registered = ENVIRONMENTS.get(game.target)
    target = registered.target if registered is not None else game.target
    limit = game.max_episode_steps
    if limit is None and registered is not None:
        limit = registered.max_episode_steps
    with ExitStack() as stack:
        if is_address(target):
            client = stack.enter_context(Client(target, timeout=game.timeout))
        else:
            server = ServerProcess(target, args=["--instances", str(game.instances)])
            stack.callback(server.close)
            client = stack.enter_context(Client(server.address, timeout=game.timeout))
        if game.config:
            client.configure(**game.config)
        trainer = stack.enter_context(dial_trainer("127.0.0.1", game.port, game.timeout))
        GodotBridge(
            client,
            trainer,
            env_seed=game.env_seed,
            repeat_action=game.repeat_action,
            max_episode_steps=limit,
        ).serve()


def godot_arguments(argv: Sequence[str]) -> dict[str, str]:
    """A game's command line as Godot's ``Sync`` reads it: ``--KEY=VALUE`` as ``{KEY: VALUE}``.

    A flag without ``=`` maps to ``""``; a bare word after ``--fixed-fps`` (godot-rl passes
    ``--fixed-fps N``) is its value.

    Raises:
        ValueError: an argument that is not a ``--`` flag.
    """
    arguments: dict[str, str] = {}
    words = list(argv)
    while words:
        word = words.pop(0)
        if not word.startswith("--") or len(word) == 2:
            raise ValueError(f"{word!r} is no --KEY=VALUE flag")
        key, equals, value = word[2:].partition("=")
        if not equals and key == "fixed-fps" and words and not words[0].startswith("--"):
            value = words.pop(0)
        arguments[key] = value
    return arguments


def launcher_command(argv: Sequence[str], command: Sequence[str]) -> list[str]:
    """A launcher's ``rlenv`` command line: ``command`` (written in it) and godot-rl's flags.

    ``--port=``, ``--env_seed=`` and ``--action_repeat=`` are the trainer's; flags in
    :data:`GODOT_FLAGS` are ignored; any other ``--KEY=VALUE`` configures the environment
    (``VALUE`` read as JSON where it is JSON, else as a string), after the launcher's own.
    """
    words = list(command)
    for key, value in godot_arguments(argv).items():
        if key in ("port", "env_seed", "action_repeat"):
            words += [f"--{key.replace('_', '-')}", value]
        elif key not in GODOT_FLAGS:
            words += ["--set", f"{key}={value}"]
    return words


def config_value(text: str) -> Any:
    """A ``--KEY=VALUE``'s value: JSON where it parses (numbers, true, lists), else the text."""
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def write_launcher(path: Path, command: Sequence[str]) -> None:
    """Write an executable at ``path`` that godot-rl can run as its ``env_path``.

    It runs ``rlenv`` with ``command`` (``godot-rl TARGET`` and its options) in this Python,
    with this rlenv (their folders written in it), then the flags godot-rl gives a game
    (:func:`launcher_command`). ``sys.executable`` may hold no space (a ``#!`` line's
    limit). On Linux godot-rl runs ``env_path`` with its suffix replaced by
    ``.x86_64``: name the file so.
    """
    folders = list(
        dict.fromkeys(
            str(Path(module.__file__ or "").resolve().parent.parent)
            for module in (rlenv, rlenv_client, rlenv_tools)
        )
    )
    text = (
        f"#!{sys.executable}\n"
        '"""rlenv as a Godot game for Godot RL Agents (written by rlenv godot-rl --launcher)."""\n'
        "import os\nimport sys\n\n"
        f"FOLDERS = {folders!r}  # this rlenv, for this process and its server's\n"
        "sys.path[:0] = FOLDERS\n"
        "inherited = [os.environ['PYTHONPATH']] if os.environ.get('PYTHONPATH') else []\n"
        "os.environ['PYTHONPATH'] = os.pathsep.join([*FOLDERS, *inherited])\n"
        "from rlenv_tools._godot_game import launcher_command\n"
        "from rlenv_tools.cli import main\n\n"
        f"sys.exit(main(launcher_command(sys.argv[1:], {list(command)!r})))\n"
    )
    path.write_text(text)
    path.chmod(path.stat().st_mode | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH)
    if os.name == "posix" and path.suffix != ".x86_64":
        print(f"note: godot-rl runs {path.with_suffix('.x86_64')} for this env_path on Linux")
