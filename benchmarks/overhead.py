"""Where a CartPole step's time goes: ``python benchmarks/overhead.py``.

Prints, in one run and in-process (no sockets):

- the **floor**: the agent's own code and the pymunk step called directly, in the order the
  tree calls them (check the action, set it, then per tick ``_physics_process``,
  ``space.step``, ``_after_physics_tick``; then ``get_data``), with no tree around them;
- a full **step** through :class:`rlenv.instance.Instance` (request check, tree, timer,
  response), and its ratio to the floor;
- both split into a cost per tick and a cost per request, from steps of 1 and of ``REPEAT``
  ticks (per tick = the difference over the extra ticks; per request = the rest);
- the **codec**: encoding and decoding the request and the response with the sans-IO protocol.

This is the profile behind issue 5's figures: what the framework adds to user code, per step.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numpy as np

from examples.cartpole import CartPoleEnvironment
from rlenv.instance import Instance
from rlenv.physics import PhysicsWorld
from rlenv.protocol import Connection, Request, Role
from rlenv.spaces import check

STEPS = 20_000
ROUNDS = 3
REPEAT = 4
OBSERVE = {"agent": {}}


def _per_step(run: Callable[[int], None]) -> float:
    """Median microseconds per step of ``run(STEPS)`` over ``ROUNDS`` rounds, after a warm-up."""
    run(STEPS // 10)
    times = []
    for _ in range(ROUNDS):
        start = time.perf_counter()
        run(STEPS)
        times.append((time.perf_counter() - start) / STEPS * 1e6)
    return statistics.median(times)


def main() -> None:
    instance = Instance(CartPoleEnvironment)
    # No push and a pole allowed to swing all the way round: one episode for the whole run, so
    # every figure is a step and none a reset.
    instance.call(Request(id=1, config={"agent": {"angle_limit": 1e9}}, reset={"seed": 1}))
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

    floor_us, floor_1 = _per_step(floor(REPEAT)), _per_step(floor(1))
    step_us, step_1 = _per_step(step(REPEAT)), _per_step(step(1))
    codec_us = _per_step(codec)
    floor_tick, step_tick = (floor_us - floor_1) / (REPEAT - 1), (step_us - step_1) / (REPEAT - 1)
    print(f"CartPole, repeat_action={REPEAT}, microseconds per step (medians of {ROUNDS} rounds)")
    print(f"  floor (agent code + pymunk only)   {floor_us:7.1f}")
    print(f"  full step through the tree         {step_us:7.1f}   {step_us / floor_us:.2f}x floor")
    print(f"  framework overhead                 {step_us - floor_us:7.1f}")
    print(f"  codec (request + reply, both ends) {codec_us:7.1f}")
    print(f"    per tick:    floor {floor_tick:6.1f}   through the tree {step_tick:6.1f}")
    print(f"    per request: floor {floor_1 - floor_tick:6.1f}   through the tree "
          f"{step_1 - step_tick:6.1f}")


if __name__ == "__main__":
    main()
