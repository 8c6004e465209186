"""What watching costs the trainer: steps/s with the inspector's page open, and without.

``python benchmarks/inspector_cost.py [--rounds R] [--seconds S]`` (needs Chromium: ``make
test-browser`` installs what it can). A trainer in this process steps a served CartPole on random
actions, resetting when an episode ends, as fast as it can. In turns (the order alternates
each round), it runs ``S`` seconds with nothing else attached, then ``S`` seconds with ``rlenv
inspect`` attached and its page open in headless Chromium (drawing the scene at up to 30
frames/s, polling the tree, the selected node and the statistics). It prints the steps/s of
each round, their min and median, and the median ratio: the issue's target is a drop under 5%.
It also prints the server's CPU time per trainer step in each (from ``/proc``): what serving the
page's requests between the trainer's adds, whatever the machine's idle cores do to the rate (a
busy browser keeps this VM's cores awake, which alone can make the trainer faster).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from browser import Browser, find_chromium  # noqa: E402  (the tests' DevTools driver)
from procfs import cpu_seconds  # noqa: E402

from rlenv_client import Client, ServerProcess  # noqa: E402
from rlenv_tools.inspector import Inspector  # noqa: E402

CARTPOLE = "examples.cartpole:CartPoleEnvironment"


def train(client: Client, seconds: float, random: np.random.Generator) -> float:
    """Steps per second of a random-action training loop, for ``seconds``."""
    steps, started = 0, time.perf_counter()
    deadline = started + seconds
    client.reset()
    while time.perf_counter() < deadline:
        for _ in range(100):
            _, _, terminated, truncated, _ = client.step(
                random.uniform(-1, 1, 1).astype(np.float32)
            )
            steps += 1
            if terminated or truncated:
                client.reset()
    return steps / (time.perf_counter() - started)


def watched(
    server: ServerProcess,
    chromium: str,
    client: Client,
    seconds: float,
    random: np.random.Generator,
) -> tuple[float, int]:
    """Steps per second with the page open; and how many frames the page drew meanwhile."""
    with Inspector([f"{server.host}:{server.port}"]) as inspector, Browser(chromium) as browser:
        browser.open(inspector.url)
        deadline = time.monotonic() + 30
        while not browser.evaluate("window.inspector && window.inspector.frames > 10"):
            assert time.monotonic() < deadline, "the page drew nothing"
            time.sleep(0.05)
        browser.evaluate("document.querySelector('#tree li:nth-child(4)').click()")  # World
        before = browser.evaluate("window.inspector.frames")
        rate = train(client, seconds, random)
        return rate, browser.evaluate("window.inspector.frames") - before


def main() -> None:
    """Measure and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=5, help="rounds of each, in turns")
    parser.add_argument("--seconds", type=float, default=5.0, help="seconds per round")
    args = parser.parse_args()
    chromium = find_chromium()
    if chromium is None:
        raise SystemExit("no Chromium found: apt-get install chromium")
    random = np.random.default_rng(0)
    rates: dict[str, list[float]] = {"without": [], "with": []}
    cpu: dict[str, list[float]] = {"without": [], "with": []}  # server µs per step
    with ServerProcess(CARTPOLE) as server, Client(server.host, server.port) as client:
        train(client, 2.0, random)  # wake the machine up
        print(
            f"{'round':>5}{'without':>10}{'with':>10}{'ratio':>8}{'frames/s':>10}"
            f"{'server µs/step without':>24}{'with':>8}"
        )
        for round_ in range(args.rounds):
            frames = 0
            for kind in ("without", "with") if round_ % 2 == 0 else ("with", "without"):
                used = cpu_seconds(server.pid)
                if kind == "with":
                    rate, frames = watched(server, chromium, client, args.seconds, random)
                else:
                    rate = train(client, args.seconds, random)
                rates[kind].append(rate)
                cpu[kind].append((cpu_seconds(server.pid) - used) / (rate * args.seconds) * 1e6)
            print(
                f"{round_:>5}{rates['without'][-1]:>10.0f}{rates['with'][-1]:>10.0f}"
                f"{rates['with'][-1] / rates['without'][-1]:>8.3f}"
                f"{frames / args.seconds:>10.1f}{cpu['without'][-1]:>24.1f}"
                f"{cpu['with'][-1]:>8.1f}"
            )
    ratios = [w / o for w, o in zip(rates["with"], rates["without"], strict=True)]
    for kind, values in rates.items():
        print(
            f"{kind:>8}: min {min(values):.0f}, median {statistics.median(values):.0f} steps/s; "
            f"server CPU median {statistics.median(cpu[kind]):.1f} µs/step"
        )
    print(
        f"with / without, per round: min {min(ratios):.3f}, median "
        f"{statistics.median(ratios):.3f} (a drop of "
        f"{100 * (1 - statistics.median(ratios)):.1f}% at the median)"
    )


if __name__ == "__main__":
    main()
