"""What the ``rlenv`` subcommands share.

The builders' argument (the parser's subcommands), the command line's port type, and SIGTERM
as an exit.
"""

from __future__ import annotations

import argparse
from types import FrameType

__all__ = ["Commands", "exit_on_signal", "port"]

Commands = argparse._SubParsersAction  # what add_subparsers returns: each builder adds to it


def port(text: str) -> int:
    """A port number from the command line (argparse says which argument, if not)."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{port} is not a port: ports run from 0 to 65535")
    return port


def exit_on_signal(signum: int, frame: FrameType | None) -> None:
    """A signal handler: exit with status 128 + ``signum``, as a shell reports it.

    By ``SystemExit``, so that what the command holds is closed on the way out.
    """
    raise SystemExit(128 + signum)
