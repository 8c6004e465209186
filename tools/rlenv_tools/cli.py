"""The ``rlenv`` command: serve, http, inspect, check, bench, replay, dataset, demo."""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Sequence

from rlenv.protocol.errors import RlenvError
from rlenv_tools._cli_recordings import add_dataset, add_replay
from rlenv_tools._cli_serve import add_serve
from rlenv_tools._cli_trials import add_bench, add_check, add_demo
from rlenv_tools._cli_web import add_http, add_inspect

__all__ = ["main", "serve_command"]

logger = logging.getLogger(__name__)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``rlenv`` command line; returns the exit code."""
    args = _parser().parse_args(argv)
    logging.basicConfig(
        level=args.log_level,
        stream=sys.stderr,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    if os.getcwd() not in sys.path and "" not in sys.path:
        sys.path.insert(0, os.getcwd())  # MODULE:CLASS from here, as ``python -m`` finds it
    try:
        return args.run(args)
    except KeyboardInterrupt:
        return 130
    except Exception as error:  # one clear line; the traceback with --log-level DEBUG
        logger.debug("rlenv %s failed", args.command, exc_info=error)
        print(f"rlenv {args.command}: {_in_words(error)}", file=sys.stderr)
        return 2


def _parser() -> argparse.ArgumentParser:
    """The ``rlenv`` command's parser: the subcommands, each from its own builder."""
    parser = argparse.ArgumentParser(prog="rlenv", description=__doc__)
    parser.add_argument(
        "--log-level",
        default="WARNING",
        choices=["DEBUG", "INFO", "WARNING", "ERROR"],
        help="default: WARNING",
    )
    commands = parser.add_subparsers(dest="command", required=True)
    for add in (
        add_serve,
        add_http,
        add_inspect,
        add_check,
        add_bench,
        add_replay,
        add_dataset,
        add_demo,
    ):
        add(commands)
    return parser


def _in_words(error: Exception) -> str:
    """What went wrong, for a person: the message first (a target's comes with its hint)."""
    if isinstance(error, OSError | ValueError | ImportError | RuntimeError | RlenvError) and str(
        error
    ):
        return str(error)
    return f"{type(error).__name__}: {error}" if str(error) else type(error).__name__


def serve_command(target: str) -> int:
    """``rlenv serve TARGET`` with this process's other arguments (for ``python -m`` examples)."""
    return main(["serve", target, *sys.argv[1:]])
