"""PhysicsFramesTimer: a timer that counts physics ticks instead of seconds.

Lockstep simulation has no wall clock, so durations are counted in ticks. The timer counts the
ticks it processes in (a paused tree runs none) and emits ``timeout`` at the end of the tick that
completes the wait, after the physics spaces have stepped: whoever listens sees the state that
tick produced.
"""

from __future__ import annotations

from rlenv.node import Node, ProcessMode
from rlenv.signals import Signal

__all__ = ["PhysicsFramesTimer"]


class PhysicsFramesTimer(Node):
    """Fires ``timeout`` after ``wait_frames`` physics ticks (Godot's Timer, counting ticks).

    It counts only inside a tree, and only the ticks it processes in (see ``process_mode``).
    Starting it is explicit: call :meth:`start`::

        timer = PhysicsFramesTimer(30, name="Cooldown")   # half a second at 60 ticks/s
        self.add_child(timer)
        timer.start().timeout.connect(self.on_cooldown_over)

    Args:
        wait_frames: ticks to wait after :meth:`start` (at least 1).
        one_shot: stop after firing once; otherwise start over and fire every ``wait_frames``.
        name: the node name.
        process_mode: when the timer counts; by default it follows its parent.

    Attributes:
        wait_frames: ticks to wait; :meth:`start` may replace it.
        one_shot: whether it stops after firing once.

    Raises:
        ValueError: ``wait_frames`` is smaller than 1.
    """

    timeout = Signal()
    """``timeout()``: emitted at the end of the tick that completes the wait, as a deferred call
    (after the physics stepped), unless the timer was stopped or restarted in between."""

    def __init__(
        self,
        wait_frames: int = 1,
        *,
        one_shot: bool = True,
        name: str | None = None,
        process_mode: ProcessMode = ProcessMode.INHERIT,
    ) -> None:
        super().__init__(name, process_mode=process_mode)
        self.wait_frames = _check_frames(wait_frames)
        self.one_shot = one_shot
        self._elapsed = 0
        self._running = False
        self._generation = 0

    def start(self, frames: int | None = None) -> PhysicsFramesTimer:
        """Start (or restart) counting; ``frames`` replaces :attr:`wait_frames` when given.

        Returns:
            The timer, so that ``timer.start(4).timeout.connect(...)`` reads naturally.

        Raises:
            ValueError: ``frames`` is smaller than 1.
        """
        if frames is not None:
            if type(frames) is not int or frames < 1:
                _check_frames(frames)  # raises
            self.wait_frames = frames
        self._elapsed = 0
        self._running = True
        self._generation += 1
        return self

    def stop(self) -> None:
        """Stop counting; a timeout due at the end of this tick is cancelled."""
        self._running = False
        self._generation += 1

    def is_stopped(self) -> bool:
        """Whether the timer is not counting."""
        return not self._running

    @property
    def frames_elapsed(self) -> int:
        """Ticks counted since the last start (or the last firing, when repeating)."""
        return self._elapsed

    @property
    def frames_left(self) -> int:
        """Ticks still to count before the timer fires (0 when stopped)."""
        return self.wait_frames - self._elapsed if self._running else 0

    def _physics_process(self, delta: float) -> None:
        """Count the tick; the hot path is one test while stopped, a count and a test running."""
        if self._running:
            self._elapsed += 1
            if self._elapsed >= self.wait_frames:
                self._complete_wait()

    def _complete_wait(self) -> None:
        """Stop or start over, and fire at the end of the tick unless stopped or restarted.

        Nothing is deferred when nobody ever asked for the ``timeout`` signal (its first use,
        to connect to it, creates it).
        """
        if self.one_shot:
            self._running = False
        else:
            self._elapsed = 0
        if "timeout" in self._signals:
            self.call_deferred(self._fire, self._generation)

    def _fire(self, generation: int) -> None:
        """Emit ``timeout`` unless :meth:`start` or :meth:`stop` was called since it was due."""
        if generation == self._generation:
            self.timeout.emit()


def _check_frames(frames: int) -> int:
    if type(frames) is not int or frames < 1:
        raise ValueError(f"a timer waits at least 1 physics frame, got {frames!r}")
    return frames
