"""The ``rlenv`` command: serve, http, inspect, check, bench, replay, dataset, demo."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import stat
import subprocess
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from types import FrameType
from typing import cast

from rlenv.protocol.errors import RlenvError
from rlenv.serving._endpoint import DEFAULT_HOST, Limits
from rlenv.serving._recent import KEEP_EPISODES
from rlenv.transport.sockets import format_address

__all__ = ["main", "serve_command"]

logger = logging.getLogger(__name__)

_Commands = argparse._SubParsersAction  # what add_subparsers returns: each builder adds to it


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
        _add_serve,
        _add_http,
        _add_inspect,
        _add_check,
        _add_bench,
        _add_replay,
        _add_dataset,
        _add_demo,
    ):
        add(commands)
    return parser


def _add_serve(commands: _Commands) -> None:
    """``rlenv serve``: an environment over TCP."""
    serve = commands.add_parser("serve", help="serve an environment over TCP")
    serve.add_argument("target", help="the environment class, as MODULE:CLASS")
    serve.add_argument(
        "--host", default=DEFAULT_HOST, help=f"address to bind (default {DEFAULT_HOST})"
    )
    serve.add_argument("--port", type=_port, default=0, help="port to bind (default 0: any free)")
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
    serve.set_defaults(run=_serve)


def _add_http(commands: _Commands) -> None:
    """``rlenv http``: the HTTP/JSON gateway."""
    http = commands.add_parser(
        "http",
        help="serve environments over HTTP/JSON (needs the http extra)",
        description="An HTTP/JSON gateway: sessions under /v1/envs, bevy_rl's routes on TARGET, "
        "a WebSocket and server-sent events per session, GET /openapi.json. See docs/http.md.",
    )
    http.add_argument(
        "target",
        nargs="?",
        default=None,
        help="the environment class (MODULE:CLASS) or a running server "
        "(HOST:PORT); sessions may also use the registered ids",
    )
    http.add_argument(
        "--host", default=DEFAULT_HOST, help=f"address to bind (default {DEFAULT_HOST})"
    )
    http.add_argument(
        "--port", type=_port, default=8000, help="port to bind (default 8000; 0: any free)"
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


def _add_inspect(commands: _Commands) -> None:
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
        "--port", type=_port, default=0, help="the page's port on 127.0.0.1 (default 0: a free one)"
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


def _add_check(commands: _Commands) -> None:
    """``rlenv check``: a server checked the way trainers use it."""
    check = commands.add_parser("check", help="check a server the way trainers use it")
    check.add_argument("target", help="HOST:PORT of a running server, or MODULE:CLASS to start")
    check.add_argument("--timeout", type=float, default=30.0, help="seconds per answer")
    check.add_argument(
        "--compliance",
        action="store_true",
        help="also send hostile input (bad frames, a slow drip ...) and check "
        "that every probe gets its error while a client keeps stepping",
    )
    check.add_argument(
        "--token",
        default=os.environ.get("RLENV_TOKEN"),
        help="the server's token (default: $RLENV_TOKEN)",
    )
    check.set_defaults(run=_check)


def _add_bench(commands: _Commands) -> None:
    """``rlenv bench``: rlenv measured against same-run baselines."""
    bench = commands.add_parser("bench", help="measure rlenv against same-run baselines")
    bench.add_argument("--rounds", type=int, default=5, help="rounds per figure (median)")
    bench.add_argument(
        "--steps",
        type=int,
        default=None,
        help="steps per round (default 2000; --train: 8000 env-steps per SyncVectorEnv round)",
    )
    bench.add_argument("--quick", action="store_true", help="fewer vector sizes")
    bench.add_argument("--json", metavar="PATH", help="also write the figures as JSON")
    bench.add_argument(
        "--train",
        nargs="?",
        const="rlenv/CartPole-v1",
        metavar="TARGET",
        help="instead, what serving costs a trainer: PPO (if stable-baselines3 "
        "is installed) and SyncVectorEnv on TARGET (MODULE:CLASS or a registered "
        "id; default rlenv/CartPole-v1), each against TARGET in process",
    )
    bench.add_argument("--envs", type=int, default=8, help="--train: environments per trainer")
    bench.add_argument(
        "--busy",
        action="store_true",
        help="--train: with a CPU-bound process of something else running",
    )
    bench.add_argument(
        "--torch-threads",
        type=int,
        default=None,
        metavar="N",
        help="--train: torch.set_num_threads(N) (default: torch's own)",
    )
    bench.add_argument(
        "--native",
        metavar="ID",
        help="--train: PPO also trains on this gymnasium id (CartPole-v1), for reference",
    )
    bench.set_defaults(run=_bench)


def _add_replay(commands: _Commands) -> None:
    """``rlenv replay``: a recorded episode re-run and compared, or opened as timelines."""
    replay = commands.add_parser("replay", help="re-run a recorded episode and compare")
    replay.add_argument(
        "file",
        nargs="+",
        help="an episode file (rlenv_client.replay.RecordEpisodes); several with --inspect",
    )
    replay.add_argument(
        "--target",
        help="MODULE:CLASS to serve (default: the recorded one, "
        "where it is an installed package: a module beside the recording or in "
        "the current folder runs only with --target or --trust-target)",
    )
    replay.add_argument(
        "--trust-target",
        action="store_true",
        help="run the recorded target even where it is no installed package "
        "(importing runs its code: only for recordings you trust)",
    )
    replay.add_argument("--address", help="HOST:PORT of a running server instead")
    replay.add_argument(
        "--inspect",
        action="store_true",
        help="open the episodes as timelines in the inspector's page (scrub, "
        "step, tick, branch, compare; docs/time-travel.md): prints its "
        "address and serves it until Ctrl-C (or until standard input closes, "
        "when it is a pipe)",
    )
    replay.add_argument(
        "--port",
        type=_port,
        default=0,
        help="with --inspect: the page's port on 127.0.0.1 (default 0: any free)",
    )
    replay.add_argument(
        "--policy",
        action="append",
        default=[],
        metavar="FILE.onnx",
        help="with --inspect: a policy file to branch with (repeatable; the onnx extra)",
    )
    replay.add_argument("--follow-stdin", action="store_true", help=argparse.SUPPRESS)
    replay.set_defaults(run=_replay)


def _add_dataset(commands: _Commands) -> None:
    """``rlenv dataset create``: a Minari dataset from recordings."""
    dataset = commands.add_parser("dataset", help="Minari datasets (the minari extra)")
    dataset_commands = dataset.add_subparsers(dest="dataset_command", required=True)
    create = dataset_commands.add_parser(
        "create", help="re-simulate recorded episodes, check them and write a Minari dataset"
    )
    create.add_argument(
        "dataset_id", metavar="DATASET_ID", help="Minari's id: ENV/NAME-vN or NAMESPACE/ENV/NAME-vN"
    )
    create.add_argument(
        "--from",
        dest="source",
        type=Path,
        required=True,
        metavar="DIR",
        help="a folder of recordings (rlenv_client.replay.RecordEpisodes)",
    )
    create.add_argument(
        "--target",
        help="MODULE:CLASS to serve (default: the recorded one, "
        "where it is an installed package: see rlenv replay --help)",
    )
    create.add_argument(
        "--trust-target",
        action="store_true",
        help="run the recorded target even where it is no installed package "
        "(importing runs its code: only for recordings you trust)",
    )
    create.add_argument("--description", help="what the dataset holds (Minari's metadata)")
    create.add_argument("--algorithm-name", help="what chose the actions")
    create.add_argument("--author", help="who made the dataset")
    create.add_argument("--author-email", help="how to reach them")
    create.add_argument("--code-permalink", help="a link to the code that made it")
    create.set_defaults(run=_dataset_create)


def _add_demo(commands: _Commands) -> None:
    """``rlenv demo``: CartPole balanced by a controller."""
    demo = commands.add_parser("demo", help="serve CartPole and balance it with a controller")
    demo.add_argument("--episodes", type=int, default=5, help="episodes to run (default 5)")
    demo.add_argument(
        "--repeat-action", type=int, default=1, help="physics ticks per action (default 1)"
    )
    demo.add_argument("--seed", type=int, default=0, help="seed of the first episode")
    demo.add_argument(
        "--max-seconds",
        type=float,
        default=30.0,
        help="simulated seconds after which an episode is cut short (default 30)",
    )
    demo.set_defaults(run=_demo)


def _in_words(error: Exception) -> str:
    """What went wrong, for a person: the message first (a target's comes with its hint)."""
    if isinstance(error, OSError | ValueError | ImportError | RuntimeError | RlenvError) and str(
        error
    ):
        return str(error)
    return f"{type(error).__name__}: {error}" if str(error) else type(error).__name__


def _port(text: str) -> int:
    """A port number from the command line (argparse says which argument, if not)."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{port} is not a port: ports run from 0 to 65535")
    return port


def _policy(text: str) -> tuple[str, str]:
    """``AGENT=FILE`` from the command line, as (agent, file)."""
    agent, equals, path = text.partition("=")
    if not equals or not agent or not path:
        raise argparse.ArgumentTypeError(
            f"expected AGENT=FILE or AGENT=heuristic (e.g. Agent=model.onnx), got {text!r}"
        )
    return agent, path


def serve_command(target: str) -> int:
    """``rlenv serve TARGET`` with this process's other arguments (for ``python -m`` examples)."""
    return main(["serve", target, *sys.argv[1:]])


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
    signal.signal(signal.SIGTERM, _exit_on_signal)
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


def _demo(args: argparse.Namespace) -> int:
    from rlenv.targets import EXAMPLES, import_module
    from rlenv_client import Client
    from rlenv_client.launcher import ServerProcess

    cartpole = import_module(f"{EXAMPLES}.cartpole")  # examples.cartpole in a checkout
    with ServerProcess(cartpole.TARGET) as server, Client(server.host, server.port) as client:
        print(f"CartPole served at {server.address}; balancing with a proportional controller")
        limit = round(args.max_seconds * client.hello.physics_ticks_per_second)
        for episode in range(args.episodes):
            observation, _ = client.reset(seed=args.seed + episode)
            episode_return, frames, terminated = 0.0, 0, False
            while not terminated and frames < limit:
                repeat = min(args.repeat_action, limit - frames)
                observation, reward, terminated, _, info = client.step(
                    cartpole.controller(observation), repeat_action=repeat
                )
                episode_return += reward
                frames += info["frames"]
            ending = "the pole fell" if terminated else "time limit"
            seconds = frames / client.hello.physics_ticks_per_second
            print(
                f"episode {episode + 1}: return {episode_return:.0f} over {frames} physics "
                f"ticks ({seconds:.1f} s simulated, {ending})",
                flush=True,
            )
    return 0


_STATUS_COLOURS = {"pass": "32", "fail": "31", "skip": "33"}
"""ANSI colours of ``rlenv check``'s statuses: green, red, yellow."""


def _colour_wanted() -> bool:
    """Colour only for a terminal, and never when ``NO_COLOR`` is set (no-color.org)."""
    return (
        sys.stdout.isatty() and not os.environ.get("NO_COLOR") and os.environ.get("TERM") != "dumb"
    )


def _check(args: argparse.Namespace) -> int:
    from rlenv_tools._checks import run_checks

    results = run_checks(
        args.target, timeout=args.timeout, compliance=args.compliance, token=args.token
    )
    width = max(len(result.name) for result in results)
    colours = _STATUS_COLOURS if _colour_wanted() else {}
    for result in results:
        status = f"{result.status.upper():<5}"
        if result.status in colours:
            status = f"\x1b[{colours[result.status]}m{status}\x1b[0m"
        print(f"{status} {result.name:<{width}}  {result.detail}")
    failed = sum(result.status == "fail" for result in results)
    passed = sum(result.status == "pass" for result in results)
    print(f"{passed} passed, {failed} failed")
    return 1 if failed else 0


def _bench(args: argparse.Namespace) -> int:
    def progress(message: str) -> None:
        print(f"... {message}", file=sys.stderr, flush=True)

    if args.train is not None:
        from rlenv_tools.training_speed import format_rows, measure_training, rows_to_json

        rows = measure_training(
            args.train,
            envs=args.envs,
            rounds=args.rounds,
            busy=args.busy,
            torch_threads=args.torch_threads,
            steps=args.steps or 8000,
            native=args.native,
            progress=progress,
        )
        table, as_json = format_rows(rows), rows_to_json(rows)
    else:
        from rlenv_tools._bench import format_table, run_benchmarks, to_json

        figures = run_benchmarks(
            rounds=args.rounds, steps=args.steps or 2000, quick=args.quick, progress=progress
        )
        table, as_json = format_table(figures), to_json(figures)
    print(table)
    if args.json:
        with open(args.json, "w") as out:
            out.write(as_json + "\n")
    return 0


def _replay(args: argparse.Namespace) -> int:
    from rlenv_client.replay import EpisodeFile, replay
    from rlenv_client.session import Session
    from rlenv_client.trusted_targets import check_target

    if args.inspect:
        return _replay_inspect(args)
    if args.policy or args.port or args.follow_stdin:
        print(
            "rlenv replay: --policy, --port and --follow-stdin go with --inspect", file=sys.stderr
        )
        return 2
    if len(args.file) > 1:
        print("rlenv replay: one file at a time (several with --inspect)", file=sys.stderr)
        return 2
    args.file = args.file[0]
    try:
        episode = EpisodeFile.load(args.file)
    except (OSError, ValueError) as error:
        print(f"rlenv replay: {error}", file=sys.stderr)
        return 2
    target = args.target or episode.target
    if args.address is None and target is None:
        print(
            "rlenv replay: the episode names no target; pass --target or --address", file=sys.stderr
        )
        return 2
    if args.address is None and args.target is None and not args.trust_target:
        # Without an address there is a target (refused above otherwise).
        check_target(
            cast(str, target), named_by=f"the recording {args.file}", folder=Path(args.file).parent
        )
    session = Session(target, address=args.address)
    try:
        result = replay(episode, session.client)
    finally:
        session.close()
    if result.divergence is None:
        also = ", every reward and flag too" if result.outcomes_checked else ""
        print(f"replayed {result.steps} steps of {args.file}: every observation identical{also}")
        return 0
    print(f"replayed {args.file}: first divergence at {result.divergence}")
    return 1


def _replay_inspect(args: argparse.Namespace) -> int:
    """``rlenv replay FILE ... --inspect``: the inspector's page with the files as timelines."""
    from rlenv_tools.inspector import serve
    from rlenv_tools.timeline import load_policy

    if args.address is not None:
        print(
            "rlenv replay: --inspect re-simulates in processes of its own; it takes no --address",
            file=sys.stderr,
        )
        return 2
    from rlenv_client.replay import EpisodeFile
    from rlenv_client.trusted_targets import check_target

    for path in args.file if args.target is None else ():
        recorded = EpisodeFile.load(path).target
        if recorded is None:
            print(
                f"rlenv replay: {path} names no target; pass --target MODULE:CLASS", file=sys.stderr
            )
            return 2
        if not args.trust_target:  # said now, not only on the page
            check_target(recorded, named_by=f"the recording {path}", folder=Path(path).parent)
    policies, unavailable = {}, {}
    for path in args.policy:
        name = Path(path).stem
        if not Path(path).is_file():  # said whether or not onnxruntime is there
            raise ValueError(f"cannot read the policy {path}: no such file")
        try:
            policies[name] = load_policy(path)
        except ImportError as error:  # the page says why its policy button is off
            unavailable[name] = str(error)
            print(f"rlenv replay: policy {name} unavailable: {error}", file=sys.stderr)
    signal.signal(signal.SIGTERM, _exit_on_signal)
    stdin_is_pipe = False
    try:
        stdin_is_pipe = stat.S_ISFIFO(os.fstat(sys.stdin.fileno()).st_mode)
    except (OSError, ValueError, AttributeError):
        pass
    serve(
        [],
        token=None,
        port=args.port,
        follow_stdin=args.follow_stdin or stdin_is_pipe,
        ready=lambda line: print(line, flush=True),
        target=args.target,
        recordings=args.file,
        policies=policies,
        unavailable=unavailable,
        trust_target=args.trust_target,
    )
    return 0


def _dataset_create(args: argparse.Namespace) -> int:
    try:
        from rlenv_tools.datasets import create_dataset
    except ImportError as error:
        print(f"rlenv dataset: {error}", file=sys.stderr)
        return 2
    with warnings.catch_warnings():  # Minari's advice on every field left out, one line each
        warnings.filterwarnings("ignore", message=r"`\w+` is set to None", category=UserWarning)
        dataset = create_dataset(
            args.dataset_id,
            args.source,
            target=args.target,
            trust_target=args.trust_target,
            description=args.description,
            algorithm_name=args.algorithm_name,
            author=args.author,
            author_email=args.author_email,
            code_permalink=args.code_permalink,
            report=lambda line: print(f"note: {line}"),
        )
    print(
        f"wrote dataset {args.dataset_id}: {dataset.total_episodes} episodes, "
        f"{dataset.total_steps} steps, each observation identical to its recording"
    )
    return 0


def _exit_on_signal(signum: int, frame: FrameType | None) -> None:
    raise SystemExit(128 + signum)
