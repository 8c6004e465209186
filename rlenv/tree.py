"""SceneTree: the root node, groups, pause, deferred calls and the main loop.

The loop is **lockstep** by default: simulated time never depends on the wall clock. One
:meth:`SceneTree.iteration` runs, while the tree is not paused, one physics tick of fixed length
``1 / physics_ticks_per_second``:

1. ``physics_frame`` is emitted;
2. ``_physics_process(delta)`` runs on every node that can process, in tree order;
3. ``_physics_step(delta)`` runs on every simulating node (pymunk spaces step here);
4. deferred calls run;

and then one frame: ``process_frame`` is emitted, ``_process(delta)`` runs in tree order, and
deferred calls run. ``delta`` of a frame is the simulated time since the previous frame: one tick,
or 0 while paused. A paused tree runs no ticks, so its physics stands still; nodes that wait for
the outside world (an environment waiting for its client) block in their ``_process`` instead of
spinning.

In **real-time** mode (:attr:`SceneTree.real_time`) ticks follow a clock instead: an iteration
runs every tick that has come due since the last one (paused or not, as Godot does: pausable
nodes simply skip them), then one frame whose ``delta`` is the clock time elapsed. The clock is
injectable (``clock=``), so tests drive time by hand.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from typing import Any

from rlenv.node import Node
from rlenv.signals import Signal, SignalOwner

__all__ = ["SceneTree"]

_MAX_DEFERRED_PER_FLUSH = 1_000_000


class SceneTree(SignalOwner):
    """Owns the root node and runs the main loop.

    Args:
        physics_ticks_per_second: the fixed physics rate; one tick lasts its inverse.
    """

    physics_frame = Signal()
    """Emitted at the start of every physics tick."""
    process_frame = Signal()
    """Emitted at the start of every frame."""
    node_added = Signal("node")
    """Emitted when a node enters the tree."""
    node_removed = Signal("node")
    """Emitted when a node leaves the tree."""

    def __init__(
        self, physics_ticks_per_second: int = 60, *, clock: Callable[[], float] = time.monotonic
    ) -> None:
        if physics_ticks_per_second < 1:
            raise ValueError("physics_ticks_per_second must be at least 1")
        self._signals = {}
        self.physics_ticks_per_second = physics_ticks_per_second
        self.paused = False
        self.clock = clock
        self._real_time = False
        self._next_tick_at = 0.0
        self._last_frame_at = 0.0
        self.physics_frames = 0
        self.process_frames = 0
        self._locked = 0
        self._deferred: deque[tuple[Callable[..., Any], tuple[Any, ...]]] = deque()
        self._lists_stale = True
        self._physics_nodes: list[Node] = []
        self._step_nodes: list[Node] = []
        self._process_nodes: list[Node] = []
        self._quit_requested = False
        self.root = Node("root")
        self.root._propagate_enter_tree(self)
        self.root._propagate_ready()

    @property
    def physics_delta(self) -> float:
        """The fixed length of one physics tick, in simulated seconds."""
        return 1.0 / self.physics_ticks_per_second

    # --- deferred calls, groups -------------------------------------------------------------

    def call_deferred(self, callback: Callable[..., Any], *args: Any) -> None:
        """Call ``callback(*args)`` after the current pass, in the order deferred."""
        self._deferred.append((callback, args))

    def flush_deferred(self) -> None:
        """Run the deferred calls now, including those they defer in turn.

        Raises:
            RuntimeError: deferred calls keep deferring more, without end.
        """
        queue = self._deferred
        calls = 0
        while queue:
            callback, args = queue.popleft()
            callback(*args)
            calls += 1
            if calls > _MAX_DEFERRED_PER_FLUSH:
                raise RuntimeError("deferred calls keep deferring more calls; giving up")

    def get_nodes_in_group(self, group: str) -> list[Node]:
        """The nodes of the tree in ``group``, in tree order."""
        return [node for node in self.root.iter_subtree() if group in node._groups]

    def get_first_node_in_group(self, group: str) -> Node | None:
        """The first node in ``group`` in tree order, or ``None``."""
        return next((node for node in self.root.iter_subtree() if group in node._groups), None)

    def call_group(self, group: str, method: str, *args: Any) -> None:
        """Call ``method(*args)`` on every node in ``group``, in tree order."""
        for node in self.get_nodes_in_group(group):
            getattr(node, method)(*args)

    # --- the loop ---------------------------------------------------------------------------

    def physics_tick(self) -> None:
        """Run one physics tick (see the module docstring), paused or not."""
        if self._lists_stale:
            self._rebuild_lists()
        delta = 1.0 / self.physics_ticks_per_second
        self.physics_frames += 1
        self._emit("physics_frame")
        paused = self.paused
        self._locked += 1
        node = self.root
        try:
            for node in self._physics_nodes:
                if node._physics_processing and node._tree is not None \
                        and node._processes_when[paused]:
                    node._physics_process(delta)
            for node in self._step_nodes:
                if node._tree is not None and node._processes_when[paused]:
                    node._physics_step(delta)
        except Exception as error:
            error.add_note(f"raised in the physics tick of {node!r}")
            raise
        finally:
            self._locked -= 1
        self.flush_deferred()

    def process(self, delta: float) -> None:
        """Run one frame of ``_process(delta)`` calls, then the deferred calls."""
        if self._lists_stale:
            self._rebuild_lists()
        self.process_frames += 1
        self._emit("process_frame")
        paused = self.paused
        self._locked += 1
        node = self.root
        try:
            for node in self._process_nodes:
                if node._processing and node._tree is not None and node._processes_when[paused]:
                    node._process(delta)
        except Exception as error:
            error.add_note(f"raised in the process frame of {node!r}")
            raise
        finally:
            self._locked -= 1
        self.flush_deferred()

    @property
    def real_time(self) -> bool:
        """Whether ticks follow the clock (real time) instead of running on demand (lockstep)."""
        return self._real_time

    @real_time.setter
    def real_time(self, value: bool) -> None:
        if value and not self._real_time:
            self._next_tick_at = self._last_frame_at = self.clock()
        self._real_time = value

    def time_to_next_tick(self) -> float | None:
        """Seconds until the next tick is due in real time (``None`` in lockstep)."""
        if not self._real_time:
            return None
        return max(0.0, self._next_tick_at - self.clock())

    def iteration(self) -> None:
        """One turn of the loop.

        Lockstep: a physics tick unless paused, then a frame. Real time: every tick due by the
        clock, then a frame.
        """
        if self._real_time:
            now = self.clock()
            delta = 1.0 / self.physics_ticks_per_second
            while self._next_tick_at <= now:
                self.physics_tick()
                self._next_tick_at += delta
            self.process(now - self._last_frame_at)
            self._last_frame_at = now
        elif self.paused:
            self.process(0.0)
        else:
            self.physics_tick()
            self.process(1.0 / self.physics_ticks_per_second)

    def run(self, iteration: Callable[[], None] | None = None) -> None:
        """Iterate until :meth:`quit` is called.

        Args:
            iteration: what one turn of the loop runs; :meth:`iteration` by default.
        """
        turn = iteration or self.iteration
        self._quit_requested = False
        while not self._quit_requested:
            turn()

    def quit(self) -> None:
        """Make :meth:`run` return after the current iteration."""
        self._quit_requested = True

    # --- internals --------------------------------------------------------------------------

    def _structure_changed(self) -> None:
        self._lists_stale = True

    def _rebuild_lists(self) -> None:
        order = list(self.root.iter_subtree())
        self._physics_nodes = [n for n in order if n._physics_processing]
        self._step_nodes = [n for n in order if type(n)._physics_step is not Node._physics_step]
        self._process_nodes = [n for n in order if n._processing]
        self._lists_stale = False

