"""What going to a step of a 10,000-step episode costs: ``python benchmarks/time_travel.py``.

Records one 10,000-step episode of each environment over a real server, opens it as a
:class:`~rlenv_tools.timeline.Timeline` (which re-simulates it once, checking every digest, and
parks its checkpoints: forked copies of the environment's process), then goes to random steps
in a random order, each through ``timeline.at(step)`` (the observation, the draw list and every
node's exported properties: what the inspector's page shows). Printed: the open time, the
spacing and count of checkpoints and what they hold in memory, and min / median / 95th
percentile / max of a jump, beside the baseline a snapshot gives (restore the reset on a scratch
environment and replay the actions up to the step), in turns with the jumps.

- ``cartpole``: the light scene (``angle_limit`` and ``track_limit`` 1e9: it never ends);
- ``plinko``: Plinko's levels at difficulty 1 (the most pegs), the ball dropped again from the
  top whenever it lands, so that one episode lasts 10,000 steps of contacts.
"""

from __future__ import annotations

import argparse
import random
import statistics
import time
from pathlib import Path
from tempfile import TemporaryDirectory

import numpy as np

from rlenv.examples.cartpole import controller
from rlenv.examples.plinko import TOP, PlinkoAgent, PlinkoEnvironment, follow
from rlenv_client import Client
from rlenv_client.launcher import ServerProcess
from rlenv_client.replay import EpisodeFile, digest
from rlenv_tools.forking import ForkedEnvironment
from rlenv_tools.timeline import Timeline

STEPS = 10_000


class EndlessPlinkoAgent(PlinkoAgent):
    """Plinko's agent, but a ball that lands is dropped again: the episode never ends."""

    def _after_physics_tick(self, delta: float) -> None:
        world = self._world()
        if world.caught or world.landed:
            if world.caught:
                self.add_reward(1.0)
            assert world.ball is not None
            world.ball.position = (float(world.np_random.uniform(-3.0, 3.0)), TOP - 0.3)
            world.ball.velocity = (0.0, 0.0)
            world.caught = world.landed = False


class EndlessPlinko(PlinkoEnvironment):
    """Plinko with :class:`EndlessPlinkoAgent`."""

    def __init__(self) -> None:
        super().__init__()
        self.remove_child(self.get_node("Agent"))
        self.add_child(EndlessPlinkoAgent())
        self.move_child(self.get_node("Agent"), 0)


ENVIRONMENTS = {
    "cartpole": (
        "examples.cartpole:CartPoleEnvironment",
        {"environment": {}, "world": {"track_limit": 1e9}, "agent": {"angle_limit": 1e9}},
        controller,
    ),
    "plinko": (
        "benchmarks.time_travel:EndlessPlinko",
        {"environment": {}, "world": {"difficulty": 1.0}, "agent": {}},
        follow,
    ),
}


def record(target: str, config: dict, policy, path: Path) -> None:
    """One ``STEPS``-step episode under a noisy ``policy``, written to ``path``."""
    with ServerProcess(target) as server, Client(server.host, server.port, timeout=60) as client:
        client.configure(agent=config["agent"] or None, world=config["world"] or None)
        observation, _ = client.reset(seed=1)
        digests = [digest(observation)]
        for t in range(STEPS):
            noise = 0.4 * np.sin(t / 7.0)
            action = np.clip(policy(observation) + noise, -1, 1).astype(np.float32)
            observation, _, terminated, truncated, _ = client.step(action)
            digests.append(digest(observation))
            assert not (terminated or truncated), f"{target} ended at step {t + 1}"
        EpisodeFile(target, client.snapshot(), digests, False, False).save(path)


def replayed(episode: EpisodeFile, environment: ForkedEnvironment, step: int) -> float:
    """Seconds to reach ``step`` from a snapshot: restore the reset, replay the actions."""
    began = time.perf_counter()
    environment.call("restore", {**episode.snapshot, "events": episode.snapshot["events"][:step]})
    environment.call("tree")
    environment.call("draw")
    return time.perf_counter() - began


def private_megabytes(pids: list[int]) -> float:
    """The memory the processes hold alone (USS), in MiB."""
    from procfs import memory_kib  # a sibling when run as a script; a server importing this
    # module for EndlessPlinko never calls it

    return sum(memory_kib(pid)[1] for pid in pids) / 1024


def summary(seconds: list[float]) -> str:
    ordered = sorted(seconds)
    p95 = ordered[min(len(ordered) - 1, int(0.95 * len(ordered)))]
    return (
        f"min {1e3 * ordered[0]:7.2f} ms  median {1e3 * statistics.median(ordered):7.2f} ms  "
        f"p95 {1e3 * p95:7.2f} ms  max {1e3 * ordered[-1]:7.2f} ms"
    )


def measure(name: str, jumps: int, baselines: int) -> None:
    target, config, policy = ENVIRONMENTS[name]
    with TemporaryDirectory() as directory:
        path = Path(directory) / "episode.rlenv"
        began = time.perf_counter()
        record(target, config, policy, path)
        recorded = time.perf_counter() - began
        episode = EpisodeFile.load(path)
        began = time.perf_counter()
        timeline = Timeline(episode)
        opened = time.perf_counter() - began
        baseline = ForkedEnvironment.start(target)
        try:
            every = timeline._checkpoints.every
            pids = timeline.processes
            print(
                f"{name}: {len(timeline)} steps recorded in {recorded:.1f} s; opened (every "
                f"step re-simulated and checked) in {opened:.1f} s; a checkpoint every "
                f"{every} steps: {len(pids)} processes holding "
                f"{private_megabytes(pids):.0f} MiB of their own"
            )
            rng = random.Random(7)
            random_steps = [rng.randrange(len(timeline) + 1) for _ in range(jumps)]
            start = rng.randrange(len(timeline) // 2, len(timeline))
            dragged_back = [max(0, start - 3 * k) for k in range(jumps)]
            agent = [path for path in timeline.at(0).properties if path.endswith("/Agent")]
            for pattern, steps, nodes in (
                ("random steps", random_steps, None),
                ("random steps, the agent's properties only", random_steps, agent),
                ("a drag back, 3 steps apart", dragged_back, None),
            ):
                jumped, replays = [], []
                for index, step in enumerate(steps):
                    began = time.perf_counter()
                    state = timeline.at(step, nodes=nodes)
                    jumped.append(time.perf_counter() - began)
                    assert digest(state.observation) == episode.observations[step]
                    if index % (jumps // baselines) == 0:
                        replays.append(replayed(episode, baseline, step))
                ratio = statistics.median(replays) / statistics.median(jumped)
                print(
                    f"  {pattern}: timeline.at(step) x {jumps}: {summary(jumped)}; "
                    f"over 50 ms: {sum(s > 0.05 for s in jumped)}"
                )
                print(
                    f"    the baseline, snapshot replayed from the reset, x {len(replays)}: "
                    f"{summary(replays)}; ratio of medians {ratio:.0f}x"
                )
        finally:
            baseline.end()
            timeline.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jumps", type=int, default=300)
    parser.add_argument("--baselines", type=int, default=10)
    parser.add_argument("environments", nargs="*", default=list(ENVIRONMENTS))
    args = parser.parse_args()
    for name in args.environments:
        measure(name, args.jumps, args.baselines)


if __name__ == "__main__":
    main()
