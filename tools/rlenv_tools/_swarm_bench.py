"""``rlenv bench --swarm`` (``python benchmarks/swarm.py``): a swarm as one group, as nodes, bare.

``examples/swarm`` for N in 16, 64 and 256 members, three ways, each stepped on the same random
actions (one pool of 16 drawn from seed 0), episodes of no time limit (``episode_ticks``
configured away: few members reach the nest on random actions) reset from the next seed when
every member has left:

- **group**: the flock as one ``RLAgentGroup`` (``SwarmEnvironment``), served: a
  :class:`~rlenv_client.Client` steps it over a server in a subprocess, as a trainer would
  (loopback, its shared-memory lane), one ``(N, 2)`` action array a step;
- **nodes**: the same scene as N ``RLAgent`` nodes (``SwarmNodesEnvironment``), served the same
  way, one action per member in play a step;
- **floor**: the same game in bare pymunk and numpy in this process
  (:class:`examples.swarm.scene.SwarmFloor`): what a step costs without rlenv.

Each step runs 4 physics ticks. A figure is agent-steps per second: the members each step
stepped (the rows an answer reports), per second of the round. The three take their rounds in
turns, after a warm-up round each; a figure is the median of its rounds.
"""

from __future__ import annotations

import logging
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rlenv.targets import import_module

__all__ = ["SIZES", "SwarmRates", "measure_swarm", "summary_line", "swarm_line"]

logger = logging.getLogger(__name__)

SIZES = (16, 64, 256)
"""The flocks measured."""
SWARM = "rlenv.examples.swarm"
_ENDLESS = 2**31 - 1
"""``episode_ticks`` for the benchmark: no time limit."""
_POOL = 16
"""Random actions drawn once, taken in turn."""


@dataclass
class SwarmRates:
    """The rounds of one flock: agent-steps per second of each way, one value a round."""

    count: int
    group: list[float] = field(default_factory=list)
    nodes: list[float] = field(default_factory=list)
    floor: list[float] = field(default_factory=list)

    def median(self, way: str) -> float:
        """The median of ``way``'s rounds (``"group"``, ``"nodes"``, ``"floor"``)."""
        return statistics.median(getattr(self, way))

    def low(self, way: str) -> float:
        """The slowest of ``way``'s rounds."""
        return min(getattr(self, way))


def swarm_line(rates: SwarmRates) -> str:
    """``swarm N=256: group 123456 agent-steps/s, nodes 23456, floor 345678`` (medians)."""
    group, nodes, floor = (round(rates.median(way)) for way in ("group", "nodes", "floor"))
    return f"swarm N={rates.count}: group {group} agent-steps/s, nodes {nodes}, floor {floor}"


def summary_line(rates: SwarmRates) -> str:
    """``swarm: group/nodes 5.3x, floor/group 1.8x at N=256`` (of the medians)."""
    group = rates.median("group")
    return (
        f"swarm: group/nodes {group / rates.median('nodes'):.1f}x, "
        f"floor/group {rates.median('floor') / group:.1f}x at N={rates.count}"
    )


_Run = Callable[[int], int]
"""``run(steps)``: ``steps`` steps; how many agent-steps they were."""


def _actions(count: int) -> np.ndarray:
    return np.random.default_rng(0).uniform(-1, 1, (_POOL, count, 2)).astype(np.float32)


def _served(client: Any, count: int, group: str | None, slots: dict[str, int]) -> _Run:
    """Steps of a served flock: one group's array, or one row per member node asked.

    ``slots``: each member node's slot by name (the per-node version's).
    """
    from_seed = iter(range(1, 2**31))
    pool = _actions(count)
    client.configure(episode_ticks=_ENDLESS)
    observation = client.reset(seed=0)[0]
    turn = 0

    def run(steps: int) -> int:
        nonlocal observation, turn
        done = 0
        for _ in range(steps):
            actions = pool[turn % _POOL]
            turn += 1
            if group is not None:
                action: Any = {group: actions}
            else:
                action = {name: actions[slots[name]] for name in observation}
            observation, _, terminated, truncated, info = client.step(action)
            outcomes = info["agents"]
            done += int(outcomes[group]["active"].sum()) if group else len(outcomes)
            if terminated or truncated:
                observation = client.reset(seed=next(from_seed))[0]
        return done

    return run


def _floor(count: int) -> _Run:
    """Steps of :class:`~examples.swarm.scene.SwarmFloor`, reset the same way."""
    floor = import_module(f"{SWARM}.scene").SwarmFloor(count, episode_ticks=_ENDLESS)
    from_seed = iter(range(1, 2**31))
    pool = _actions(count)
    floor.reset(np.random.default_rng(0))
    turn = 0

    def run(steps: int) -> int:
        nonlocal turn
        done = 0
        for _ in range(steps):
            done += floor.step(pool[turn % _POOL])
            turn += 1
            if floor.ended():
                floor.reset(np.random.default_rng(next(from_seed)))
        return done

    return run


def _rate(run: _Run, steps: int) -> float:
    start = time.perf_counter()
    done = run(steps)
    return done / (time.perf_counter() - start)


def measure_swarm(
    rounds: int = 5,
    steps: int = 200,
    sizes: tuple[int, ...] = SIZES,
    progress: Callable[[str], None] = logger.info,
) -> list[SwarmRates]:
    """Measure every size (see the module docstring).

    Args:
        rounds: timed rounds of each way, taken in turns after a warm-up round each.
        steps: steps per round of the group and the floor; the nodes take ``steps * 16 / N``
            (at least 10), their rounds lasting about as long.
        sizes: the flocks.
        progress: told each round's figures.
    """
    from rlenv_client import Client, ServerProcess

    swarm = import_module(SWARM)
    results = []
    for count in sizes:
        with (
            ServerProcess(swarm.TARGETS[count]) as group_server,
            Client(group_server.host, group_server.port, timeout=120) as group_client,
            ServerProcess(swarm.NODE_TARGETS[count]) as nodes_server,
            Client(nodes_server.host, nodes_server.port, timeout=120) as nodes_client,
        ):
            slots = {swarm.member_name(slot): slot for slot in range(count)}
            ways = {
                "group": (_served(group_client, count, swarm.GROUP, slots), steps),
                "nodes": (
                    _served(nodes_client, count, None, slots),
                    max(10, steps * 16 // count),
                ),
                "floor": (_floor(count), steps),
            }
            rates = SwarmRates(count)
            for run, taken in ways.values():
                run(taken)  # warm-up
            for number in range(rounds):
                for way, (run, taken) in ways.items():
                    getattr(rates, way).append(_rate(run, taken))
                progress(
                    f"N={count} round {number + 1}/{rounds}: "
                    + ", ".join(f"{way} {getattr(rates, way)[-1]:,.0f}" for way in ways)
                )
        results.append(rates)
    return results
