"""Where a CartPole step's time goes: ``python benchmarks/overhead.py``.

Prints, in one run, each figure beside its floor (rounds taken in turns, medians and minimums):

- **framework per tick and per request**, in this process: a step through the host's one door
  (:meth:`rlenv.serving._host.Host.answer`: checks, plan, tree, timer, answer) against the
  floor: what a hand-written server does for the same step (decode the action from its bytes,
  the agent's ``set_action``, per tick ``_physics_process``, ``space.step`` and
  ``_after_physics_tick``, then ``get_data`` and the observation's bytes), at repeat_action 1,
  ``REPEAT`` and ``LONG``; per tick is the slope over the extra ticks of ``LONG``, per request
  the rest at repeat 1;
- **the codec, both ends**: the client building the step request and its frame, the server
  reading it, the server's answer as a frame, the client reading it into gymnasium's 5-tuple;
  against plain msgpack doing the same with ``tobytes`` / ``frombuffer``;
- a **column step** (``steps`` request) of ``INSTANCES`` instances at repeat_action 1, per
  instance, against the same floor for every instance.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import msgpack
import numpy as np

from rlenv.examples.cartpole import CartPoleEnvironment
from rlenv.protocol import Connection, Request, Role
from rlenv.scene2d.physics import PhysicsWorld
from rlenv.serving._host import Host
from rlenv_client.base import BaseClient

STEPS = 20_000
ROUNDS = 7
REPEAT = 4
LONG = 12  # the repeat whose extra ticks give the cost per tick
INSTANCES = 32
# No push and a pole allowed to swing all the way round: one episode for the whole run, so
# every figure is a step and none a reset.
ENDLESS = {"agent": {"angle_limit": 1e9}, "world": {"track_limit": 1e9}}
ACTION = np.zeros(1, np.float32)


def _per_step(*runs: Callable[[int], None]) -> list[tuple[float, float]]:
    """(median, min) microseconds per step of each ``run(STEPS)``, rounds taken in turns.

    After a warm-up round each; taking turns puts a figure and its floor under the same
    conditions however the machine's speed drifts.
    """
    for run in runs:
        run(STEPS // 10)
    times: list[list[float]] = [[] for _ in runs]
    for _ in range(ROUNDS):
        for run, kept in zip(runs, times, strict=True):
            start = time.perf_counter()
            run(STEPS)
            kept.append((time.perf_counter() - start) / STEPS * 1e6)
    return [(statistics.median(kept), min(kept)) for kept in times]


def _host(count: int = 1) -> Host:
    host = Host(CartPoleEnvironment, count)
    host.answer(
        Request(
            1, {"batch": [{"config": ENDLESS, "reset": {"seed": seed}} for seed in range(count)]}
        )
    )
    return host


def _floor(host: Host, repeat: int) -> Callable[[int], None]:
    """A hand-written server's work for ``steps`` steps of every instance of ``host``."""
    parts = []
    for instance in host.instances:
        world = instance.environment.find_children("*", PhysicsWorld)[0]
        parts.append((instance.agents[0], world.space))
    delta = host.instances[0].tree.physics_delta
    packed = ACTION.tobytes()

    def run(steps: int) -> None:
        for _ in range(steps // len(parts)):
            for agent, space in parts:
                agent.set_action(np.frombuffer(packed, np.float32))
                for _ in range(repeat):
                    agent._physics_process(delta)
                    space.step(delta)
                    agent._after_physics_tick(delta)
                agent.reward = 0.0
                agent.get_data({}).tobytes()

    return run


def _through(host: Host, repeat: int) -> Callable[[int], None]:
    """Steps through the host's door, as a server answers them (no socket, no codec)."""
    request = Request(
        2, {"action": ACTION.tobytes(), "observation": {"agent": {}}, "repeat_action": repeat}
    )

    def run(steps: int) -> None:
        for _ in range(steps):
            reply = host.answer(request)
        assert not (reply.terminated or reply.truncated), "the episode must not end"

    return run


def _codecs(host: Host) -> tuple[Callable[[int], None], Callable[[int], None]]:
    """rlenv's codec at both ends of a step, and plain msgpack doing the same work."""
    server, client = Connection(Role.SERVER), Connection(Role.CLIENT)
    client.receive_data(server.send(host.hello))
    client.next_message()
    endpoint = _Client(host)
    reply = host.answer(endpoint.step_request(ACTION, REPEAT, request_id=1))

    def ours(steps: int) -> None:
        for index in range(steps):
            server.receive_data(
                client.send(endpoint.step_request(ACTION, REPEAT, request_id=index))
            )
            request = server.next_message()
            reply.id = request.id  # type: ignore[union-attr]
            client.receive_data(server.send(reply))
            endpoint.step_result(client.next_message())  # type: ignore[arg-type]

    observation = np.zeros(5, np.float32)
    agent = {"agent": {}}

    def plain(steps: int) -> None:
        for index in range(steps):
            request = msgpack.unpackb(
                msgpack.packb(
                    {
                        "id": index,
                        "action": ACTION.tobytes(),
                        "observation": agent,
                        "repeat_action": REPEAT,
                    }
                )
            )
            np.frombuffer(request["action"], np.float32)
            answer = msgpack.unpackb(
                msgpack.packb(
                    {
                        "id": request["id"],
                        "observation": {"agent": observation.tobytes()},
                        "reward": 4.0,
                        "terminated": False,
                        "truncated": False,
                        "info": {},
                        "frames": REPEAT,
                    }
                )
            )
            np.frombuffer(answer["observation"]["agent"], np.float32).copy()

    return ours, plain


class _Client(BaseClient):
    """The client API with no transport: its request building and answer reading only."""

    def __init__(self, host: Host) -> None:
        super().__init__()
        self._set_hello(host.hello)
        self.address = "nowhere"

    def close(self) -> None:
        """Nothing to release."""

    def _send(self, request: Request) -> None:
        raise NotImplementedError

    def _receive(self) -> None:  # type: ignore[override]
        raise NotImplementedError


def main() -> None:
    """Measure and print every figure."""
    host = _host()
    repeats = (1, REPEAT, LONG)
    measured = _per_step(*(_floor(host, n) for n in repeats), *(_through(host, n) for n in repeats))
    floors, steps = (
        dict(zip(repeats, measured[:3], strict=True)),
        dict(zip(repeats, measured[3:], strict=True)),
    )
    print(
        f"CartPole in this process, microseconds per step (median and min of {ROUNDS} rounds "
        "taken in turns)"
    )
    for n in repeats:
        (floor, floor_min), (step, step_min) = floors[n], steps[n]
        print(
            f"  repeat {n:<2}  floor (a hand-written server's work) {floor:7.2f} (min "
            f"{floor_min:.2f})   through the host {step:7.2f} (min {step_min:.2f})   "
            f"{step / floor:.2f}x floor"
        )
    for which, label in ((0, "medians"), (1, "minimums")):
        # Per tick: the slope over the extra ticks of LONG; per request: the rest at repeat 1.
        tick = (steps[LONG][which] - steps[1][which] - floors[LONG][which] + floors[1][which]) / (
            LONG - 1
        )
        request = steps[1][which] - floors[1][which] - tick
        print(
            f"  framework above the floor, from the {label:8}: {tick:5.2f} per tick, "
            f"{request:5.2f} per request"
        )
    ours, plain = _codecs(host)
    (codec, codec_min), (bare, bare_min) = _per_step(ours, plain)
    print(
        f"  codec, both ends of a step: {codec:.2f} (min {codec_min:.2f}), "
        f"{codec / bare:.2f}x plain msgpack ({bare:.2f}, min {bare_min:.2f})"
    )
    columns, columns_floor = _column_step()
    print(f"column step of {INSTANCES} instances, repeat_action 1, microseconds per instance")
    print(
        f"  floor {columns_floor[0]:.2f} (min {columns_floor[1]:.2f})   through the host "
        f"(steps request) {columns[0]:.2f} (min {columns[1]:.2f})   "
        f"{columns[0] / columns_floor[0]:.2f}x floor"
    )


def _column_step() -> tuple[tuple[float, float], tuple[float, float]]:
    """Per instance: a steps request through the host, and its floor."""
    host = _host(INSTANCES)
    request = Request(
        2, {"steps": {"action": np.zeros((INSTANCES, 1), np.float32).tobytes(), "repeat_action": 1}}
    )

    def through(steps: int) -> None:
        for _ in range(steps // INSTANCES):
            host.answer(request)

    through_us, floor_us = _per_step(through, _floor(host, 1))
    return through_us, floor_us


if __name__ == "__main__":
    main()
