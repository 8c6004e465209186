"""``rlenv check``, ``rlenv bench`` and ``rlenv demo``: the commands that try rlenv out.

A server checked the way trainers use it, rlenv measured against same-run baselines, CartPole
served and balanced by a controller.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable
from dataclasses import asdict

from rlenv_tools._cli_arguments import Commands

__all__ = ["add_bench", "add_check", "add_demo"]


def add_check(commands: Commands) -> None:
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


def add_bench(commands: Commands) -> None:
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
    bench.add_argument(
        "--swarm",
        action="store_true",
        help="instead, a swarm (examples/swarm, 16, 64 and 256 members) served as one "
        "RLAgentGroup, served as N RLAgent nodes, and its bare pymunk floor "
        "(default --steps 200)",
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


def _bench(args: argparse.Namespace) -> int:
    def progress(message: str) -> None:
        print(f"... {message}", file=sys.stderr, flush=True)

    if args.swarm:
        return _bench_swarm(args, progress)
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


def _bench_swarm(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from rlenv_tools._swarm_bench import measure_swarm, summary_line, swarm_line

    results = measure_swarm(rounds=args.rounds, steps=args.steps or 200, progress=progress)
    for rates in results:
        print(swarm_line(rates), flush=True)
    print(summary_line(results[-1]))
    if args.json:
        with open(args.json, "w") as out:
            json.dump([asdict(rates) for rates in results], out, indent=2)
            out.write("\n")
    return 0


def add_demo(commands: Commands) -> None:
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
