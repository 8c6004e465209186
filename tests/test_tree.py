"""SceneTree processing, process modes, the lockstep loop, deferred calls and PhysicsFramesTimer."""

from __future__ import annotations

import pytest

import rlenv.tree
from rlenv.node import Node, ProcessMode
from rlenv.timer import PhysicsFramesTimer
from rlenv.tree import SceneTree

INHERIT = ProcessMode.INHERIT
PAUSABLE = ProcessMode.PAUSABLE
WHEN_PAUSED = ProcessMode.WHEN_PAUSED
ALWAYS = ProcessMode.ALWAYS
DISABLED = ProcessMode.DISABLED


class Worker(Node):
    """Logs every _process, _physics_process and _physics_step call with its delta."""

    def __init__(self, name: str, log: list, **kwargs) -> None:
        super().__init__(name, **kwargs)
        self.log = log

    def _process(self, delta: float) -> None:
        self.log.append(("process", self.name, delta))

    def _physics_process(self, delta: float) -> None:
        self.log.append(("physics", self.name, delta))


class Stepper(Worker):
    def _physics_step(self, delta: float) -> None:
        self.log.append(("step", self.name, delta))


class FrameCounter(Node):
    def __init__(self, name: str = "Counter", **kwargs) -> None:
        super().__init__(name, **kwargs)
        self.frames = 0
        self.ticks = 0

    def _process(self, delta: float) -> None:
        self.frames += 1

    def _physics_process(self, delta: float) -> None:
        self.ticks += 1


def kinds(log: list, kind: str) -> list[str]:
    return [entry[1] for entry in log if entry[0] == kind]


# --- processing order ------------------------------------------------------------------------


def build_order_tree(tree: SceneTree, log: list, cls: type[Worker] = Worker) -> None:
    """root/{A/{B/{D}, C}, E}, added in an order different from tree order."""
    a, b, c, d, e = (cls(name, log) for name in "ABCDE")
    tree.root.add_child(a)
    a.add_child(b)
    tree.root.add_child(e)
    a.add_child(c)
    b.add_child(d)


def test_process_in_tree_order(tree: SceneTree, log: list) -> None:
    build_order_tree(tree, log)
    tree.process(0.25)
    assert log == [("process", name, 0.25) for name in "ABDCE"]
    assert tree.process_frames == 1
    assert tree.physics_frames == 0


def test_physics_process_in_tree_order_then_steps(tree: SceneTree, log: list) -> None:
    build_order_tree(tree, log, Stepper)
    tree.physics_tick()
    delta = 1 / 60
    assert log == [("physics", name, delta) for name in "ABDCE"] + [
        ("step", name, delta) for name in "ABDCE"
    ]
    assert tree.physics_frames == 1
    assert tree.process_frames == 0


def test_order_follows_move_child(tree: SceneTree, log: list) -> None:
    build_order_tree(tree, log)
    tree.process(0.0)
    log.clear()
    tree.root.move_child(tree.root.get_node("E"), 0)
    tree.process(0.0)
    assert kinds(log, "process") == list("EABDC")


def test_frame_signals_come_first(tree: SceneTree, log: list) -> None:
    tree.root.add_child(Stepper("S", log))
    tree.physics_frame.connect(lambda: log.append(("physics_frame",)))
    tree.process_frame.connect(lambda: log.append(("process_frame",)))
    tree.iteration()
    assert [entry[0] for entry in log] == [
        "physics_frame",
        "physics",
        "step",
        "process_frame",
        "process",
    ]


# --- process modes ---------------------------------------------------------------------------

MODE_TABLE = [
    # mode, processes when not paused, processes when paused
    (INHERIT, True, False),
    (PAUSABLE, True, False),
    (WHEN_PAUSED, False, True),
    (ALWAYS, True, True),
    (DISABLED, False, False),
]


@pytest.mark.parametrize(("mode", "running", "paused"), MODE_TABLE)
def test_process_modes(tree: SceneTree, log: list, mode, running: bool, paused: bool) -> None:
    node = Worker("W", log, process_mode=mode)
    tree.root.add_child(node)
    assert node.process_mode is mode
    tree.paused = False
    assert node.can_process() is running
    tree.process(0.1)
    tree.physics_tick()
    assert len(log) == (2 if running else 0)
    log.clear()
    tree.paused = True
    assert node.can_process() is paused
    tree.process(0.1)
    tree.physics_tick()
    assert len(log) == (2 if paused else 0)


@pytest.mark.parametrize(("mode", "running", "paused"), MODE_TABLE)
def test_inherit_resolves_through_ancestors(
    tree: SceneTree, log: list, mode, running: bool, paused: bool
) -> None:
    grandparent = Node("Grandparent", process_mode=mode)
    parent = Node("Parent")
    child = Worker("Child", log)
    parent.add_child(child)
    grandparent.add_child(parent)
    tree.root.add_child(grandparent)
    for is_paused, expected in ((False, running), (True, paused)):
        tree.paused = is_paused
        log.clear()
        assert child.can_process() is expected
        assert parent.can_process() is expected
        tree.process(0.0)
        assert kinds(log, "process") == (["Child"] if expected else [])


def test_root_resolves_to_pausable(tree: SceneTree) -> None:
    assert tree.root.process_mode is INHERIT
    assert tree.root.can_process()
    tree.paused = True
    assert not tree.root.can_process()


def test_changing_parent_mode_affects_inheriting_children(tree: SceneTree, log: list) -> None:
    parent = Node("Parent")
    inheriting = Worker("Inheriting", log)
    grandchild = Worker("Grandchild", log)
    fixed = Worker("Fixed", log, process_mode=PAUSABLE)
    below_fixed = Worker("BelowFixed", log)
    inheriting.add_child(grandchild)
    fixed.add_child(below_fixed)
    parent.add_child(inheriting)
    parent.add_child(fixed)
    tree.root.add_child(parent)
    tree.paused = True
    tree.process(0.0)
    assert log == []

    parent.process_mode = WHEN_PAUSED
    tree.process(0.0)
    assert kinds(log, "process") == ["Inheriting", "Grandchild"]
    assert not fixed.can_process() and not below_fixed.can_process()

    log.clear()
    parent.process_mode = ALWAYS
    tree.paused = False
    tree.process(0.0)
    assert kinds(log, "process") == ["Inheriting", "Grandchild", "Fixed", "BelowFixed"]

    log.clear()
    parent.process_mode = DISABLED
    tree.process(0.0)
    assert kinds(log, "process") == ["Fixed", "BelowFixed"]

    log.clear()
    fixed.process_mode = INHERIT  # now follows the disabled parent
    tree.process(0.0)
    assert log == []


def test_mode_resolved_when_entering_under_parent(tree: SceneTree, log: list) -> None:
    parent = Node("Parent", process_mode=WHEN_PAUSED)
    tree.root.add_child(parent)
    child = Worker("Child", log)
    parent.add_child(child)
    assert not child.can_process()
    tree.paused = True
    assert child.can_process()
    # moved under a pausable parent, it follows the new parent
    parent.remove_child(child)
    tree.root.add_child(child)
    assert not child.can_process()
    tree.paused = False
    assert child.can_process()


def test_can_process_is_false_outside_tree() -> None:
    assert not Node("Loose", process_mode=ALWAYS).can_process()


def test_process_mode_rejects_unknown_values() -> None:
    with pytest.raises(ValueError):
        Node("N", process_mode=7)
    node = Node("N")
    with pytest.raises(ValueError):
        node.process_mode = 9


# --- iteration -------------------------------------------------------------------------------


@pytest.mark.parametrize("ticks_per_second", [60, 50, 1])
def test_iteration_not_paused(log: list, ticks_per_second: int) -> None:
    tree = SceneTree(ticks_per_second)
    tree.root.add_child(Stepper("S", log))
    assert tree.physics_delta == 1 / ticks_per_second
    tree.iteration()
    tree.iteration()
    delta = 1 / ticks_per_second
    assert log == [("physics", "S", delta), ("step", "S", delta), ("process", "S", delta)] * 2
    assert tree.physics_frames == 2
    assert tree.process_frames == 2


def test_iteration_paused_runs_no_tick_and_zero_delta(tree: SceneTree, log: list) -> None:
    tree.root.add_child(Stepper("Always", log, process_mode=ALWAYS))
    tree.root.add_child(Stepper("Pausable", log))
    tree.paused = True
    tree.iteration()
    tree.iteration()
    assert log == [("process", "Always", 0.0)] * 2
    assert tree.physics_frames == 0
    assert tree.process_frames == 2
    tree.paused = False
    log.clear()
    tree.iteration()
    assert tree.physics_frames == 1
    assert kinds(log, "process") == ["Always", "Pausable"]
    assert [entry[2] for entry in log] == [1 / 60] * 6


def test_physics_tick_while_paused_runs_only_unpausable_nodes(tree: SceneTree, log: list) -> None:
    tree.root.add_child(Stepper("Always", log, process_mode=ALWAYS))
    tree.root.add_child(Stepper("Pausable", log))
    tree.root.add_child(Stepper("WhenPaused", log, process_mode=WHEN_PAUSED))
    tree.paused = True
    tree.physics_tick()
    assert [entry[:2] for entry in log] == [
        ("physics", "Always"),
        ("physics", "WhenPaused"),
        ("step", "Always"),
        ("step", "WhenPaused"),
    ]
    assert tree.physics_frames == 1


def test_ticks_per_second_must_be_positive() -> None:
    with pytest.raises(ValueError, match="at least 1"):
        SceneTree(0)


# --- set_process -----------------------------------------------------------------------------


def test_set_process_and_set_physics_process(tree: SceneTree, log: list) -> None:
    node = Worker("W", log)
    assert node.is_processing() and node.is_physics_processing()
    tree.root.add_child(node)
    node.set_process(False)
    assert not node.is_processing()
    tree.iteration()
    assert [entry[0] for entry in log] == ["physics"]
    node.set_physics_process(False)
    assert not node.is_physics_processing()
    tree.iteration()
    assert len(log) == 1
    node.set_process(True)
    node.set_physics_process(True)
    tree.iteration()
    assert [entry[0] for entry in log] == ["physics", "physics", "process"]


def test_set_process_before_entering_tree(tree: SceneTree, log: list) -> None:
    node = Worker("W", log)
    node.set_process(False)
    tree.root.add_child(node)
    tree.process(0.1)
    assert log == []


@pytest.mark.parametrize("physics", [False, True], ids=["process", "physics_process"])
def test_disabling_processing_during_pass_skips_later_node(
    tree: SceneTree, log: list, physics: bool
) -> None:
    class Disabler(Node):
        def _process(self, delta: float) -> None:
            self.get_node("../Later").set_process(False)

        def _physics_process(self, delta: float) -> None:
            self.get_node("../Later").set_physics_process(False)

    tree.root.add_child(Disabler("Disabler"))
    tree.root.add_child(Worker("Later", log))
    if physics:
        tree.physics_tick()
    else:
        tree.process(0.1)
    assert log == []


def test_process_mode_change_during_pass_applies_to_later_node(tree: SceneTree, log: list) -> None:
    class Disabler(Node):
        def _process(self, delta: float) -> None:
            self.get_node("../Later").process_mode = DISABLED

    tree.root.add_child(Disabler("Disabler"))
    tree.root.add_child(Worker("Later", log))
    tree.process(0.1)
    assert log == []


def test_nodes_not_overriding_virtuals_are_not_called(
    tree: SceneTree, monkeypatch: pytest.MonkeyPatch
) -> None:
    class OnlyPhysics(Node):
        def _physics_process(self, delta: float) -> None:
            pass

    class OnlyProcess(Node):
        def _process(self, delta: float) -> None:
            pass

    plain, only_physics, only_process = Node("Plain"), OnlyPhysics(), OnlyProcess()
    for node in (plain, only_physics, only_process):
        tree.root.add_child(node)
    assert not plain.is_processing() and not plain.is_physics_processing()
    assert not only_physics.is_processing() and only_physics.is_physics_processing()
    assert only_process.is_processing() and not only_process.is_physics_processing()

    called: list[tuple[str, str]] = []
    monkeypatch.setattr(Node, "_process", lambda self, delta: called.append(("p", self.name)))
    monkeypatch.setattr(
        Node, "_physics_process", lambda self, delta: called.append(("pp", self.name))
    )
    monkeypatch.setattr(Node, "_physics_step", lambda self, delta: called.append(("s", self.name)))
    tree.iteration()
    tree.iteration()
    assert called == []


@pytest.mark.parametrize("physics", [False, True], ids=["process", "physics_process"])
def test_enabling_processing_during_pass_applies_from_next_pass(
    tree: SceneTree, log: list, physics: bool
) -> None:
    class Enabler(Node):
        def _process(self, delta: float) -> None:
            self.get_node("../Later").set_process(True)

        def _physics_process(self, delta: float) -> None:
            self.get_node("../Later").set_physics_process(True)

    later = Worker("Later", log)
    later.set_process(False)
    later.set_physics_process(False)
    tree.root.add_child(Enabler("Enabler"))
    tree.root.add_child(later)
    run = tree.physics_tick if physics else lambda: tree.process(0.1)
    run()
    assert log == []
    run()
    assert kinds(log, "physics" if physics else "process") == ["Later"]


def test_process_mode_change_during_tick_skips_later_process_and_step(
    tree: SceneTree, log: list
) -> None:
    class Disabler(Node):
        def _physics_process(self, delta: float) -> None:
            self.get_node("../Later").process_mode = DISABLED

    tree.root.add_child(Stepper("Before", log))
    tree.root.add_child(Disabler("Disabler"))
    tree.root.add_child(Stepper("Later", log))
    tree.physics_tick()
    assert [entry[:2] for entry in log] == [("physics", "Before"), ("step", "Before")]


def test_process_mode_enabled_during_pass_applies_from_next_pass(
    tree: SceneTree, log: list
) -> None:
    class Enabler(Node):
        def _process(self, delta: float) -> None:
            self.get_node("../Later").process_mode = ALWAYS

    tree.root.add_child(Enabler("Enabler"))
    tree.root.add_child(Worker("Later", log, process_mode=DISABLED))
    tree.process(0.1)
    assert log == []
    tree.process(0.1)
    assert kinds(log, "process") == ["Later"]


def test_pausing_during_pass_applies_from_next_pass(tree: SceneTree, log: list) -> None:
    class Pauser(Node):
        def _process(self, delta: float) -> None:
            self.get_tree().paused = True

    tree.root.add_child(Pauser("Pauser", process_mode=ALWAYS))
    tree.root.add_child(Worker("Later", log))
    tree.process(0.1)
    assert kinds(log, "process") == ["Later"]
    tree.process(0.1)
    assert kinds(log, "process") == ["Later"]


def test_structure_changes_in_frame_signal_apply_to_that_pass(tree: SceneTree, log: list) -> None:
    leaving = Worker("Leaving", log)
    tree.root.add_child(leaving)
    tree.iteration()  # the plan includes Leaving
    log.clear()

    def swap() -> None:
        if leaving.is_inside_tree():
            tree.root.remove_child(leaving)
            tree.root.add_child(Worker("Arriving", log))

    tree.physics_frame.connect(swap)
    tree.physics_tick()
    assert kinds(log, "physics") == ["Arriving"]


def test_paused_is_a_bool(tree: SceneTree) -> None:
    assert tree.paused is False
    tree.paused = 1
    assert tree.paused is True
    tree.paused = []
    assert tree.paused is False


def test_pausing_reuses_the_plans(
    tree: SceneTree, log: list, monkeypatch: pytest.MonkeyPatch
) -> None:
    built: list[bool] = []

    class CountedPlan(rlenv.tree._TickPlan):
        def __init__(self, root: Node, paused: bool) -> None:
            built.append(paused)
            super().__init__(root, paused)

    monkeypatch.setattr(rlenv.tree, "_TickPlan", CountedPlan)
    node = Worker("W", log, process_mode=ALWAYS)
    tree.root.add_child(node)
    for _ in range(3):
        tree.paused = False
        tree.iteration()
        tree.paused = True
        tree.iteration()
    assert built == [False, True]
    node.set_process(True)  # unchanged: the plans stay valid
    node.process_mode = ALWAYS
    tree.iteration()
    assert built == [False, True]
    node.set_process(False)
    tree.iteration()
    tree.paused = False
    tree.iteration()
    assert built == [False, True, True, False]
    assert kinds(log, "process") == ["W"] * 7


def test_physics_ticks_per_second_can_change(tree: SceneTree, log: list) -> None:
    tree.root.add_child(Worker("W", log))
    tree.physics_ticks_per_second = 20
    assert tree.physics_delta == 1 / 20
    tree.iteration()
    assert [entry[2] for entry in log] == [1 / 20, 1 / 20]
    with pytest.raises(ValueError, match="at least 1"):
        tree.physics_ticks_per_second = 0
    assert tree.physics_ticks_per_second == 20


# --- on_physics_tick_end ---------------------------------------------------------------------


def test_tick_end_runs_after_steps_and_before_deferred_calls(tree: SceneTree, log: list) -> None:
    class Deferrer(Stepper):
        def _physics_process(self, delta: float) -> None:
            super()._physics_process(delta)
            self.call_deferred(log.append, ("deferred", self.name))

    tree.root.add_child(Deferrer("A", log))
    tree.root.add_child(Stepper("B", log))
    tree.on_physics_tick_end = lambda delta: log.append(("tick end", "tree", delta))
    tree.iteration()
    assert log == [
        ("physics", "A", 1 / 60),
        ("physics", "B", 1 / 60),
        ("step", "A", 1 / 60),
        ("step", "B", 1 / 60),
        ("tick end", "tree", 1 / 60),
        ("deferred", "A"),
        ("process", "A", 1 / 60),
        ("process", "B", 1 / 60),
    ]


def test_tick_end_runs_before_a_timeout(tree: SceneTree, log: list) -> None:
    timer = PhysicsFramesTimer(1)
    tree.root.add_child(timer)
    record_timeouts(tree, log, timer)
    tree.on_physics_tick_end = lambda delta: log.append(("tick end", tree.physics_frames))
    timer.start()
    tree.physics_tick()
    assert log == [("tick end", 1), ("timeout", 1)]


def test_tick_end_runs_on_every_tick_paused_or_not(tree: SceneTree, log: list) -> None:
    tree.on_physics_tick_end = log.append
    tree.paused = True
    tree.iteration()  # a paused lockstep iteration runs no tick
    assert log == []
    tree.physics_tick()
    tree.paused = False
    tree.iteration()
    assert log == [1 / 60, 1 / 60]
    tree.on_physics_tick_end = None
    tree.iteration()
    assert len(log) == 2


def test_structure_changes_in_tick_end_are_immediate(tree: SceneTree, log: list) -> None:
    old = Worker("Old", log)
    tree.root.add_child(old)
    seen: list[tuple[bool, bool]] = []

    def swap(delta: float) -> None:
        if old.is_inside_tree():
            tree.root.remove_child(old)
            new = Worker("New", log)
            tree.root.add_child(new)
            seen.append((old.is_inside_tree(), new.is_inside_tree()))

    tree.on_physics_tick_end = swap
    tree.iteration()
    assert seen == [(False, True)]
    assert kinds(log, "physics") == ["Old"]
    assert kinds(log, "process") == ["New"]


# --- deferred calls --------------------------------------------------------------------------


def test_call_deferred_fifo_with_args(tree: SceneTree, log: list) -> None:
    tree.call_deferred(log.append, 1)
    tree.call_deferred(lambda a, b: log.append((a, b)), 2, 3)
    tree.call_deferred(log.append, 4)
    assert log == []
    tree.flush_deferred()
    assert log == [1, (2, 3), 4]
    tree.flush_deferred()
    assert log == [1, (2, 3), 4]


def test_nested_deferred_calls_run_in_same_flush(tree: SceneTree, log: list) -> None:
    def outer(tag: str) -> None:
        log.append(tag)
        tree.call_deferred(log.append, f"{tag}-inner")

    tree.call_deferred(outer, "a")
    tree.call_deferred(outer, "b")
    tree.process(0.0)
    assert log == ["a", "b", "a-inner", "b-inner"]


def test_deferred_from_process_run_after_the_pass(tree: SceneTree, log: list) -> None:
    class Deferrer(Node):
        def _process(self, delta: float) -> None:
            log.append(("process", self.name))
            self.call_deferred(log.append, ("deferred", self.name))

    tree.root.add_child(Deferrer("A"))
    tree.root.add_child(Deferrer("B"))
    tree.process(0.0)
    assert log == [("process", "A"), ("process", "B"), ("deferred", "A"), ("deferred", "B")]


def test_deferred_from_physics_run_at_end_of_tick(tree: SceneTree, log: list) -> None:
    class Deferrer(Stepper):
        def _physics_process(self, delta: float) -> None:
            super()._physics_process(delta)
            self.call_deferred(log.append, ("deferred", self.name))

    tree.root.add_child(Deferrer("A", log))
    tree.physics_tick()
    assert [entry[:2] for entry in log] == [("physics", "A"), ("step", "A"), ("deferred", "A")]


def test_node_call_deferred_outside_tree_is_immediate(log: list) -> None:
    Node("Loose").call_deferred(log.append, "now")
    assert log == ["now"]


def test_endless_deferral_is_detected(tree: SceneTree, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(rlenv.tree, "_MAX_DEFERRED_PER_FLUSH", 100)

    def again() -> None:
        tree.call_deferred(again)

    tree.call_deferred(again)
    with pytest.raises(RuntimeError, match="keep deferring"):
        tree.flush_deferred()


# --- errors and quitting ---------------------------------------------------------------------


class Boom(Node):
    def __init__(self, name: str, where: str) -> None:
        super().__init__(name)
        self.where = where

    def _physics_process(self, delta: float) -> None:
        if self.where == "physics":
            raise ZeroDivisionError("kaboom")

    def _physics_step(self, delta: float) -> None:
        if self.where == "step":
            raise ZeroDivisionError("kaboom")

    def _process(self, delta: float) -> None:
        if self.where == "process":
            raise ZeroDivisionError("kaboom")


def test_exception_in_physics_process_names_the_node(tree: SceneTree, log: list) -> None:
    level = Node("Level")
    level.add_child(Worker("Before", log))
    level.add_child(Boom("Bomb", "physics"))
    level.add_child(Worker("After", log))
    tree.root.add_child(level)
    with pytest.raises(ZeroDivisionError, match="kaboom") as info:
        tree.physics_tick()
    notes = info.value.__notes__
    assert len(notes) == 1
    assert "/root/Level/Bomb" in notes[0]
    assert "physics tick" in notes[0]
    assert kinds(log, "physics") == ["Before"]
    # the tree is not left locked: structure changes are immediate again
    extra = Node("Extra")
    tree.root.add_child(extra)
    assert extra.is_inside_tree()


def test_exception_in_physics_step_names_the_node(tree: SceneTree) -> None:
    tree.root.add_child(Boom("Stepper", "step"))
    with pytest.raises(ZeroDivisionError) as info:
        tree.physics_tick()
    assert "/root/Stepper" in info.value.__notes__[0]


def test_exception_in_process_names_the_node(tree: SceneTree) -> None:
    tree.root.add_child(Node("Fine"))
    tree.root.add_child(Boom("Broken", "process"))
    with pytest.raises(ZeroDivisionError) as info:
        tree.process(0.1)
    assert "/root/Broken" in info.value.__notes__[0]
    assert "process frame" in info.value.__notes__[0]


def test_quit_makes_run_return(tree: SceneTree) -> None:
    class Quitter(FrameCounter):
        def _process(self, delta: float) -> None:
            super()._process(delta)
            if self.frames == 5:
                self.get_tree().quit()
            if self.frames > 50:
                raise AssertionError("quit() did not make run() return")

    quitter = Quitter()
    tree.root.add_child(quitter)
    tree.run()
    assert quitter.frames == 5 and quitter.ticks == 5
    assert tree.process_frames == 5 and tree.physics_frames == 5
    # run can be started again
    quitter.frames = 0
    tree.run()
    assert tree.process_frames == 10


# --- PhysicsFramesTimer ----------------------------------------------------------------------


def record_timeouts(tree: SceneTree, log: list, timer: PhysicsFramesTimer) -> None:
    """Log ``("timeout", physics_frames)`` on every timeout."""
    timer.timeout.connect(lambda: log.append(("timeout", tree.physics_frames)))


@pytest.mark.parametrize("frames", [1, 4, 7])
def test_timer_fires_after_exactly_n_ticks(tree: SceneTree, log: list, frames: int) -> None:
    timer = PhysicsFramesTimer(frames)
    tree.root.add_child(timer)
    record_timeouts(tree, log, timer)
    timer.start()
    for _ in range(frames - 1):
        tree.physics_tick()
    assert log == []
    assert not timer.is_stopped()
    tree.physics_tick()
    assert log == [("timeout", frames)]
    assert timer.is_stopped()
    for _ in range(2 * frames + 2):
        tree.physics_tick()
    assert log == [("timeout", frames)]


@pytest.mark.parametrize("frames", [1, 4, 7])
def test_timer_start_with_frames(tree: SceneTree, log: list, frames: int) -> None:
    timer = PhysicsFramesTimer()
    tree.root.add_child(timer)
    assert timer.start(frames) is timer
    assert timer.wait_frames == frames
    record_timeouts(tree, log, timer)
    for _ in range(10):
        tree.iteration()
    assert log == [("timeout", frames)]


def test_timer_fires_at_end_of_tick(tree: SceneTree, log: list) -> None:
    tree.root.add_child(Stepper("Before", log))
    timer = PhysicsFramesTimer(2)
    tree.root.add_child(timer)
    tree.root.add_child(Stepper("After", log))
    timer.timeout.connect(lambda: log.append(("timeout", tree.physics_frames)))
    timer.start()
    tree.physics_tick()
    log.clear()
    tree.physics_tick()
    assert [entry[:2] for entry in log] == [
        ("physics", "Before"),
        ("physics", "After"),
        ("step", "Before"),
        ("step", "After"),
        ("timeout", 2),
    ]


def test_timer_does_not_count_while_paused(tree: SceneTree, log: list) -> None:
    timer = PhysicsFramesTimer(3)
    tree.root.add_child(timer)
    record_timeouts(tree, log, timer)
    timer.start()
    tree.iteration()
    tree.paused = True
    for _ in range(5):
        tree.iteration()
        tree.physics_tick()  # even an explicit tick does not count for a pausable timer
    assert timer.frames_elapsed == 1
    assert timer.frames_left == 2
    assert log == []
    tree.paused = False
    tree.iteration()
    assert log == []
    tree.iteration()
    assert len(log) == 1
    assert timer.is_stopped()


def test_always_timer_counts_paused_ticks(tree: SceneTree, log: list) -> None:
    timer = PhysicsFramesTimer(2, process_mode=ALWAYS)
    tree.root.add_child(timer)
    record_timeouts(tree, log, timer)
    timer.start()
    tree.paused = True
    tree.physics_tick()
    tree.physics_tick()
    assert log == [("timeout", 2)]


def test_timer_inherits_disabled_parent(tree: SceneTree, log: list) -> None:
    parent = Node("Parent", process_mode=DISABLED)
    timer = PhysicsFramesTimer(1)
    parent.add_child(timer)
    tree.root.add_child(parent)
    record_timeouts(tree, log, timer)
    timer.start()
    for _ in range(3):
        tree.iteration()
    assert log == [] and timer.frames_elapsed == 0
    parent.process_mode = INHERIT
    tree.iteration()
    assert log == [("timeout", 4)]


@pytest.mark.parametrize("where", ["physics", "step"])
def test_stop_cancels_timeout_due_this_tick(tree: SceneTree, log: list, where: str) -> None:
    timer = PhysicsFramesTimer(3)

    class Stopper(Node):
        def _physics_process(self, delta: float) -> None:
            if where == "physics" and timer.frames_elapsed == 3:
                timer.stop()

        def _physics_step(self, delta: float) -> None:
            if where == "step" and timer.frames_elapsed == 3:
                timer.stop()

    tree.root.add_child(timer)
    tree.root.add_child(Stopper("Stopper"))  # after the timer in tree order
    record_timeouts(tree, log, timer)
    timer.start()
    for _ in range(10):
        tree.physics_tick()
    assert log == []
    assert timer.is_stopped()
    assert timer.frames_left == 0


def test_stop_before_due(tree: SceneTree, log: list) -> None:
    timer = PhysicsFramesTimer(3)
    tree.root.add_child(timer)
    record_timeouts(tree, log, timer)
    timer.start()
    tree.physics_tick()
    timer.stop()
    for _ in range(5):
        tree.physics_tick()
    assert log == []
    assert timer.frames_elapsed == 1


def test_repeating_timer(tree: SceneTree, log: list) -> None:
    timer = PhysicsFramesTimer(3, one_shot=False)
    tree.root.add_child(timer)
    record_timeouts(tree, log, timer)
    timer.start()
    for _ in range(10):
        tree.physics_tick()
    assert log == [("timeout", 3), ("timeout", 6), ("timeout", 9)]
    assert not timer.is_stopped()
    assert timer.frames_elapsed == 1
    assert timer.frames_left == 2
    timer.stop()
    for _ in range(5):
        tree.physics_tick()
    assert len(log) == 3


def test_restart_resets_count(tree: SceneTree, log: list) -> None:
    timer = PhysicsFramesTimer(3)
    tree.root.add_child(timer)
    record_timeouts(tree, log, timer)
    timer.start()
    tree.physics_tick()
    tree.physics_tick()
    timer.start()
    assert timer.frames_elapsed == 0
    tree.physics_tick()
    tree.physics_tick()
    assert log == []
    tree.physics_tick()
    assert log == [("timeout", 5)]


def test_restart_from_timeout_handler(tree: SceneTree, log: list) -> None:
    timer = PhysicsFramesTimer(2)
    tree.root.add_child(timer)
    record_timeouts(tree, log, timer)
    timer.timeout.connect(lambda: timer.start(3) if len(log) < 3 else None)
    timer.start()
    for _ in range(12):
        tree.physics_tick()
    assert log == [("timeout", 2), ("timeout", 5), ("timeout", 8)]


@pytest.mark.parametrize("frames", [0, -1, 2.0, True, None])
def test_timer_rejects_bad_frames(frames) -> None:
    timer = PhysicsFramesTimer(2)
    if frames is not None:
        with pytest.raises(ValueError, match="at least 1 physics frame"):
            timer.start(frames)
        assert timer.wait_frames == 2
        assert timer.is_stopped()
    with pytest.raises(ValueError):
        PhysicsFramesTimer(frames if frames is not None else 0)


def test_timer_frames_left_and_elapsed(tree: SceneTree) -> None:
    timer = PhysicsFramesTimer(5)
    tree.root.add_child(timer)
    assert timer.is_stopped()
    assert timer.frames_left == 0 and timer.frames_elapsed == 0
    tree.physics_tick()
    assert timer.frames_elapsed == 0  # not started: does not count
    timer.start()
    assert timer.frames_left == 5 and timer.frames_elapsed == 0
    tree.physics_tick()
    tree.physics_tick()
    assert timer.frames_left == 3 and timer.frames_elapsed == 2
    for _ in range(3):
        tree.physics_tick()
    assert timer.is_stopped()
    assert timer.frames_left == 0
    assert timer.frames_elapsed == 5
