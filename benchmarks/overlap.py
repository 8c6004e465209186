"""Does overlapping pay? Vector layouts of CartPole stepped in one run, rounds in turns.

``python benchmarks/overlap.py [--rounds R] [--seconds S]`` steps CartPoles the way
``gymnasium.make_vec("rlenv/CartPole-v0", num_envs=N)`` does (repeat_action 4, random actions,
the 500-step time limit, an ended episode reset on its next step through the ``steps``
request's reset mask), with ``Client.send_steps`` / ``receive_steps`` driven directly, in
these layouts:

- ``servers``: today's layout, one server per core (2 x N/2), every server sent its request,
  then every answer gathered;
- ``+L local``: 2 servers of (N - L)/2 and L instances in this process (a
  ``LocalClient(target, instances=L)``), stepped between sending to the servers and gathering
  their answers;
- ``double``: double buffering as Sample Factory does it: two halves of N/2, each in 2 servers
  of N/4; the trainer handles one half's answer (and sends it its next actions) while the
  other half steps;
- ``one server``: all N in one server (one request per step, one core);
- ``local only``: all N in this process, one group (no server: the cost without sockets).

Each layout runs a warm-up round, then the layouts take turns for R rounds; a round is as
many vector steps as make ~S seconds at the speed of the warm-up. It prints, per layout, the
env-steps per second (min and median), the CPU microseconds per env-step of its servers (from
``/proc/PID/stat``) and of this process (``time.process_time``, the local instances
included), the cores they kept busy (speed times CPU per env-step: what overlap could gain
is what ``servers`` leaves idle of the machine's cores), and the ratios of the speed to
``servers`` (min and median of the per-round ratios). Only ratios within one run mean
anything on a machine whose speed drifts.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field

import numpy as np
from procfs import cpu_seconds

from rlenv_client import Client, LocalClient, ServerProcess

CARTPOLE = "examples.cartpole:CartPoleEnvironment"
REPEAT = 4
TIME_LIMIT = 500


@dataclass
class Shard:
    """A group of instances behind one client, and its columns of the vector."""

    client: Client | LocalClient
    start: int
    stop: int


@dataclass
class Vector:
    """The bookkeeping a vector does per step, over some shards (autoreset, time limit)."""

    shards: list[Shard]
    num_envs: int
    actions: list[np.ndarray]
    observations: np.ndarray = field(init=False)
    resetting: np.ndarray = field(init=False)
    steps: np.ndarray = field(init=False)
    turn: int = 0

    def __post_init__(self) -> None:
        space = self.shards[0].client.observation_space
        self.observations = np.zeros((self.num_envs, *space.shape), space.dtype)
        self.resetting = np.ones(self.num_envs, np.bool_)  # the first step resets every one
        self.steps = np.zeros(self.num_envs, np.int64)

    def send(self, shard: Shard) -> None:
        """Send ``shard`` its actions and reset mask."""
        span = slice(shard.start, shard.stop)
        shard.client.send_steps(
            self.actions[self.turn % len(self.actions)][span], self.resetting[span], REPEAT
        )

    def receive(self, shard: Shard) -> None:
        """Gather ``shard``'s answer into the columns; mark its ended episodes to reset."""
        answer = shard.client.receive_steps()
        if answer.errors is not None:
            raise RuntimeError(f"{shard.client.address}: {answer.errors}")
        span = slice(shard.start, shard.stop)
        self.observations[span] = answer.observation
        resetting = self.resetting[span]
        steps = self.steps[span]
        steps[resetting] = 0
        steps[~resetting] += 1
        self.resetting[span] = answer.terminated | answer.truncated | (steps >= TIME_LIMIT)


def start_servers(stack: ExitStack, counts: list[int]) -> tuple[list[Client], list[int]]:
    """Servers of ``counts`` instances each, connected; their clients and pids."""
    servers = [
        stack.enter_context(ServerProcess(CARTPOLE, args=["--instances", str(count)]))
        for count in counts
    ]
    clients = [stack.enter_context(Client(server.host, server.port)) for server in servers]
    return clients, [server.process.pid for server in servers]


def shards_of(clients: list[Client | LocalClient], counts: list[int]) -> list[Shard]:
    """One shard per client, their columns in order."""
    shards, start = [], 0
    for client, count in zip(clients, counts, strict=True):
        shards.append(Shard(client, start, start + count))
        start += count
    return shards


Round = Callable[[int], tuple[float, float, float]]  # vector steps -> (speed, server, client)


def measured(
    step: Callable[[], None],
    num_envs: int,
    pids: list[int],
    flush: Callable[[], None] = lambda: None,
) -> Round:
    """A round: ``steps`` calls of ``step`` (then ``flush``), timed and CPU counted."""

    def round_(steps: int) -> tuple[float, float, float]:
        servers = sum(cpu_seconds(pid) for pid in pids)
        client = time.process_time()
        start = time.perf_counter()
        for _ in range(steps):
            step()
        flush()
        elapsed = time.perf_counter() - start
        env_steps = steps * num_envs
        return (
            env_steps / elapsed,
            (sum(cpu_seconds(pid) for pid in pids) - servers) / env_steps * 1e6,
            (time.process_time() - client) / env_steps * 1e6,
        )

    return round_


def synchronous(
    stack: ExitStack, counts: list[int], local: int, actions: list[np.ndarray]
) -> Round:
    """Servers of ``counts``, and ``local`` instances in this process stepped in between."""
    clients, pids = start_servers(stack, counts)
    everyone: list[Client | LocalClient] = list(clients)
    if local:
        everyone.append(stack.enter_context(LocalClient(CARTPOLE, instances=local)))
    shards = shards_of(everyone, [*counts, local] if local else counts)
    vector = Vector(shards, sum(counts) + local, actions)
    remote, here = shards[: len(clients)], shards[len(clients) :]

    def step() -> None:
        for shard in remote:
            vector.send(shard)
        for shard in here:
            vector.send(shard)
            vector.receive(shard)
        for shard in remote:
            vector.receive(shard)
        vector.turn += 1

    return measured(step, vector.num_envs, pids)


def double_buffered(stack: ExitStack, counts: list[int], actions: list[np.ndarray]) -> Round:
    """Two halves, each in servers of ``counts``: one half steps while the other is handled."""
    clients, pids = start_servers(stack, counts + counts)
    shards = shards_of(list(clients), counts + counts)
    vector = Vector(shards, 2 * sum(counts), actions)
    halves = [shards[: len(counts)], shards[len(counts) :]]
    in_flight: list[bool] = [False, False]
    state = {"half": 0}

    def step() -> None:  # two half-steps: as many env-steps as one vector step
        for _ in range(2):
            half = state["half"]
            if in_flight[half]:
                for shard in halves[half]:
                    vector.receive(shard)
            for shard in halves[half]:
                vector.send(shard)
            in_flight[half] = True
            state["half"] = 1 - half
        vector.turn += 1

    def flush() -> None:  # end the round with nothing in flight
        for half in (0, 1):
            if in_flight[half]:
                for shard in halves[half]:
                    vector.receive(shard)
                in_flight[half] = False

    return measured(step, vector.num_envs, pids, flush)


def local_only(stack: ExitStack, num_envs: int, actions: list[np.ndarray]) -> Round:
    """Every instance in this process, one group."""
    client = stack.enter_context(LocalClient(CARTPOLE, instances=num_envs))
    vector = Vector([Shard(client, 0, num_envs)], num_envs, actions)

    def step() -> None:
        vector.send(vector.shards[0])
        vector.receive(vector.shards[0])
        vector.turn += 1

    return measured(step, num_envs, [])


def layouts(stack: ExitStack, num_envs: int, locals_: list[int]) -> dict[str, Round]:
    """The layouts measured for ``num_envs`` CartPoles (the first is the baseline)."""
    rng = np.random.default_rng(0)
    actions = [rng.uniform(-1, 1, (num_envs, 1)).astype(np.float32) for _ in range(64)]
    half = num_envs // 2
    found = {f"servers 2 x {half}": synchronous(stack, [half, half], 0, actions)}
    for local in locals_:
        share = (num_envs - local) // 2
        found[f"2 x {share} + {local} local"] = synchronous(stack, [share, share], local, actions)
    quarter = num_envs // 4
    found[f"double 2 x (2 x {quarter})"] = double_buffered(stack, [quarter, quarter], actions)
    found[f"one server x {num_envs}"] = synchronous(stack, [num_envs], 0, actions)
    found[f"local only {num_envs}"] = local_only(stack, num_envs, actions)
    return found


def compare(num_envs: int, rounds_of: dict[str, Round], rounds: int, seconds: float) -> None:
    """Warm up each layout, size its rounds, run them in turns, print the figures."""
    sizes = {}
    for name, round_ in rounds_of.items():
        round_(20)
        speed, _, _ = round_(50)
        sizes[name] = max(20, int(speed * seconds / num_envs))
    results: dict[str, list[tuple[float, float, float]]] = {name: [] for name in rounds_of}
    for _ in range(rounds):
        for name, round_ in rounds_of.items():
            results[name].append(round_(sizes[name]))
    print(
        f"\n{num_envs} CartPoles, repeat {REPEAT}: env-steps/s min, median; CPU us per "
        "env-step (medians): servers, this process; cores busy; speed / first layout's, "
        "min and median of the rounds' ratios"
    )
    baseline = results[next(iter(results))]
    for name, values in results.items():
        speeds = [v[0] for v in values]
        ratios = [v[0] / b[0] for v, b in zip(values, baseline, strict=True)]
        server = statistics.median(v[1] for v in values)
        client = statistics.median(v[2] for v in values)
        cores = statistics.median(v[0] * (v[1] + v[2]) / 1e6 for v in values)
        print(
            f"  {name:26s} {min(speeds):7.0f} {statistics.median(speeds):7.0f}/s"
            f"   cpu {server:5.1f} + {client:5.1f} = {server + client:5.1f} us"
            f"  {cores:4.2f} cores"
            f"   x{min(ratios):.2f} x{statistics.median(ratios):.2f}",
            flush=True,
        )


def main() -> None:
    """Parse the arguments and measure at 64 and at 8 environments."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--seconds", type=float, default=1.0, help="length of a round")
    parser.add_argument("--envs", type=int, nargs="*", default=[64, 8])
    arguments = parser.parse_args()
    splits = {64: [4, 8, 16], 8: [2, 4]}
    for num_envs in arguments.envs:
        with ExitStack() as stack:
            found = layouts(stack, num_envs, splits.get(num_envs, [num_envs // 8 or 1]))
            compare(num_envs, found, arguments.rounds, arguments.seconds)


if __name__ == "__main__":
    main()
