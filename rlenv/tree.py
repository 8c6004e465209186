"""SceneTree: the root node, groups, pause, deferred calls and the main loop.

The loop is **lockstep** by default: simulated time never depends on the wall clock. One
:meth:`SceneTree.iteration` runs, while the tree is not paused, one physics tick of fixed length
``1 / physics_ticks_per_second``:

1. ``physics_frame`` is emitted;
2. ``_physics_process(delta)`` runs on every node that can process, in tree order;
3. ``_physics_step(delta)`` runs on every simulating node (pymunk spaces step here);
4. :attr:`SceneTree.on_physics_tick_end` is called, when set;
5. deferred calls run;

and then one frame: ``process_frame`` is emitted, ``_process(delta)`` runs in tree order, and
deferred calls run. ``delta`` of a frame is the simulated time since the previous frame: one tick,
or 0 while paused. A paused tree runs no ticks, so its physics stands still; nodes that wait for
the outside world (an environment waiting for its client) block in their ``_process`` instead of
spinning.

In **real-time** mode (:attr:`SceneTree.real_time`) ticks follow a clock instead: an iteration
runs every tick that has come due since the last one (paused or not, as Godot does: pausable
nodes simply skip them), then one frame whose ``delta`` is the clock time elapsed. The clock is
injectable (``clock=``), so tests drive time by hand.

**The tick plan.** A pass checks nothing per node: the tree keeps, for each value of
:attr:`SceneTree.paused`, the lists of bound methods its passes call (``_physics_process``,
``_physics_step`` and ``_process`` of the nodes that can run in that state, in tree order), and a
pass just calls them. Whatever the plan depends on (adding, removing or moving a node,
``set_process``, ``set_physics_process``, a process mode) marks both plans stale, and the next pass
builds the one it needs; pausing and unpausing only switch plans. A change that stops a node
*during* a pass still applies to the rest of that pass: the node's remaining calls in the pass are
replaced by no-ops. A change that lets a node run takes effect from the next pass.
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

    A server builds one tree per environment instance, with the environment's
    ``physics_ticks_per_second``, and adds the environment below :attr:`root`; build one
    yourself to run nodes without a server (tests, tools).

    Args:
        physics_ticks_per_second: the fixed physics rate; one tick lasts its inverse, in
            simulated seconds.
        clock: the clock real-time mode follows: a callable returning seconds
            (``time.monotonic``; ``rlenv.testing.ManualClock`` in tests).

    Attributes:
        root: the root node, named ``root``: absolute paths start with ``/root/``.
        physics_frames: physics ticks run so far.
        process_frames: frames run so far.
        clock: the clock real-time mode follows.
    """

    physics_frame = Signal()
    """``physics_frame()``: emitted at the start of every physics tick."""
    process_frame = Signal()
    """``process_frame()``: emitted at the start of every frame."""
    node_added = Signal("node")
    """``node_added(node)``: ``node`` entered the tree."""
    node_removed = Signal("node")
    """``node_removed(node)``: ``node`` left the tree."""

    on_physics_tick_end: Callable[[float], None] | None = None
    """Called with the tick's ``delta`` at the end of every physics tick, when set.

    It runs after every ``_physics_step`` (so the physics spaces have stepped) and before the
    deferred calls of the tick, outside the processing pass: structure changes made in it are
    immediate. An environment reads the rewards of the tick here.
    """

    def __init__(
        self, physics_ticks_per_second: int = 60, *, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self._signals = {}
        self.physics_ticks_per_second = physics_ticks_per_second
        self._paused = False
        self.clock = clock
        self.on_physics_tick_end = None
        self._real_time = False
        self._next_tick_at = 0.0
        self._last_frame_at = 0.0
        self.physics_frames = 0
        self.process_frames = 0
        self._deferred: deque[tuple[Callable[..., Any], tuple[Any, ...]]] = deque()
        self._plans: list[_TickPlan | None] = [None, None]  # indexed by paused; None when stale
        self._plan: _TickPlan | None = None  # the plan for the current value of paused
        self._running: _TickPlan | None = None  # the plan of the pass under way
        self._quit_requested = False
        # Changes whenever a node is added, removed or moved (and when what runs changes): what
        # is derived from the tree's structure may be kept while it stays the same.
        self.structure_version = 0
        self.root = Node("root")
        self.root._propagate_enter_tree(self)
        self.root._propagate_ready()

    @property
    def physics_ticks_per_second(self) -> int:
        """The fixed physics rate, in ticks per simulated second (60 by default).

        Raises:
            ValueError: on setting a rate smaller than 1.
        """
        return self._physics_ticks_per_second

    @physics_ticks_per_second.setter
    def physics_ticks_per_second(self, value: int) -> None:
        if value < 1:
            raise ValueError("physics_ticks_per_second must be at least 1")
        self._physics_ticks_per_second = value
        self._physics_delta = 1.0 / value

    @property
    def physics_delta(self) -> float:
        """The fixed length of one physics tick, in simulated seconds."""
        return self._physics_delta

    @property
    def paused(self) -> bool:
        """Whether the tree is paused: pausable nodes do not process, and lockstep runs no ticks."""
        return self._paused

    @paused.setter
    def paused(self, value: bool) -> None:
        paused = bool(value)
        if paused is not self._paused:
            self._paused = paused
            self._plan = self._plans[paused]  # each value has its own plan: no rebuild

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
        delta = self._physics_delta
        self.physics_frames += 1
        if self._signals:
            self._emit("physics_frame")
        plan = self._plan or self._build_plan()
        outer, self._running = self._running, plan  # passes may nest
        try:
            for call in plan.physics:
                call(delta)
            for call in plan.steps:
                call(delta)
        except Exception as error:
            error.add_note(f"raised in the physics tick of {_owner(call)!r}")
            raise
        finally:
            self._running = outer
        if self.on_physics_tick_end is not None:
            self.on_physics_tick_end(delta)
        if self._deferred:
            self.flush_deferred()

    def process(self, delta: float) -> None:
        """Run one frame of ``_process(delta)`` calls, then the deferred calls."""
        self.process_frames += 1
        if self._signals:
            self._emit("process_frame")
        plan = self._plan or self._build_plan()
        outer, self._running = self._running, plan  # passes may nest
        try:
            for call in plan.process:
                call(delta)
        except Exception as error:
            error.add_note(f"raised in the process frame of {_owner(call)!r}")
            raise
        finally:
            self._running = outer
        if self._deferred:
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
            self._real_time_iteration()
        elif self._paused:
            self.process(0.0)
        else:
            self._lockstep_iteration()

    def iterate_until(self, done: Callable[[], bool]) -> None:
        """Turn the loop until ``done()`` says so (asked before each turn).

        The same as ``while not done(): tree.iteration()``, with one call less per turn in
        lockstep (an environment runs an action's ticks this way).
        """
        while not done():
            if self._real_time or self._paused:
                self.iteration()
                continue
            self.physics_tick()  # what _lockstep_iteration does, inlined on the hot path
            plan = self._plan
            if plan is None or plan.process or self._signals:
                self.process(self._physics_delta)
            else:
                self.process_frames += 1

    def _lockstep_iteration(self) -> None:
        """A physics tick, then a frame (only counted when it has nothing to call).

        The tick ran its deferred calls, so a frame has something to call only with ``_process``
        calls in the plan or a signal connected.
        """
        self.physics_tick()
        plan = self._plan
        if plan is None or plan.process or self._signals:
            self.process(self._physics_delta)
        else:
            self.process_frames += 1

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

    def _real_time_iteration(self) -> None:
        """Every tick due by the clock, then a frame of the clock time elapsed."""
        now = self.clock()
        while self._next_tick_at <= now:
            self.physics_tick()
            self._next_tick_at += self._physics_delta
        self.process(now - self._last_frame_at)
        self._last_frame_at = now

    def _plan_changed(self) -> None:
        """Mark the plans stale; nodes that can no longer run skip the rest of the pass."""
        self.structure_version += 1
        self._plans = [None, None]
        self._plan = None
        if self._running is not None:
            self._running.skip_stopped()

    def _build_plan(self) -> _TickPlan:
        """Build and keep the plan for the current value of :attr:`paused`."""
        plan = self._plans[self._paused] = self._plan = _TickPlan(self.root, self._paused)
        return plan


class _TickPlan:
    """What the passes call while the tree's ``paused`` is ``paused``: bound methods, in tree order.

    Args:
        root: the root of the tree.
        paused: the value of ``paused`` the plan is for.

    Attributes:
        physics: ``_physics_process`` of the nodes that physics-process and can run.
        steps: ``_physics_step`` of the simulating nodes that can run.
        process: ``_process`` of the nodes that process and can run.
    """

    __slots__ = (
        "_physics_nodes",
        "_process_nodes",
        "_step_nodes",
        "paused",
        "physics",
        "process",
        "steps",
    )

    def __init__(self, root: Node, paused: bool) -> None:
        order = [node for node in root.iter_subtree() if node._processes_when[paused]]
        self.paused = paused
        self._physics_nodes = [node for node in order if node._physics_processing]
        self._step_nodes = [node for node in order if _simulates(node)]
        self._process_nodes = [node for node in order if node._processing]
        self.physics: list[Callable[[float], None]] = [
            node._physics_process for node in self._physics_nodes
        ]
        self.steps: list[Callable[[float], None]] = [
            node._physics_step for node in self._step_nodes
        ]
        self.process: list[Callable[[float], None]] = [
            node._process for node in self._process_nodes
        ]

    def skip_stopped(self) -> None:
        """Turn into no-ops the calls of nodes that can no longer run (a change mid-pass)."""
        paused = self.paused
        _skip_unless(
            self.physics,
            self._physics_nodes,
            lambda node: node._physics_processing and node._processes_when[paused],
        )
        _skip_unless(self.steps, self._step_nodes, lambda node: node._processes_when[paused])
        _skip_unless(
            self.process,
            self._process_nodes,
            lambda node: node._processing and node._processes_when[paused],
        )


def _skip_unless(
    calls: list[Callable[[float], None]], nodes: list[Node], can_run: Callable[[Node], bool]
) -> None:
    """Replace by a no-op each call whose node (``nodes``, index for index) cannot run."""
    for index, node in enumerate(nodes):
        if not can_run(node):
            calls[index] = _skipped


def _simulates(node: Node) -> bool:
    """Whether ``node`` overrides ``_physics_step``."""
    return type(node)._physics_step is not Node._physics_step


def _skipped(delta: float) -> None:
    """Stands in for the call of a node that was stopped during the pass."""


def _owner(call: Callable[[float], None]) -> object:
    """The node a planned call belongs to (the bound method's ``__self__``)."""
    return getattr(call, "__self__", call)
