"""step_space: the same step as pymunk's ``Space.step``, bit for bit, whatever is pending."""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

import pymunk
import pytest

from rlenv.scene2d.physics import step_space

Step = Callable[[pymunk.Space, float], None]
DELTA = 1.0 / 60.0


def pymunk_step(space: pymunk.Space, delta: float) -> None:
    space.step(delta)


class Pile:
    """Balls dropped on a floor and on each other, with collision handlers that change the space.

    Every ball hitting the floor for the first time is removed by its ``begin`` handler (a
    removal deferred to the end of the step) and replaced by a new ball dropped from above (an
    add deferred the same way, and a body pymunk then checks before the next step); one ball a
    step, as pymunk adds what was deferred in the order of a set (of objects hashed by
    address). Every ``separate`` registers a post-step callback. The log records what each
    handler saw, and when; in each step, in no particular order (Chipmunk meets the contacts
    that ended in the order of a hash set of pointers).
    """

    FLOOR, BALL = 1, 2

    def __init__(self, handlers: bool) -> None:
        self.space = space = pymunk.Space()
        space.gravity = (0.0, -9.81)
        space.iterations = 10
        floor = pymunk.Segment(space.static_body, (-5.0, 0.0), (5.0, 0.0), 0.1)
        floor.collision_type = self.FLOOR
        floor.friction = 0.7
        space.add(floor)
        self.log: list[Any] = []
        self.dropped = 0
        self.ticks = 0  # steps run (the caller counts them)
        self._replaced_at = -1
        for index in range(12):
            self.drop(-2.0 + 0.37 * index, 1.0 + 0.6 * index)
        if handlers:
            space.on_collision(self.FLOOR, self.BALL, begin=self.replace)
            space.on_collision(self.BALL, self.BALL, separate=self.later)

    def drop(self, x: float, y: float) -> None:
        body = pymunk.Body(1.0, pymunk.moment_for_circle(1.0, 0.0, 0.2))
        body.position = (x, y)
        body.angular_velocity = 0.1 * self.dropped
        shape = pymunk.Circle(body, 0.2)
        shape.collision_type = self.BALL
        shape.friction = 0.5
        shape.elasticity = 0.3
        self.dropped += 1
        self.space.add(body, shape)

    def replace(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        ball = arbiter.shapes[1]
        self.log.append((self.ticks, "begin", _bits(ball.body.position)))
        if self.dropped < 30 and self._replaced_at != self.ticks:
            self._replaced_at = self.ticks
            space.remove(ball, ball.body)
            self.drop(ball.body.position.x * 0.5, 4.0)

    def later(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        first, second = arbiter.shapes
        self.log.append((self.ticks, "separate", _where(first), _where(second)))
        space.add_post_step_callback(self.after, first, second)

    def after(self, space: pymunk.Space, key: pymunk.Shape, other: pymunk.Shape) -> None:
        self.log.append((self.ticks, "after", _where(key), _where(other), len(space.bodies)))

    def state(self) -> list[Any]:
        """Every body's pose and velocities, bit for bit, in the space's order; the log."""
        return [
            [
                _bits((*body.position, *body.velocity, body.angle, body.angular_velocity))
                for body in self.space.bodies
            ],
            len(self.space.shapes),
            sorted(self.log, key=repr),
        ]


def _where(shape: pymunk.Shape) -> bytes | None:
    """Where the shape's body is, bit for bit (``None`` for a shape that left the space)."""
    return None if shape.body is None else _bits(shape.body.position)


def _bits(values: Any) -> bytes:
    return struct.pack(f"{len(values)}d", *values)


def run(step: Step, handlers: bool, ticks: int = 240) -> Pile:
    pile = Pile(handlers)
    for _ in range(ticks):
        step(pile.space, DELTA)
        pile.ticks += 1
    return pile


@pytest.mark.parametrize("handlers", [False, True])
def test_step_space_is_space_step_bit_for_bit(handlers: bool) -> None:
    ours, theirs = run(step_space, handlers), run(pymunk_step, handlers)
    assert ours.state() == theirs.state()
    assert run(step_space, handlers, 239).state() != ours.state()  # the pile moves to the end


def test_handlers_that_change_the_space_take_effect_as_with_space_step() -> None:
    pile = run(step_space, True)
    kinds = {entry[1] for entry in pile.log}
    assert kinds == {"begin", "separate", "after"}  # every kind of deferred work was met
    assert pile.dropped == 30  # the begin handlers removed balls and dropped new ones
    assert len(pile.space.bodies) == 12 and len(pile.space.shapes) == 13
    assert not pile.space._add_later and not pile.space._remove_later
    assert not pile.space._post_step_callbacks


def test_step_space_adds_and_removes_during_the_step_like_space_step() -> None:
    """An add and a removal asked for from a callback wait for the end of the step."""
    seen: list[tuple[int, int]] = []
    for step in (step_space, pymunk_step):
        pile = Pile(False)
        space = pile.space
        for _ in range(30):
            step(space, DELTA)  # the bodies are checked, the next steps have nothing pending
        body = pymunk.Body(1.0, 1.0)
        shape = pymunk.Circle(body, 0.1)

        def add_and_remove(
            arbiter: pymunk.Arbiter,
            space: pymunk.Space,
            data: Any,
            body: pymunk.Body = body,
            shape: pymunk.Circle = shape,
        ) -> None:
            if body.space is None and shape not in space._add_later:
                space.add(body, shape)
                space.remove(arbiter.shapes[1])
                seen.append((len(space.bodies), len(space.shapes)))

        space.on_collision(Pile.FLOOR, Pile.BALL, pre_solve=add_and_remove)
        for _ in range(200):
            step(space, DELTA)
        seen.append((len(space.bodies), len(space.shapes)))
    assert seen[: len(seen) // 2] == seen[len(seen) // 2 :]
    assert seen[-1] == (13, 13)  # the new body in, one ball's shape out


def test_a_body_added_between_steps_is_checked_as_space_step_checks_it() -> None:
    space = pymunk.Space()
    step_space(space, DELTA)
    body = pymunk.Body()  # dynamic, and no mass: pymunk refuses it at the next step
    space.add(body, pymunk.Circle(body, 0.1))
    with pytest.raises(AssertionError, match="Dynamic bodies must have a mass"):
        step_space(space, DELTA)
    assert not space._locked
