"""``rlenv godot-rl``: an rlenv environment in a Godot game's part, for Godot RL Agents."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from rlenv_tools._cli_arguments import Commands, port

__all__ = ["add_godot_rl"]


def add_godot_rl(commands: Commands) -> None:
    """``rlenv godot-rl``: dial into a godot-rl trainer and play the game's part."""
    godot = commands.add_parser(
        "godot-rl",
        help="play a Godot game's part for a Godot RL Agents (godot-rl) trainer",
        description="Dial into a godot-rl trainer (its GodotEnv listens on 127.0.0.1:11008 by "
        "default) and answer it as a Godot game does: every agent of every instance is one "
        "AIController. With --launcher, write an executable that godot-rl runs as env_path "
        "instead (n_parallel). See docs/other-trainers.md.",
    )
    godot.add_argument(
        "target",
        help="a registered id (rlenv/CartPole-v1), MODULE:CLASS, or a running server (HOST:PORT)",
    )
    godot.add_argument(
        "--port", type=port, default=11008, help="the trainer's port on 127.0.0.1 (default 11008)"
    )
    godot.add_argument(
        "--instances",
        type=_positive,
        default=None,
        help="instances of TARGET's server, AIControllers to the trainer (default 1; not for "
        "HOST:PORT, which has its own)",
    )
    godot.add_argument(
        "--env-seed",
        "--env_seed",
        type=int,
        default=None,
        help="seed instance i's first reset with ENV_SEED * instances + i (default: unseeded)",
    )
    godot.add_argument(
        "--action-repeat",
        "--action_repeat",
        type=_positive,
        default=None,
        help="physics ticks per action (default: the environment's repeat_action)",
    )
    godot.add_argument(
        "--max-episode-steps",
        type=_positive,
        default=None,
        help="truncate episodes after this many steps (default: a registered id's limit)",
    )
    godot.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="configure the environment first (VALUE as JSON where it is JSON); repeatable",
    )
    godot.add_argument(
        "--timeout",
        type=float,
        default=60.0,
        help="seconds to reach the trainer and for each answer of the server (default 60)",
    )
    godot.add_argument(
        "--launcher",
        type=Path,
        default=None,
        metavar="FILE.x86_64",
        help="write an executable for godot-rl's env_path that plays TARGET with these "
        "options (godot-rl's --port=, --env_seed=, --action_repeat=, --KEY=VALUE win), then exit",
    )
    godot.set_defaults(run=_run)


def _positive(text: str) -> int:
    """A whole number of at least 1 (argparse says which argument, if not)."""
    try:
        number = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if number < 1:
        raise argparse.ArgumentTypeError(f"{number} is less than 1")
    return number


def _run(args: argparse.Namespace) -> int:
    from rlenv_tools._godot_game import Game, config_value, play, write_launcher

    config: dict[str, Any] = {}
    for setting in args.set:
        key, equals, value = setting.partition("=")
        if not equals or not key:
            raise ValueError(f"--set {setting!r}: give KEY=VALUE")
        config[key] = config_value(value)
    if args.launcher is not None:
        command = ["godot-rl", args.target, "--timeout", str(args.timeout)]
        for flag, value in (
            ("--instances", args.instances),
            ("--max-episode-steps", args.max_episode_steps),
        ):
            if value is not None:
                command += [flag, str(value)]
        for setting in args.set:
            command += ["--set", setting]
        write_launcher(args.launcher, command)
        print(f"wrote {args.launcher}: give godot-rl env_path={args.launcher}")
        return 0
    play(
        Game(
            args.target,
            port=args.port,
            instances=args.instances or 1,
            env_seed=args.env_seed,
            repeat_action=args.action_repeat,
            max_episode_steps=args.max_episode_steps,
            config=config,
            timeout=args.timeout,
        )
    )
    return 0
