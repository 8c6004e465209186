"""``rlenv replay`` and ``rlenv dataset create``: the commands on recorded episodes.

Re-run one and compare it, open several as timelines in the inspector's page, or make a Minari
dataset of a folder of them.
"""

from __future__ import annotations

import argparse
import os
import signal
import stat
import sys
import warnings
from pathlib import Path
from typing import cast

from rlenv_tools._cli_arguments import Commands, exit_on_signal, port

__all__ = ["add_dataset", "add_replay"]


def add_replay(commands: Commands) -> None:
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
        type=port,
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
    signal.signal(signal.SIGTERM, exit_on_signal)
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


def add_dataset(commands: Commands) -> None:
    """``rlenv dataset create``: a Minari dataset from recordings."""
    dataset = commands.add_parser("dataset", help="Minari datasets (the minari extra)")
    dataset_commands = dataset.add_subparsers(dest="dataset_command", required=True)
    create = dataset_commands.add_parser(
        "create",
        help="re-simulate recorded episodes, check them and write a Minari dataset (one per "
        "agent class where agents come and go)",
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


def _dataset_create(args: argparse.Namespace) -> int:
    try:
        from rlenv_tools.datasets import create_datasets
    except ImportError as error:
        print(f"rlenv dataset: {error}", file=sys.stderr)
        return 2
    with warnings.catch_warnings():  # Minari's advice on every field left out, one line each
        warnings.filterwarnings("ignore", message=r"`\w+` is set to None", category=UserWarning)
        datasets = create_datasets(
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
    for dataset in datasets:  # one, or one per agent class where agents come and go
        print(
            f"wrote dataset {dataset.id}: {dataset.total_episodes} episodes, "
            f"{dataset.total_steps} steps, each observation identical to its recording"
        )
    return 0
