"""``rlenv http`` and ``rlenv inspect``: the commands that serve over HTTP.

The gateway (environments' sessions as HTTP/JSON) and the live inspector's page.
"""

from __future__ import annotations

import argparse
import os
import sys

from rlenv.serving._endpoint import DEFAULT_HOST
from rlenv_tools._cli_arguments import Commands, port

__all__ = ["add_http", "add_inspect"]


def add_http(commands: Commands) -> None:
    """``rlenv http``: the HTTP/JSON gateway."""
    http = commands.add_parser(
        "http",
        help="serve environments over HTTP/JSON (needs the http extra)",
        description="An HTTP/JSON gateway: sessions under /v1/envs, bevy_rl's routes and "
        "OpenEnv's (under /openenv) on TARGET, a WebSocket and server-sent events per "
        "session, GET /openapi.json. See docs/http.md.",
    )
    http.add_argument(
        "target",
        nargs="?",
        default=None,
        help="the environment class (MODULE:CLASS), a running server (HOST:PORT) "
        "or a registered id (rlenv/CartPole-v1, with its time limit); sessions may "
        "also use the registered ids",
    )
    http.add_argument(
        "--host", default=DEFAULT_HOST, help=f"address to bind (default {DEFAULT_HOST})"
    )
    http.add_argument(
        "--port", type=port, default=8000, help="port to bind (default 8000; 0: any free)"
    )
    http.add_argument(
        "--token",
        default=os.environ.get("RLENV_TOKEN"),
        help="bearer token every request must carry (default: $RLENV_TOKEN); "
        "required to bind anything but loopback",
    )
    http.add_argument(
        "--isolate",
        action="store_true",
        help="accepted for older command lines: every session's environment runs "
        "in a server subprocess of its own (a crash or a hang takes only its "
        "session: 502, 504)",
    )
    http.add_argument(
        "--timeout",
        type=float,
        default=30.0,
        help="seconds an environment may take to answer (default 30; then 504)",
    )
    http.add_argument(
        "--max-sessions", type=int, default=32, help="sessions at once (default 32; then 503)"
    )
    http.add_argument(
        "--max-sessions-per-client",
        type=int,
        default=16,
        metavar="N",
        help="sessions at once created by one client address (default 16; then 503)",
    )
    http.add_argument(
        "--max-body",
        type=int,
        default=1 << 20,
        help="largest request body in bytes (default 1 MiB; then 413)",
    )
    http.add_argument(
        "--idle-timeout",
        type=float,
        default=600.0,
        help="seconds after which a session without requests is closed (default 600; 0: never)",
    )
    http.add_argument(
        "--head-timeout",
        type=float,
        default=5.0,
        help="seconds a connection has to complete a request head (default 5; then it is closed)",
    )
    http.add_argument(
        "--max-connections",
        type=int,
        default=100,
        help="connections open at once (default 100; beyond, the oldest still "
        "waiting for its request head is closed)",
    )
    http.set_defaults(run=_http)


def _http(args: argparse.Namespace) -> int:
    try:
        from rlenv_tools.http.app import Settings, serve
    except ImportError as error:
        print(
            f"rlenv http: {error.name or error} is missing; install the http extra: "
            "pip install 'rlenv[http]'",
            file=sys.stderr,
        )
        return 2
    settings = Settings(
        target=args.target,
        host=args.host,
        port=args.port,
        token=args.token,
        timeout=args.timeout,
        max_sessions=args.max_sessions,
        max_sessions_per_client=args.max_sessions_per_client,
        max_body=args.max_body,
        idle_timeout=args.idle_timeout or None,
        head_timeout=args.head_timeout,
        max_connections=args.max_connections,
    )
    serve(settings, ready=lambda url: print(f"listening on {url}", flush=True))
    return 0


def add_inspect(commands: Commands) -> None:
    """``rlenv inspect``: the live inspector's page."""
    inspect = commands.add_parser(
        "inspect", help="watch running servers in the browser (a page on 127.0.0.1)"
    )
    inspect.add_argument(
        "addresses", nargs="+", metavar="HOST:PORT", help="the environment servers to watch"
    )
    inspect.add_argument(
        "--token",
        default=None,
        help="the servers' token (default: $RLENV_TOKEN, which keeps it out of the process list)",
    )
    inspect.add_argument(
        "--port", type=port, default=0, help="the page's port on 127.0.0.1 (default 0: a free one)"
    )
    inspect.add_argument(
        "--follow-stdin",
        action="store_true",
        help="read new address lists (JSON) from standard input; exit when it "
        "closes (set by rlenv_tools.inspector.Inspector)",
    )
    inspect.add_argument(
        "--record-demonstrations",
        metavar="DIR",
        default=None,
        help="let a person take control from the page (keys to actions: the "
        "agent's demonstration_keys) and record each episode into DIR, as "
        "rlenv replay re-runs them",
    )
    inspect.add_argument(
        "--target",
        metavar="MODULE:CLASS",
        default=None,
        help="the environment's class, written into demonstrations so that "
        "rlenv replay needs no --target; the recent episodes' timelines run it "
        "(default: the servers' own target, where it is an installed package)",
    )
    inspect.add_argument(
        "--trust-target",
        action="store_true",
        help="run the servers' target in the page's timelines even where it is "
        "no installed package (importing runs its code: only for servers you "
        "trust)",
    )
    inspect.add_argument(
        "--demonstration-rate",
        type=float,
        default=None,
        metavar="HZ",
        help="actions a second while a person plays (default: the "
        "environment's real time, its ticks a second over repeat_action)",
    )
    inspect.set_defaults(run=_inspect)


def _inspect(args: argparse.Namespace) -> int:
    from rlenv_tools.inspector import serve

    serve(
        args.addresses,
        token=args.token,
        port=args.port,
        follow_stdin=args.follow_stdin,
        ready=lambda line: print(line, flush=True),
        record_demonstrations=args.record_demonstrations,
        target=args.target,
        demonstration_rate=args.demonstration_rate,
        trust_target=args.trust_target,
    )
    return 0
