"""``rlenv serve``: an environment over TCP.

Its arguments (the server's, its limits on clients, the policies, the inspector beside it) and
its run, which serves until Ctrl-C or SIGTERM (with ``--inspect``, the inspector's page in a
process of its own).
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
from pathlib import Path

from rlenv.serving._endpoint import DEFAULT_HOST, Limits
from rlenv.serving._recent import KEEP_EPISODES
from rlenv.transport.sockets import format_address
from rlenv_tools._cli_arguments import Commands, exit_on_signal, port

__all__ = ["add_serve"]


def add_serve(commands: Commands) -> None:
    """``rlenv serve``: an environment over TCP."""
    serve = commands.add_parser("serve", help="serve an environment over TCP")
    serve.add_argument("target", help="the environment class, as MODULE:CLASS")
    serve.add_argument(
        "--host", default=DEFAULT_HOST, help=f"address to bind (default {DEFAULT_HOST})"
    )
    serve.add_argument("--port", type=port, default=0, help="port to bind (default 0: any free)")
    serve.add_argument(
        "--instances",
        type=int,
        default=1,
        help="independent copies of the environment to host, stepped together "
        "by batch requests (default 1)",
    )
    serve.add_argument(
        "--per-client",
        action="store_true",
        help="give every client environments of its own (--instances of them) "
        "in this process, instead of one controller and observers",
    )
    serve.add_argument(
        "--real-time",
        action="store_true",
        help="ticks follow the wall clock; actions apply when they arrive",
    )
    serve.add_argument(
        "--record-dir",
        type=Path,
        default=None,
        metavar="DIR",
        help="let clients record videos into DIR (configure record='name.mp4')",
    )
    serve.add_argument(
        "--keep-episodes",
        type=int,
        default=None,
        metavar="N",
        help="keep each instance's last N finished episodes as recordings from "
        "the start, for the inspector's timeline (client.episodes()); 0: none, "
        f"ever (default: the last {KEEP_EPISODES}, once a client asks for them)",
    )
    serve.add_argument(
        "--lifeline",
        type=int,
        default=None,
        metavar="FD",
        help="exit when this inherited pipe closes (set by ServerProcess)",
    )
    serve.add_argument(
        "--token",
        default=os.environ.get("RLENV_TOKEN"),
        help="secret clients must present (default: $RLENV_TOKEN); required to "
        "bind anything but loopback",
    )
    _add_limits(serve)
    _add_policies(serve)
    _add_inspection(serve)
    serve.set_defaults(run=_serve)


def _add_limits(serve: argparse.ArgumentParser) -> None:
    """``rlenv serve``'s limits on its clients (:class:`~rlenv.serving._endpoint.Limits`)."""
    defaults = Limits()
    serve.add_argument(
        "--max-frame-size",
        type=int,
        default=defaults.max_frame_size,
        help=f"largest request in bytes (default {defaults.max_frame_size})",
    )
    serve.add_argument(
        "--frame-deadline",
        type=float,
        default=defaults.frame_deadline,
        help=f"seconds a started frame may take (default {defaults.frame_deadline})",
    )
    serve.add_argument(
        "--first-request-timeout",
        type=float,
        default=defaults.first_request_timeout,
        help="with a token, seconds a client has from connecting to send it (in its "
        f"first request; default {defaults.first_request_timeout})",
    )
    serve.add_argument(
        "--max-connections",
        type=int,
        default=defaults.max_connections,
        help=f"clients connected at once (default {defaults.max_connections})",
    )
    serve.add_argument(
        "--idle-timeout",
        type=float,
        default=defaults.idle_timeout,
        help=f"seconds a client may stay silent, 0: forever (default {defaults.idle_timeout})",
    )


def _add_policies(serve: argparse.ArgumentParser) -> None:
    """``rlenv serve``'s policies, which act for agents on the server, and their episodes."""
    serve.add_argument(
        "--policy",
        action="append",
        type=_policy,
        default=[],
        metavar="AGENT=FILE|heuristic",
        help="let the ONNX policy FILE (rlenv_tools.policies.export_onnx) act "
        "for AGENT, or its own heuristic with AGENT=heuristic "
        "(RLAgent.heuristic); repeat for several agents. With every agent "
        "driven, the server plays episodes itself (seeded 0, 1, 2 ...) and "
        "clients observe; otherwise a client controls the other agents (a file "
        "needs the onnx extra)",
    )
    serve.add_argument(
        "--max-episode-steps",
        type=int,
        default=None,
        metavar="N",
        help="cut policy-driven episodes short after N steps (truncated)",
    )


def _add_inspection(serve: argparse.ArgumentParser) -> None:
    """``rlenv serve``'s inspector beside it, and what a person plays there recorded."""
    serve.add_argument(
        "--inspect",
        action="store_true",
        help="also start the live inspector (rlenv inspect) on this server and "
        "print its page's address",
    )
    serve.add_argument(
        "--record-demonstrations",
        metavar="DIR",
        default=None,
        help="with --inspect: let a person take control from the page and record "
        "their episodes into DIR (as rlenv inspect --record-demonstrations)",
    )


def _policy(text: str) -> tuple[str, str]:
    """``AGENT=FILE`` from the command line, as (agent, file)."""
    agent, equals, path = text.partition("=")
    if not equals or not agent or not path:
        raise argparse.ArgumentTypeError(
            f"expected AGENT=FILE or AGENT=heuristic (e.g. Agent=model.onnx), got {text!r}"
        )
    return agent, path


def _serve(args: argparse.Namespace) -> int:
    from rlenv.serving.server import Server

    if args.max_episode_steps is not None and (args.max_episode_steps < 1 or not args.policy):
        raise ValueError(
            "--max-episode-steps needs a number >= 1 and --policy (it cuts "
            "policy-driven episodes short)"
        )
    if args.record_demonstrations is not None and not args.inspect:
        raise ValueError(
            "--record-demonstrations records what a person plays from the "
            "inspector's page: it goes with --inspect"
        )
    if args.per_client and args.inspect:
        raise ValueError(
            "--inspect watches the environment of a controller; with --per-client "
            "every client has its own: start the inspector on one of them instead"
        )
    signal.signal(signal.SIGTERM, exit_on_signal)
    limits = Limits(
        max_frame_size=args.max_frame_size,
        frame_deadline=args.frame_deadline,
        first_request_timeout=args.first_request_timeout,
        idle_timeout=args.idle_timeout or None,
        max_connections=args.max_connections,
    )
    server = Server(
        args.target,
        host=args.host,
        port=args.port,
        lifeline=args.lifeline,
        token=args.token,
        limits=limits,
        instances=args.instances,
        record_dir=args.record_dir,
        real_time=args.real_time,
        per_client=args.per_client,
        policies=dict(args.policy),
        max_episode_steps=args.max_episode_steps,
        keep_episodes=args.keep_episodes,
    )
    with server:
        inspector = None
        try:  # Ctrl-C once it listens (however soon) ends it with status 0
            host, port = server.address
            print(f"listening on {format_address(host, port)}", flush=True)
            inspector = (
                _start_inspector(host, port, args.token, args.target, args.record_demonstrations)
                if args.inspect
                else None
            )
            server.serve_forever()
        except KeyboardInterrupt:
            pass
        finally:
            if inspector is not None:
                from rlenv_client.launcher import end_process

                inspector.stdin.close()  # type: ignore[union-attr]  # it exits at EOF
                end_process(inspector, None, first=None)
    return 0


def _start_inspector(
    host: str, port: int, token: str | None, target: str, demonstrations: str | None
) -> subprocess.Popen[bytes]:
    """``rlenv inspect`` on this server, in a process of its own (it prints its address).

    This process only holds the pipe whose end stops it: the server gains no HTTP code and no
    thread. With ``demonstrations`` (a folder), a person may take control from the page.
    """
    env = dict(os.environ)
    if token is not None:
        env["RLENV_TOKEN"] = token
    reachable = {"0.0.0.0": "127.0.0.1", "": "127.0.0.1", "::": "::1"}.get(host, host)
    address = format_address(reachable, port)
    options = (
        []
        if demonstrations is None
        else ["--record-demonstrations", demonstrations, "--target", target]
    )
    return subprocess.Popen(
        [sys.executable, "-m", "rlenv_tools.inspector", address, "--follow-stdin", *options],
        stdin=subprocess.PIPE,
        env=env,
    )
