"""A server's reader of pipelined frames: time per message as its backlog grows, two checkouts.

``python benchmarks/frame_backlog.py [OTHER_PYTHON] [--rounds R]`` feeds a server-side
:class:`~rlenv.protocol.connection.Connection` a backlog of small ``steps`` requests (as a
client that pipelines them sends), all in one ``receive_data``, and times ``next_message``
for each until the backlog is read: microseconds per message (the median over runs of 50), at
backlogs of 3 KB to 300 KB.
A reader that copies what is left after every frame pays for the backlog on each message; one
that keeps an offset does not. With ``OTHER_PYTHON`` (another checkout's interpreter) both run
in turns, R rounds each, and the script prints the medians and the ratios of this checkout to
the other at each backlog (min and median over the rounds).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

BACKLOGS = (3_000, 30_000, 300_000)
"""Bytes of pipelined requests fed at once."""

RUN = 50
"""Messages timed together."""


def per_message(backlog: int) -> float:
    """Microseconds per message to read ``backlog`` bytes of pipelined requests.

    The median over runs of 50 messages, through the whole backlog five times: a run that
    another process interrupted (this machine is shared) does not count.
    """
    from rlenv.protocol import Request
    from rlenv.protocol.codec import frame
    from rlenv.protocol.connection import Connection, Role, State

    one = frame(Request(1, {"steps": {"action": bytes(32)}}).to_wire())
    count = max(RUN, backlog // len(one)) // RUN * RUN
    data = one * count
    runs = []
    clock = time.perf_counter
    for _ in range(5):
        connection = Connection(Role.SERVER)
        connection._enter(State.READY)  # as once its hello went
        connection.receive_data(data)
        for _ in range(count // RUN):
            start = clock()
            for _ in range(RUN):
                connection.next_message()
                connection.note_reply(connection.outstanding[0])  # as if answered
            runs.append((clock() - start) / RUN)
    return statistics.median(runs) * 1e6


def measure(python: str) -> dict[str, float]:
    """One process of ``python`` measuring every backlog, run from a folder of no checkout's."""
    output = subprocess.run(
        [python, os.path.abspath(__file__), "--worker"],
        capture_output=True,
        text=True,
        check=True,
        cwd=tempfile.gettempdir(),
    ).stdout
    return json.loads(output.splitlines()[-1])


def main() -> None:
    """Parse the arguments and measure (or be one measuring process, with ``--worker``)."""
    if sys.argv[1:2] == ["--worker"]:
        print(json.dumps({str(size): per_message(size) for size in BACKLOGS}))
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("other_python", nargs="?", help="the python of another checkout's venv")
    parser.add_argument("--rounds", type=int, default=5)
    arguments = parser.parse_args()
    sides = {"this": sys.executable}
    if arguments.other_python:
        other = arguments.other_python
        sides["other"] = os.path.abspath(other) if os.sep in other else other
    results: dict[str, list[dict[str, float]]] = {side: [] for side in sides}
    for turn in range(arguments.rounds):
        for side in sides if turn % 2 == 0 else reversed(list(sides)):
            results[side].append(measure(sides[side]))
    print(f"us per message, median of {arguments.rounds} rounds (each the median of runs of {RUN})")
    print(f"{'backlog':>10}" + "".join(f"{side:>10}" for side in sides))
    for size in map(str, BACKLOGS):
        print(
            f"{int(size):>10,}"
            + "".join(
                f"{statistics.median(r[size] for r in results[side]):>10.2f}" for side in sides
            )
        )
    if "other" in results:
        for size in map(str, BACKLOGS):
            ratios = [
                a[size] / b[size] for a, b in zip(results["this"], results["other"], strict=True)
            ]
            print(
                f"this / other at {int(size):,} bytes: min {min(ratios):.3f} median "
                f"{statistics.median(ratios):.3f}"
            )


if __name__ == "__main__":
    main()
