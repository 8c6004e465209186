"""The recipes' one measure: steps/s of rlenv against the same library on native CartPole-v1.

Both sides are measured once a round, the order swapped every round (the machine's speed
drifts; a baseline measured minutes apart makes ratios noise), and the ratio is taken per round:
its minimum and median are the figure. ``--smoke`` gives the tiny budget ``make test-trainers``
runs the recipes with.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, TypeVar

Stepper = Callable[[], int]
"""Makes some steps and says how many (env-steps: a vector's step of N envs is N)."""
Measure = Callable[[], float]
"""One round's steps/s of one side."""


class Closeable(Protocol):
    """An environment (or a vector of them) that is closed after its measure."""

    def close(self) -> None:
        """Free what it holds (servers, workers)."""


Env = TypeVar("Env", bound=Closeable)


def arguments(description: str | None, smoke_rounds: int = 2) -> argparse.Namespace:
    """The recipes' command line: ``--rounds``, ``--seconds`` and ``--smoke``.

    ``--seconds`` is a side's share of a round; ``--smoke`` is ``smoke_rounds`` rounds of 0.5 s,
    what a smoke test needs (not a figure).
    """
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--smoke", action="store_true", help=f"{smoke_rounds} rounds of 0.5 s")
    parsed = parser.parse_args()
    if parsed.smoke:
        parsed.rounds, parsed.seconds = smoke_rounds, 0.5
    return parsed


def rate(stepper: Stepper, seconds: float) -> float:
    """Env-steps per second of calling ``stepper`` until ``seconds`` have passed."""
    steps = 0
    start = time.perf_counter()
    while True:
        steps += stepper()
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return steps / elapsed


@dataclass
class Contest:
    """The rates of rlenv and of native CartPole-v1, round by round."""

    name: str
    rlenv: list[float]
    native: list[float]

    @property
    def ratios(self) -> list[float]:
        """The rate of rlenv over the native one's, round by round."""
        return [ours / theirs for ours, theirs in zip(self.rlenv, self.native, strict=True)]

    def __str__(self) -> str:
        def rates(values: list[float]) -> str:
            return f"min {min(values):,.0f}, median {statistics.median(values):,.0f} steps/s"

        ratios = self.ratios
        return (
            f"{self.name}: rlenv/CartPole-v1 {rates(self.rlenv)}; CartPole-v1 "
            f"{rates(self.native)}; ratio over {len(ratios)} rounds in turns: min "
            f"{min(ratios):.3f}, median {statistics.median(ratios):.3f}"
        )


def contest(name: str, rlenv: Measure, native: Measure, rounds: int) -> Contest:
    """``rounds`` rounds of one measure of each side, in turns (rlenv first in even rounds)."""
    result = Contest(name, [], [])
    for turn in range(rounds):
        sides = [(result.rlenv, rlenv), (result.native, native)]
        for rates, measure in sides if turn % 2 == 0 else reversed(sides):
            rates.append(measure())
    return result


def timed(stepper: Stepper, seconds: float) -> Measure:
    """A measure that calls ``stepper`` once to warm up, then gives its :func:`rate`."""
    stepper()
    return lambda: rate(stepper, seconds)


def print_contest(
    name: str, ours: Env, theirs: Env, measure: Callable[[Env], Measure], rounds: int
) -> None:
    """Print the :func:`contest` of ``measure(ours)`` against ``measure(theirs)``; close both.

    ``measure`` readies a side (seeds it, warms it up) and gives its round's measure.
    """
    try:
        print(contest(name, measure(ours), measure(theirs), rounds))
    finally:
        ours.close()
        theirs.close()
