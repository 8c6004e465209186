"""Where a CartPole step's time goes: ``python benchmarks/overhead.py``.

Prints, in one run and in-process (no sockets):

- the **floor**: the agent's own code and the pymunk step called directly, in the order the
  tree calls them (check the action, set it, then per tick ``_physics_process``,
  ``space.step``, ``_after_physics_tick``; then ``get_data``), with no tree around them;
- a full **step** through :class:`rlenv.instance.Instance` (request check, tree, timer,
  response), and its ratio to the floor;
- both split into a cost per tick and a cost per request, from steps of 1 and of ``REPEAT``
  ticks (per tick = the difference over the extra ticks; per request = the rest);
- the **codec**: encoding and decoding the request and the response with the sans-IO protocol;
- a **column step** (``steps`` request) of ``INSTANCES`` instances at repeat_action 1, as a
  multi-instance server answers it, per instance, against its floor (the same agent code and
  pymunk steps for every instance, called directly), and the codec of that request and answer
  per instance.

This is the profile behind issue 5's figures: what the framework adds to user code, per step.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numpy as np

from examples.cartpole import CartPoleEnvironment
from rlenv.columns import ColumnStepper
from rlenv.instance import Instance
from rlenv.physics import PhysicsWorld
from rlenv.protocol import Connection, Request, Role, Steps
from rlenv.spaces import check

STEPS = 20_000
ROUNDS = 3
REPEAT = 4
INSTANCES = 32
OBSERVE = {"agent": {}}
# No push and a pole allowed to swing all the way round: one episode for the whole run, so
# every figure is a step and none a reset.
ENDLESS = {"agent": {"angle_limit": 1e9}, "world": {"track_limit": 1e9}}


def _per_step(*runs: Callable[[int], None]) -> list[float]:
    """Median microseconds per step of each ``run(STEPS)``, their rounds taken in turns.

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
    return [statistics.median(kept) for kept in times]


def main() -> None:
    instance = Instance(CartPoleEnvironment)
    instance.call(Request(id=1, config=ENDLESS, reset={"seed": 1}))
    action = np.zeros(1, np.float32)
    environment = instance.environment
    agent = environment.agent
    space = environment.find_children("*", PhysicsWorld)[0].space
    delta = instance.tree.physics_delta

    def floor(repeat: int) -> Callable[[int], None]:
        def run(steps: int) -> None:
            for _ in range(steps):
                agent.set_action(check(agent.action_space, action))
                for _ in range(repeat):
                    agent._physics_process(delta)
                    space.step(delta)
                    agent._after_physics_tick(delta)
                agent.terminated = False
                agent.get_data(OBSERVE["agent"])
        return run

    def step(repeat: int) -> Callable[[int], None]:
        def run(steps: int) -> None:
            for index in range(steps):
                reply = instance.call(Request(id=index, action=action, observation=OBSERVE,
                                              repeat_action=repeat))
                assert not (reply.terminated or reply.truncated), "the episode must not end"
        return run

    server, client = Connection(Role.SERVER), Connection(Role.CLIENT)
    client.receive_data(server.send(instance.hello))
    client.next_message()
    request = Request(id=2, action=action, observation=OBSERVE)
    reply = instance.call(request)

    def codec(steps: int) -> None:
        for _ in range(steps):
            server.receive_data(client.send(request))
            server.next_message()
            client.receive_data(server.send(reply))
            client.next_message()

    floor_us, floor_1, step_us, step_1, codec_us = _per_step(
        floor(REPEAT), floor(1), step(REPEAT), step(1), codec)
    column_us, column_floor_us, column_codec_us = _column_step()
    floor_tick, step_tick = (floor_us - floor_1) / (REPEAT - 1), (step_us - step_1) / (REPEAT - 1)
    print(f"CartPole, repeat_action={REPEAT}, microseconds per step (medians of {ROUNDS} rounds "
          "taken in turns)")
    print(f"  floor (agent code + pymunk only)   {floor_us:7.1f}")
    print(f"  full step through the tree         {step_us:7.1f}   {step_us / floor_us:.2f}x floor")
    print(f"  framework overhead                 {step_us - floor_us:7.1f}")
    print(f"  codec (request + reply, both ends) {codec_us:7.1f}")
    print(f"    per tick:    floor {floor_tick:6.1f}   through the tree {step_tick:6.1f}")
    print(f"    per request: floor {floor_1 - floor_tick:6.1f}   through the tree "
          f"{step_1 - step_tick:6.1f}")
    print(f"column step of {INSTANCES} instances, repeat_action=1, microseconds per instance")
    print(f"  floor (agent code + pymunk only)   {column_floor_us:7.1f}")
    print(f"  through the trees (ColumnStepper)  {column_us:7.1f}   "
          f"{column_us / column_floor_us:.2f}x floor")
    print(f"  codec (request + answer, both ends) {column_codec_us:6.1f}")


def _column_step() -> tuple[float, float, float]:
    """Per instance: a steps request through a ColumnStepper, its floor, and its codec."""
    instances = [Instance(CartPoleEnvironment) for _ in range(INSTANCES)]
    for seed, instance in enumerate(instances):
        instance.call(Request(id=1, config=ENDLESS, reset={"seed": seed}))
    stepper = ColumnStepper(instances)
    request = Request(id=2, steps=Steps(np.zeros((INSTANCES, 1), np.float32), None, 1))
    action = np.zeros(1, np.float32)
    parts = [(instance.environment.agent,
              instance.environment.find_children("*", PhysicsWorld)[0].space)
             for instance in instances]
    delta = instances[0].tree.physics_delta

    def floor(steps: int) -> None:
        for _ in range(steps // INSTANCES):
            for agent, space in parts:
                agent.set_action(check(agent.action_space, action))
                agent._physics_process(delta)
                space.step(delta)
                agent._after_physics_tick(delta)
                agent.get_data(OBSERVE["agent"])

    def through(steps: int) -> None:
        for _ in range(steps // INSTANCES):
            stepper.answer(request)

    server, client = Connection(Role.SERVER), Connection(Role.CLIENT)
    client.receive_data(server.send(instances[0].hello))
    client.next_message()
    answer = stepper.answer(request)

    def codec(steps: int) -> None:
        for _ in range(steps // INSTANCES):
            server.receive_data(client.send(request))
            server.next_message()
            client.receive_data(server.send(answer))
            client.next_message()

    through_us, floor_us, codec_us = _per_step(through, floor, codec)
    return through_us, floor_us, codec_us


if __name__ == "__main__":
    main()
