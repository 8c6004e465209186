"""pymunk's ``pymunk.batch`` against per-body access, for the bodies of a swarm.

``python benchmarks/pymunk_batch.py [--rounds R] [--calls C]`` builds a space of N discs (16,
64, 256) and times, rounds in turns after a warm-up round each, three ways of doing what a
swarm's group does every physics tick:

- **read**: every body's position and velocity into one ``(N, 4)`` float64 array;
- **force**: one force per body from an ``(N, 2)`` array;
- **velocity**: one velocity per body from an ``(N, 2)`` array.

The three ways: pymunk's public properties (``body.position``, ``body.force = ...``);
Chipmunk's accessors called straight on each body (``rlenv.scene2d._chipmunk``, what rlenv's
bodies use); ``pymunk.batch`` (``get_space_bodies`` / ``set_space_bodies`` with ``Buffer``s
kept between calls, one for reads and one on an array for writes, and ``BODY_ID`` to find each
body's row: batch calls visit every body of the space, the walls' static body included, in
Chipmunk's order, which a body's removal changes). Prints microseconds per call (min and median
of the rounds) and each way's ratio to the properties.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np
import pymunk
import pymunk.batch

from rlenv.scene2d import _chipmunk

SIZES = (16, 64, 256)
_READ = pymunk.batch.BodyFields.BODY_ID | pymunk.batch.BodyFields.POSITION
_READ |= pymunk.batch.BodyFields.VELOCITY


def space_of(count: int) -> tuple[pymunk.Space, list[pymunk.Body]]:
    """A space of ``count`` discs on a grid, and a static body with four walls."""
    space = pymunk.Space()
    walls = pymunk.Body(body_type=pymunk.Body.STATIC)
    side = int(np.ceil(np.sqrt(count)))
    half = side * 0.5
    corners = [(-half, -half), (half, -half), (half, half), (-half, half)]
    space.add(
        walls,
        *(
            pymunk.Segment(walls, a, b, 0.05)
            for a, b in zip(corners, corners[1:] + corners[:1], strict=True)
        ),
    )
    bodies = []
    for index in range(count):
        body = pymunk.Body(1.0, pymunk.moment_for_circle(1.0, 0, 0.2))
        body.position = (index % side - half + 0.5, index // side - half + 0.5)
        space.add(body, pymunk.Circle(body, 0.2))
        bodies.append(body)
    return space, bodies


class Ways:
    """The three ways of one job on one space: ``properties``, ``accessors``, ``batch``."""

    def __init__(self, count: int) -> None:
        self.space, self.bodies = space_of(count)
        self.handles = [_chipmunk.handle(body) for body in self.bodies]
        self.values = np.random.default_rng(0).uniform(-1, 1, (count, 2))
        self.out = np.zeros((count, 4))
        self.buffer = pymunk.batch.Buffer()
        # batch rows: every body of the space; ours found by id (the walls' row stays zero)
        pymunk.batch.get_space_bodies(self.space, pymunk.batch.BodyFields.BODY_ID, self.buffer)
        ids = np.frombuffer(self.buffer.int_buf(), np.uintp).copy()
        slot_of = {body.id: slot for slot, body in enumerate(self.bodies)}
        self.rows = np.array([slot_of.get(int(each), -1) for each in ids])
        self.ours = self.rows >= 0
        self.written = np.zeros((len(ids), 2))
        # a second buffer for writes: pymunk grows a read's buffer, never one on our memory
        self.setter = pymunk.batch.Buffer()
        self.setter.set_float_buf(self.written)

    # read: positions and velocities into self.out
    def read_properties(self) -> None:
        self.out[:] = [(*body.position, *body.velocity) for body in self.bodies]

    def read_accessors(self) -> None:
        position_of, velocity_of = _chipmunk.position_of, _chipmunk.velocity_of
        rows = []
        for handle in self.handles:
            position, velocity = position_of(handle), velocity_of(handle)
            rows.append((position.x, position.y, velocity.x, velocity.y))
        self.out[:] = rows

    def read_batch(self) -> None:
        self.buffer.clear()
        pymunk.batch.get_space_bodies(self.space, _READ, self.buffer)
        ids = np.frombuffer(self.buffer.int_buf(), np.uintp)
        values = np.frombuffer(self.buffer.float_buf(), np.float64).reshape(len(ids), 4)
        self.out[self.rows[self.ours]] = values[self.ours]

    # force (and velocity): one row of self.values per body
    def force_properties(self) -> None:
        for body, (x, y) in zip(self.bodies, self.values.tolist(), strict=True):
            body.force = (x, y)

    def force_accessors(self) -> None:
        set_force = _chipmunk.lib.cpBodySetForce
        for handle, value in zip(self.handles, self.values.tolist(), strict=True):
            set_force(handle, value)

    def force_batch(self) -> None:
        self._set_batch(pymunk.batch.BodyFields.FORCE)

    def velocity_properties(self) -> None:
        for body, (x, y) in zip(self.bodies, self.values.tolist(), strict=True):
            body.velocity = (x, y)

    def velocity_accessors(self) -> None:
        set_velocity = _chipmunk.set_velocity_of
        for handle, value in zip(self.handles, self.values.tolist(), strict=True):
            set_velocity(handle, value)

    def velocity_batch(self) -> None:
        self._set_batch(pymunk.batch.BodyFields.VELOCITY)

    def _set_batch(self, field: pymunk.batch.BodyFields) -> None:
        self.written[self.ours] = self.values[self.rows[self.ours]]
        pymunk.batch.set_space_bodies(self.space, field, self.setter)


def timed(call: Callable[[], None], calls: int) -> float:
    """Microseconds per call over ``calls`` calls."""
    start = time.perf_counter()
    for _ in range(calls):
        call()
    return (time.perf_counter() - start) / calls * 1e6


def main() -> None:
    """Measure and print every size, job and way."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--calls", type=int, default=2000)
    args = parser.parse_args()
    for count in SIZES:
        ways = Ways(count)
        for job in ("read", "force", "velocity"):
            calls = {
                way: getattr(ways, f"{job}_{way}") for way in ("properties", "accessors", "batch")
            }
            check = _check(ways, job, calls)
            times: dict[str, list[float]] = {way: [] for way in calls}
            for call in calls.values():
                timed(call, args.calls // 4)  # warm-up
            for _ in range(args.rounds):
                for way, call in calls.items():
                    times[way].append(timed(call, max(args.calls * 16 // count, 50)))
            base = statistics.median(times["properties"])
            print(
                f"N={count:<4} {job:<8} "
                + ", ".join(
                    f"{way} {min(each):.1f}/{statistics.median(each):.1f} us "
                    f"({base / statistics.median(each):.1f}x)"
                    for way, each in times.items()
                )
                + check,
                flush=True,
            )


def _check(ways: Ways, job: str, calls: dict[str, Callable[[], None]]) -> str:
    """Run each way once and check they agree (read: the same array; writes: the same bodies)."""
    results = []
    for call in calls.values():
        if job == "read":
            call()
            results.append(ways.out.copy())
        else:
            call()
            field = "force" if job == "force" else "velocity"
            results.append(np.array([tuple(getattr(body, field)) for body in ways.bodies]))
    agree = all(np.array_equal(results[0], other) for other in results[1:])
    return "" if agree else "  (the ways DISAGREE)"


if __name__ == "__main__":
    main()
