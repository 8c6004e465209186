"""``rlenv dm-env-rpc``: an environment served over dm_env_rpc (the dm-env-rpc extra)."""

from __future__ import annotations

import argparse
import signal
import sys

from rlenv_tools._cli_arguments import Commands, exit_on_signal, port

__all__ = ["add_dm_env_rpc"]


def add_dm_env_rpc(commands: Commands) -> None:
    """``rlenv dm-env-rpc``: DeepMind's dm_env_rpc protocol (gRPC) on 127.0.0.1."""
    command = commands.add_parser(
        "dm-env-rpc",
        help="serve an environment over dm_env_rpc (gRPC; needs the dm-env-rpc extra)",
        description="A dm_env_rpc server on 127.0.0.1 (gRPC's local credentials): each "
        "CreateWorld is an environment of TARGET, driven through rlenv's client. See "
        "docs/other-trainers.md.",
    )
    command.add_argument(
        "target",
        help="the environment class (MODULE:CLASS), a registered id (rlenv/CartPole-v1, "
        "with its time limit) or a running server (HOST:PORT)",
    )
    command.add_argument(
        "--port", type=port, default=0, help="port to bind on 127.0.0.1 (default 0: any free)"
    )
    command.add_argument(
        "--timeout",
        type=float,
        default=30.0,
        help="seconds an environment may take to answer (default 30)",
    )
    command.add_argument(
        "--max-worlds", type=int, default=8, help="worlds at once (default 8; then refused)"
    )
    command.add_argument(
        "--max-connections",
        type=int,
        default=16,
        help="connections (streams) at once (default 16; then refused)",
    )
    command.set_defaults(run=_dm_env_rpc)


def _dm_env_rpc(args: argparse.Namespace) -> int:
    try:
        from rlenv_tools._dm_env_rpc_server import serve
    except ImportError as error:
        print(
            f"rlenv dm-env-rpc: {error.name or error} is missing; install the dm-env-rpc "
            "extra: pip install 'rlenv[dm-env-rpc]'",
            file=sys.stderr,
        )
        return 2
    signal.signal(signal.SIGTERM, exit_on_signal)
    serve(
        args.target,
        port=args.port,
        timeout=args.timeout,
        max_worlds=args.max_worlds,
        max_connections=args.max_connections,
        ready=lambda address: print(f"listening on {address}", flush=True),
    )
    return 0
