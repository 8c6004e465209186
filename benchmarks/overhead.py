"""Where a CartPole step's time goes: ``python benchmarks/overhead.py``.

Prints, in one run and in-process (no sockets):

- the **floor**: the agent's own code and the pymunk step called directly, in the order the
  tree calls them (check the action, set it, then per tick ``_physics_process``,
  ``space.step``, ``_after_physics_tick``; then ``get_data``), with no tree around them;
- a full **step** through :class:`rlenv.instance.Instance` (request check, tree, timer,
  response), and its ratio to the floor;
- the step split by turn of the tree's loop: the turn that takes the request, the ticks in
  between, and the last tick with the response;
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

    def floor(steps: int) -> None:
        for _ in range(steps):
            agent.set_action(check(agent.action_space, action))
            for _ in range(REPEAT):
                agent._physics_process(delta)
                space.step(delta)
                agent._after_physics_tick(delta)
            agent.terminated = False
            agent.get_data(OBSERVE["agent"])

    def step(steps: int) -> None:
        for index in range(steps):
            reply = instance.call(Request(id=index, action=action, observation=OBSERVE))
            assert not (reply.terminated or reply.truncated), "the episode must not end"

    turns: list[list[float]] = []

    def step_by_turn(steps: int) -> None:
        replies = instance._endpoint.replies
        for index in range(steps):
            instance.submit(Request(id=index, action=action, observation=OBSERVE))
            times = []
            while not replies:
                start = time.perf_counter()
                environment.iterate()
                times.append((time.perf_counter() - start) * 1e6)
            turns.append(times)
            assert not replies.popleft().terminated, "the episode must not end"

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

    floor_us = _per_step(floor)
    step_us = _per_step(step)
    codec_us = _per_step(codec)
    step_by_turn(STEPS)
    by_turn = [statistics.median(column) for column in zip(*turns, strict=True)]
    print(f"CartPole, repeat_action={REPEAT}, microseconds per step (medians of {ROUNDS} rounds)")
    print(f"  floor (agent code + pymunk only)   {floor_us:7.1f}")
    print(f"  full step through the tree         {step_us:7.1f}   {step_us / floor_us:.2f}x floor")
    print(f"  framework overhead                 {step_us - floor_us:7.1f}")
    print(f"  codec (request + reply, both ends) {codec_us:7.1f}")
    names = ["take request"] + [f"tick {n}" for n in range(1, len(by_turn) - 1)] + ["last tick"]
    for name, micros in zip(names, by_turn, strict=True):
        print(f"    turn: {name:<28} {micros:7.1f}")


if __name__ == "__main__":
    main()
