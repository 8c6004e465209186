"""Node structure, lookup, groups, signals, lifecycle order, queue_free and deferred mutation."""

from __future__ import annotations

import pytest

from rlenv.node import (
    NOTIFICATION_ENTER_TREE,
    NOTIFICATION_EXIT_TREE,
    NOTIFICATION_PARENTED,
    NOTIFICATION_PREDELETE,
    NOTIFICATION_READY,
    NOTIFICATION_UNPARENTED,
    Node,
    NodeNotFoundError,
)
from rlenv.signals import BoundSignal, Signal
from rlenv.tree import SceneTree

NOTE_NAMES = {
    NOTIFICATION_ENTER_TREE: "ENTER_TREE",
    NOTIFICATION_EXIT_TREE: "EXIT_TREE",
    NOTIFICATION_READY: "READY",
    NOTIFICATION_PARENTED: "PARENTED",
    NOTIFICATION_UNPARENTED: "UNPARENTED",
    NOTIFICATION_PREDELETE: "PREDELETE",
}


# --- helpers ---------------------------------------------------------------------------------


class Rec(Node):
    """Records its lifecycle virtuals into a shared list."""

    def __init__(self, name: str, log: list, **kwargs) -> None:
        super().__init__(name, **kwargs)
        self.log = log

    def _enter_tree(self) -> None:
        self.log.append(("enter", self.name))

    def _ready(self) -> None:
        self.log.append(("ready", self.name))

    def _exit_tree(self) -> None:
        self.log.append(("exit", self.name))


class NoteRec(Rec):
    """Also records every notification, after the matching virtual."""

    def _notification(self, what: int) -> None:
        self.log.append(("note", self.name, NOTE_NAMES.get(what, what)))


class Enemy(Node):
    pass


class Boss(Enemy):
    pass


class Emitter(Node):
    fired = Signal("a", "b")
    pinged = Signal()


def names(nodes) -> list[str]:
    return [n.name for n in nodes]


@pytest.fixture
def scene(tree: SceneTree) -> dict[str, Node]:
    """root/Level/{Player/{Sprite, Gun}, Enemies/{Goblin, Orc, BigBoss}}."""
    level = Node("Level")
    player = Node("Player")
    sprite = Node("Sprite")
    gun = Node("Gun")
    enemies = Node("Enemies")
    goblin = Enemy("Goblin")
    orc = Enemy("Orc")
    boss = Boss("BigBoss")
    player.add_child(sprite)
    player.add_child(gun)
    enemies.add_child(goblin)
    enemies.add_child(orc)
    enemies.add_child(boss)
    level.add_child(player)
    level.add_child(enemies)
    tree.root.add_child(level)
    return {n.name: n for n in (level, player, sprite, gun, enemies, goblin, orc, boss)}


# --- structure -------------------------------------------------------------------------------


def test_add_child_appends_in_order_and_sets_parent() -> None:
    parent = Node("P")
    a, b, c = Node("A"), Node("B"), Node("C")
    for child in (a, b, c):
        parent.add_child(child)
    assert parent.get_children() == [a, b, c]
    assert parent.get_child_count() == 3
    assert parent.get_child(0) is a
    assert parent.get_child(-1) is c
    assert [child.get_index() for child in (a, b, c)] == [0, 1, 2]
    assert a.parent is parent and a.get_parent() is parent
    assert parent.is_ancestor_of(a) and not a.is_ancestor_of(parent)
    # get_children returns a copy
    parent.get_children().clear()
    assert parent.get_child_count() == 3


def test_default_name_is_class_name() -> None:
    assert Node().name == "Node"
    assert Enemy().name == "Enemy"


def test_remove_child_detaches_and_keeps_order() -> None:
    parent = Node("P")
    a, b, c = Node("A"), Node("B"), Node("C")
    for child in (a, b, c):
        parent.add_child(child)
    parent.remove_child(b)
    assert parent.get_children() == [a, c]
    assert b.parent is None
    assert not parent.has_node("B")
    with pytest.raises(RuntimeError, match="has no parent"):
        b.get_index()
    # the name is free again
    parent.add_child(Node("B"))
    assert names(parent.get_children()) == ["A", "C", "B"]


def test_remove_child_of_other_node_rejected() -> None:
    parent, other = Node("P"), Node("Other")
    child = Node("Kid")
    other.add_child(child)
    with pytest.raises(ValueError, match="'Kid' is not a child of 'P'"):
        parent.remove_child(child)
    assert child.parent is other


def test_sibling_names_made_unique() -> None:
    parent = Node("P")
    nodes = [Node("Name") for _ in range(3)]
    for node in nodes:
        parent.add_child(node)
    assert names(nodes) == ["Name", "Name2", "Name3"]
    assert [parent.get_node(n) for n in ("Name", "Name2", "Name3")] == nodes
    # a name ending in a number continues from it
    extra = Node("Name2")
    parent.add_child(extra)
    assert extra.name == "Name4"
    # names are only unique among siblings
    other = Node("Other")
    other.add_child(Node("Name"))
    assert other.get_child(0).name == "Name"


def test_rename_via_setter(log: list) -> None:
    parent = Node("P")
    a, b = Node("A"), Node("B")
    parent.add_child(a)
    parent.add_child(b)
    a.renamed.connect(lambda: log.append(a.name))
    a.name = "Alpha"
    assert a.name == "Alpha"
    assert parent.get_node("Alpha") is a
    assert not parent.has_node("A")
    assert log == ["Alpha"]
    # renaming onto a sibling's name makes it unique
    a.name = "B"
    assert a.name == "B2"
    assert parent.get_node("B") is b and parent.get_node("B2") is a
    assert log == ["Alpha", "B2"]
    # renaming to the same name is a no-op without a signal
    a.name = "B2"
    assert log == ["Alpha", "B2"]
    # a detached node can take any valid name
    loose = Node("Loose")
    loose.name = "B"
    assert loose.name == "B"


@pytest.mark.parametrize(
    "bad", ["", ".", "..", "a/b", "a:b", "a@b", "a%b", "a.b", 'a"b', "/root", 42]
)
def test_invalid_names_rejected(bad) -> None:
    with pytest.raises(ValueError):
        Node(bad)
    node = Node("Good")
    with pytest.raises(ValueError):
        node.name = bad
    assert node.name == "Good"


def test_invalid_name_message_names_the_character() -> None:
    with pytest.raises(ValueError, match="contains '/'"):
        Node("a/b")


def test_add_child_that_already_has_parent_rejected() -> None:
    first, second = Node("First"), Node("Second")
    child = Node("Kid")
    first.add_child(child)
    with pytest.raises(ValueError, match="already a child of 'First'") as info:
        second.add_child(child)
    assert "remove it from there first" in str(info.value)
    assert child.parent is first
    assert second.get_child_count() == 0
    # adding it again to the same parent is rejected too
    with pytest.raises(ValueError, match="already a child"):
        first.add_child(child)
    assert first.get_children() == [child]


def test_add_node_under_itself_rejected() -> None:
    a, b, c = Node("A"), Node("B"), Node("C")
    a.add_child(b)
    b.add_child(c)
    with pytest.raises(ValueError, match="cannot add 'A' under itself"):
        c.add_child(a)
    with pytest.raises(ValueError, match="under itself"):
        a.add_child(a)
    assert a.parent is None
    assert c.get_child_count() == 0


def test_move_child(tree: SceneTree) -> None:
    a, b, c = Node("A"), Node("B"), Node("C")
    for child in (a, b, c):
        tree.root.add_child(child)
    tree.root.move_child(c, 0)
    assert tree.root.get_children() == [c, a, b]
    tree.root.move_child(c, -1)
    assert tree.root.get_children() == [a, b, c]


# --- paths and lookup ------------------------------------------------------------------------


def test_get_node_relative(scene: dict[str, Node]) -> None:
    level = scene["Level"]
    assert level.get_node("Player") is scene["Player"]
    assert level.get_node("Player/Gun") is scene["Gun"]
    assert level.get_node("Enemies/Orc") is scene["Orc"]


def test_get_node_dot_and_dotdot(scene: dict[str, Node], tree: SceneTree) -> None:
    gun = scene["Gun"]
    assert gun.get_node(".") is gun
    assert gun.get_node("..") is scene["Player"]
    assert gun.get_node("../Sprite") is scene["Sprite"]
    assert gun.get_node("../../Enemies/Orc") is scene["Orc"]
    assert gun.get_node("../..") is scene["Level"]
    assert gun.get_node("../../..") is tree.root
    assert scene["Player"].get_node("./Sprite") is scene["Sprite"]


def test_get_node_absolute(scene: dict[str, Node], tree: SceneTree) -> None:
    gun = scene["Gun"]
    assert gun.get_node("/root") is tree.root
    assert gun.get_node("/root/Level/Enemies/Goblin") is scene["Goblin"]
    assert tree.root.get_node("/root/Level/Player/Gun") is gun


def test_get_node_works_on_detached_subtree() -> None:
    top, mid, leaf = Node("Top"), Node("Mid"), Node("Leaf")
    top.add_child(mid)
    mid.add_child(leaf)
    assert top.get_node("Mid/Leaf") is leaf
    assert leaf.get_node("../..") is top
    # an absolute path needs a tree
    assert top.get_node_or_null("/root/Top") is None


@pytest.mark.parametrize(
    "path",
    [
        "",
        "Nope",
        "Player/Nope",
        "Player/Gun/Deeper",
        "/root/Nope",
        "/notroot/Level",
        "/",
        "../../../..",
    ],
)
def test_get_node_or_null_and_has_node_for_missing(scene: dict[str, Node], path: str) -> None:
    level = scene["Level"]
    assert level.get_node_or_null(path) is None
    assert not level.has_node(path)
    with pytest.raises(NodeNotFoundError):
        level.get_node(path)


def test_has_node_for_existing(scene: dict[str, Node]) -> None:
    assert scene["Level"].has_node("Player/Sprite")
    assert scene["Orc"].has_node("../Goblin")
    assert scene["Orc"].has_node("/root/Level")


def test_node_not_found_error_message(scene: dict[str, Node]) -> None:
    with pytest.raises(NodeNotFoundError) as info:
        scene["Level"].get_node("Player/Missile")
    assert isinstance(info.value, LookupError)
    message = str(info.value)
    assert "'Player/Missile'" in message
    assert "/root/Level" in message
    loose = Node("Loose")
    with pytest.raises(NodeNotFoundError, match="'Loose'"):
        loose.get_node("Child")


def test_node_not_found_error_says_where_the_walk_stopped(scene: dict[str, Node]) -> None:
    with pytest.raises(NodeNotFoundError) as info:
        scene["Level"].get_node("Player/Missile/Warhead")
    # the walk reached /root/Level/Player and found no child 'Missile'
    assert "/root/Level/Player" in str(info.value)


def test_get_path(scene: dict[str, Node], tree: SceneTree) -> None:
    assert tree.root.get_path() == "/root"
    assert scene["Gun"].get_path() == "/root/Level/Player/Gun"
    assert scene["Orc"].get_path() == "/root/Level/Enemies/Orc"
    with pytest.raises(RuntimeError, match="not inside a tree"):
        Node("Loose").get_path()


def test_get_path_to(scene: dict[str, Node]) -> None:
    gun, orc, level = scene["Gun"], scene["Orc"], scene["Level"]
    assert gun.get_path_to(orc) == "../../Enemies/Orc"
    assert level.get_path_to(gun) == "Player/Gun"
    assert gun.get_path_to(level) == "../.."
    assert gun.get_path_to(gun) == "."
    assert gun.get_path_to(scene["Sprite"]) == "../Sprite"


def test_get_path_to_round_trips(scene: dict[str, Node], tree: SceneTree) -> None:
    nodes = list(tree.root.iter_subtree())
    for a in nodes:
        for b in nodes:
            assert a.get_node(a.get_path_to(b)) is b


def test_get_path_to_other_tree_rejected(scene: dict[str, Node]) -> None:
    with pytest.raises(ValueError, match="not in the same tree"):
        scene["Gun"].get_path_to(Node("Elsewhere"))


# --- find_children ---------------------------------------------------------------------------


def test_find_children_all_in_tree_order(scene: dict[str, Node]) -> None:
    assert names(scene["Level"].find_children()) == [
        "Player",
        "Sprite",
        "Gun",
        "Enemies",
        "Goblin",
        "Orc",
        "BigBoss",
    ]


def test_find_children_by_pattern(scene: dict[str, Node]) -> None:
    level = scene["Level"]
    assert names(level.find_children("G*")) == ["Gun", "Goblin"]
    assert names(level.find_children("*r*")) == ["Player", "Sprite", "Orc"]
    assert names(level.find_children("Or?")) == ["Orc"]
    assert names(level.find_children("[GS]*")) == ["Sprite", "Gun", "Goblin"]
    assert level.find_children("gun") == []  # case-sensitive
    assert level.find_children("Level") == []  # never the node itself


def test_find_children_by_type(scene: dict[str, Node]) -> None:
    level = scene["Level"]
    assert names(level.find_children("*", Enemy)) == ["Goblin", "Orc", "BigBoss"]
    assert names(level.find_children("*", Boss)) == ["BigBoss"]
    assert names(level.find_children("*o*", Enemy)) == ["Goblin", "BigBoss"]
    assert names(level.find_children(type=(Boss, type(None)))) == ["BigBoss"]


def test_find_children_not_recursive(scene: dict[str, Node]) -> None:
    level = scene["Level"]
    assert names(level.find_children("*", recursive=False)) == ["Player", "Enemies"]
    assert level.find_children("Gun", recursive=False) == []
    assert level.find_children("*", Enemy, recursive=False) == []
    assert names(scene["Enemies"].find_children("*", Enemy, recursive=False)) == [
        "Goblin",
        "Orc",
        "BigBoss",
    ]


def test_find_child(scene: dict[str, Node]) -> None:
    level = scene["Level"]
    assert level.find_child("G*") is scene["Gun"]
    assert level.find_child("*", Enemy) is scene["Goblin"]
    assert level.find_child("*", Boss) is scene["BigBoss"]
    assert level.find_child("Nobody") is None
    assert level.find_child("Gun", recursive=False) is None


# --- groups ----------------------------------------------------------------------------------


def test_groups_membership() -> None:
    node = Node("N")
    assert not node.is_in_group("enemies")
    node.add_to_group("enemies")
    node.add_to_group("actors")
    node.add_to_group("enemies")
    assert node.is_in_group("enemies") and node.is_in_group("actors")
    assert node.get_groups() == ["actors", "enemies"]
    node.remove_from_group("enemies")
    node.remove_from_group("never")
    assert not node.is_in_group("enemies")
    assert node.get_groups() == ["actors"]


def test_get_nodes_in_group_in_tree_order(scene: dict[str, Node], tree: SceneTree) -> None:
    # added to the group in reverse tree order
    for name in ("BigBoss", "Orc", "Gun", "Player"):
        scene[name].add_to_group("g")
    assert names(tree.get_nodes_in_group("g")) == ["Player", "Gun", "Orc", "BigBoss"]
    assert tree.get_first_node_in_group("g") is scene["Player"]
    assert tree.get_nodes_in_group("empty") == []
    assert tree.get_first_node_in_group("empty") is None
    # nodes outside the tree are not listed
    scene["Enemies"].remove_child(scene["Orc"])
    loose = Node("Loose")
    loose.add_to_group("g")
    assert names(tree.get_nodes_in_group("g")) == ["Player", "Gun", "BigBoss"]


def test_call_group(scene: dict[str, Node], tree: SceneTree, log: list) -> None:
    class Target(Node):
        def hit(self, amount: int, kind: str) -> None:
            log.append((self.name, amount, kind))

    targets = [Target("T1"), Target("T2")]
    scene["Enemies"].add_child(targets[1])
    scene["Player"].add_child(targets[0])
    for target in reversed(targets):
        target.add_to_group("hittable")
    tree.call_group("hittable", "hit", 3, "fire")
    assert log == [("T1", 3, "fire"), ("T2", 3, "fire")]


# --- signals ---------------------------------------------------------------------------------


def test_signal_declared_as_class_attribute() -> None:
    assert isinstance(Emitter.fired, Signal)
    assert Emitter.fired.name == "fired"
    assert Emitter.fired.arguments == ("a", "b")
    first, second = Emitter("E1"), Emitter("E2")
    assert isinstance(first.fired, BoundSignal)
    assert first.fired is first.fired
    assert first.fired is not second.fired
    assert first.fired.owner is first
    assert first.has_signal("fired") and first.has_signal("ready")
    assert not first.has_signal("nothing")


def test_connect_emit_with_args_in_connection_order(log: list) -> None:
    emitter = Emitter()
    emitter.fired.connect(lambda a, b: log.append(("first", a, b)))
    emitter.fired.connect(lambda a, b: log.append(("second", a, b)))
    emitter.fired.emit(1, "x")
    assert log == [("first", 1, "x"), ("second", 1, "x")]


def test_signals_are_per_instance(log: list) -> None:
    first, second = Emitter("E1"), Emitter("E2")
    first.pinged.connect(lambda: log.append("first"))
    second.pinged.emit()
    assert log == []
    first.pinged.emit()
    assert log == ["first"]


def test_disconnect_and_is_connected(log: list) -> None:
    emitter = Emitter()

    def on_ping() -> None:
        log.append("ping")

    assert not emitter.pinged.is_connected(on_ping)
    emitter.pinged.connect(on_ping)
    assert emitter.pinged.is_connected(on_ping)
    assert emitter.pinged.get_connections() == [on_ping]
    emitter.pinged.emit()
    emitter.pinged.disconnect(on_ping)
    assert not emitter.pinged.is_connected(on_ping)
    emitter.pinged.emit()
    assert log == ["ping"]


def test_bound_methods_compare_equal(log: list) -> None:
    class Listener:
        def on_ping(self) -> None:
            log.append("ping")

    listener = Listener()
    emitter = Emitter()
    emitter.pinged.connect(listener.on_ping)
    assert emitter.pinged.is_connected(listener.on_ping)
    with pytest.raises(ValueError, match="already connected"):
        emitter.pinged.connect(listener.on_ping)
    emitter.pinged.disconnect(listener.on_ping)
    emitter.pinged.emit()
    assert log == []


def test_double_connect_and_unknown_disconnect_rejected() -> None:
    emitter = Emitter()

    def callback() -> None:
        pass

    emitter.pinged.connect(callback)
    with pytest.raises(ValueError, match="already connected to signal 'pinged'"):
        emitter.pinged.connect(callback)
    with pytest.raises(ValueError, match="already connected"):
        emitter.pinged.connect(callback, one_shot=True)
    assert emitter.pinged.get_connections() == [callback]
    with pytest.raises(ValueError, match="not connected to signal 'fired'"):
        emitter.fired.disconnect(callback)
    emitter.pinged.disconnect(callback)
    with pytest.raises(ValueError, match="not connected"):
        emitter.pinged.disconnect(callback)


def test_one_shot(log: list) -> None:
    emitter = Emitter()

    def once() -> None:
        log.append("once")

    def always() -> None:
        log.append("always")

    emitter.pinged.connect(once, one_shot=True)
    emitter.pinged.connect(always)
    emitter.pinged.emit()
    assert not emitter.pinged.is_connected(once)
    assert emitter.pinged.is_connected(always)
    emitter.pinged.emit()
    assert log == ["once", "always", "always"]
    # can connect again after it fired (it goes to the end of the connection list)
    emitter.pinged.connect(once, one_shot=True)
    emitter.pinged.emit()
    assert log[-2:] == ["always", "once"]


def test_one_shot_not_called_again_by_reentrant_emit(log: list) -> None:
    emitter = Emitter()

    def once() -> None:
        log.append("once")
        emitter.pinged.emit()

    emitter.pinged.connect(once, one_shot=True)
    emitter.pinged.emit()
    assert log == ["once"]


def test_connect_during_emit_takes_effect_next_emission(log: list) -> None:
    emitter = Emitter()

    def late() -> None:
        log.append("late")

    def first() -> None:
        log.append("first")
        if not emitter.pinged.is_connected(late):
            emitter.pinged.connect(late)

    emitter.pinged.connect(first)
    emitter.pinged.emit()
    assert log == ["first"]
    emitter.pinged.emit()
    assert log == ["first", "first", "late"]


def test_disconnect_during_emit_takes_effect_next_emission(log: list) -> None:
    emitter = Emitter()

    def second() -> None:
        log.append("second")

    def first() -> None:
        log.append("first")
        if emitter.pinged.is_connected(second):
            emitter.pinged.disconnect(second)

    emitter.pinged.connect(first)
    emitter.pinged.connect(second)
    emitter.pinged.emit()
    assert log == ["first", "second"]
    emitter.pinged.emit()
    assert log == ["first", "second", "first"]


def test_reentrant_emit_sees_changes_made_by_the_outer_emission(log: list) -> None:
    emitter = Emitter()

    def late() -> None:
        log.append("late")

    def first() -> None:
        log.append("first")
        if not emitter.pinged.is_connected(late):
            emitter.pinged.connect(late)
            emitter.pinged.disconnect(second)
            emitter.pinged.emit()  # a new emission: sees late, not second

    def second() -> None:
        log.append("second")

    emitter.pinged.connect(first)
    emitter.pinged.connect(second)
    emitter.pinged.emit()
    assert log == ["first", "first", "late", "second"]


def test_one_shot_connected_during_emit_fires_once_from_next_emission(log: list) -> None:
    emitter = Emitter()

    def once() -> None:
        log.append("once")

    def first() -> None:
        log.append("first")
        if len(log) == 1:
            emitter.pinged.connect(once, one_shot=True)

    emitter.pinged.connect(first)
    emitter.pinged.emit()
    emitter.pinged.emit()
    emitter.pinged.emit()
    assert log == ["first", "first", "once", "first"]
    assert emitter.pinged.get_connections() == [first]


def test_user_signals(log: list) -> None:
    node = Node("N")
    assert not node.has_signal("scored")
    node.add_user_signal("scored")
    assert node.has_signal("scored")
    node.connect("scored", lambda points: log.append(points))
    node.emit_signal("scored", 10)
    node.get_signal("scored").emit(5)
    assert log == [10, 5]
    # user signals are per instance
    assert not Node("Other").has_signal("scored")
    with pytest.raises(ValueError, match="already has a member called 'scored'"):
        node.add_user_signal("scored")
    with pytest.raises(ValueError, match="'ready'"):
        node.add_user_signal("ready")
    with pytest.raises(ValueError, match="'add_child'"):
        node.add_user_signal("add_child")


def test_get_signal_unknown_raises_key_error() -> None:
    node = Emitter()
    with pytest.raises(KeyError, match="no signal 'nothing'"):
        node.get_signal("nothing")
    with pytest.raises(KeyError):
        node.get_signal("add_child")  # an attribute, but not a signal
    with pytest.raises(KeyError):
        node.connect("nothing", print)


def test_node_connect_and_emit_signal_by_name(log: list) -> None:
    emitter = Emitter()

    def on_fired(a, b) -> None:
        log.append((a, b))

    emitter.connect("fired", on_fired)
    assert emitter.is_connected("fired", on_fired)
    assert emitter.fired.is_connected(on_fired)
    emitter.emit_signal("fired", 1, 2)
    emitter.fired.emit(3, 4)
    emitter.disconnect("fired", on_fired)
    assert not emitter.is_connected("fired", on_fired)
    emitter.emit_signal("fired", 5, 6)
    assert log == [(1, 2), (3, 4)]
    emitter.connect("pinged", lambda: log.append("once"), one_shot=True)
    emitter.emit_signal("pinged")
    emitter.emit_signal("pinged")
    assert log[-1] == "once" and log.count("once") == 1


def test_builtin_lifecycle_signals(tree: SceneTree, log: list) -> None:
    parent = Rec("Parent", log)
    child = Rec("Child", log)
    parent.add_child(child)
    for node in (parent, child):
        for signal in ("tree_entered", "ready", "tree_exiting", "tree_exited"):
            node.connect(signal, lambda s=signal, n=node: log.append(("signal", s, n.name)))
    root = tree.root
    root.child_entered_tree.connect(lambda n: log.append(("root.child_entered_tree", n.name)))
    root.child_exiting_tree.connect(lambda n: log.append(("root.child_exiting_tree", n.name)))
    parent.child_entered_tree.connect(lambda n: log.append(("P.child_entered_tree", n.name)))
    parent.child_exiting_tree.connect(lambda n: log.append(("P.child_exiting_tree", n.name)))

    tree.root.add_child(parent)
    assert log == [
        ("enter", "Parent"),
        ("signal", "tree_entered", "Parent"),
        ("root.child_entered_tree", "Parent"),
        ("enter", "Child"),
        ("signal", "tree_entered", "Child"),
        ("P.child_entered_tree", "Child"),
        ("ready", "Child"),
        ("signal", "ready", "Child"),
        ("ready", "Parent"),
        ("signal", "ready", "Parent"),
    ]
    log.clear()
    tree.root.remove_child(parent)
    assert log == [
        ("exit", "Child"),
        ("signal", "tree_exiting", "Child"),
        ("P.child_exiting_tree", "Child"),
        ("exit", "Parent"),
        ("signal", "tree_exiting", "Parent"),
        ("root.child_exiting_tree", "Parent"),
        ("signal", "tree_exited", "Child"),
        ("signal", "tree_exited", "Parent"),
    ]


def test_tree_exited_emitted_after_detach(tree: SceneTree, log: list) -> None:
    node = Node("N")
    tree.root.add_child(node)
    node.tree_exiting.connect(lambda: log.append(("exiting", node.parent, node.is_inside_tree())))
    node.tree_exited.connect(lambda: log.append(("exited", node.parent, node.is_inside_tree())))
    tree.root.remove_child(node)
    assert log == [("exiting", tree.root, True), ("exited", None, False)]


def test_tree_node_added_and_removed_signals(tree: SceneTree, log: list) -> None:
    tree.node_added.connect(lambda n: log.append(("added", n.name)))
    tree.node_removed.connect(lambda n: log.append(("removed", n.name)))
    a, b = Node("A"), Node("B")
    a.add_child(b)
    tree.root.add_child(a)
    tree.root.remove_child(a)
    assert log == [("added", "A"), ("added", "B"), ("removed", "B"), ("removed", "A")]


# --- lifecycle order -------------------------------------------------------------------------


def build_abcd(log: list) -> dict[str, Rec]:
    """A{B{D}, C}."""
    nodes = {name: Rec(name, log) for name in "ABCD"}
    nodes["B"].add_child(nodes["D"])
    nodes["A"].add_child(nodes["B"])
    nodes["A"].add_child(nodes["C"])
    return nodes


def test_enter_tree_preorder_ready_children_first(tree: SceneTree, log: list) -> None:
    nodes = build_abcd(log)
    assert log == []  # nothing happens outside a tree
    tree.root.add_child(nodes["A"])
    assert log == [
        ("enter", "A"),
        ("enter", "B"),
        ("enter", "D"),
        ("enter", "C"),
        ("ready", "D"),
        ("ready", "B"),
        ("ready", "C"),
        ("ready", "A"),
    ]
    assert all(node.is_node_ready() and node.is_inside_tree() for node in nodes.values())
    assert all(node.get_tree() is tree for node in nodes.values())


def test_exit_tree_bottom_up_last_child_first(tree: SceneTree, log: list) -> None:
    nodes = build_abcd(log)
    tree.root.add_child(nodes["A"])
    log.clear()
    tree.root.remove_child(nodes["A"])
    assert log == [("exit", "C"), ("exit", "D"), ("exit", "B"), ("exit", "A")]
    assert not any(node.is_inside_tree() for node in nodes.values())
    with pytest.raises(RuntimeError, match="not inside a tree"):
        nodes["D"].get_tree()
    # the subtree stays intact
    assert nodes["A"].get_node("B/D") is nodes["D"]


def test_tree_available_in_enter_and_exit(tree: SceneTree, log: list) -> None:
    class Probe(Node):
        def _enter_tree(self) -> None:
            log.append(("enter", self.get_tree() is tree, self.get_path()))

        def _exit_tree(self) -> None:
            log.append(("exit", self.get_tree() is tree, self.get_path()))

    probe = Probe("Probe")
    tree.root.add_child(probe)
    tree.root.remove_child(probe)
    assert log == [("enter", True, "/root/Probe"), ("exit", True, "/root/Probe")]


def test_ready_only_once(tree: SceneTree, log: list) -> None:
    nodes = build_abcd(log)
    tree.root.add_child(nodes["A"])
    tree.root.remove_child(nodes["A"])
    log.clear()
    tree.root.add_child(nodes["A"])
    assert log == [("enter", "A"), ("enter", "B"), ("enter", "D"), ("enter", "C")]


def test_request_ready_runs_ready_again_on_next_entry(tree: SceneTree, log: list) -> None:
    nodes = build_abcd(log)
    tree.root.add_child(nodes["A"])
    tree.root.remove_child(nodes["A"])
    nodes["B"].request_ready()
    log.clear()
    tree.root.add_child(nodes["A"])
    assert [entry for entry in log if entry[0] == "ready"] == [("ready", "B")]
    # only once per request
    tree.root.remove_child(nodes["A"])
    log.clear()
    tree.root.add_child(nodes["A"])
    assert [entry for entry in log if entry[0] == "ready"] == []


def test_child_added_to_ready_node_in_tree(tree: SceneTree, log: list) -> None:
    parent = Rec("Parent", log)
    tree.root.add_child(parent)
    log.clear()
    parent.add_child(Rec("Late", log))
    assert log == [("enter", "Late"), ("ready", "Late")]


def test_subtree_built_in_ready_enters_once(tree: SceneTree, log: list) -> None:
    class Builder(Rec):
        def _ready(self) -> None:
            super()._ready()
            self.add_child(Rec("Built", self.log))

    tree.root.add_child(Builder("Builder", log))
    assert log == [
        ("enter", "Builder"),
        ("ready", "Builder"),
        ("enter", "Built"),
        ("ready", "Built"),
    ]


def test_child_added_in_enter_tree_enters_once(tree: SceneTree, log: list) -> None:
    class Builder(Rec):
        def _enter_tree(self) -> None:
            super()._enter_tree()
            if not self.has_node("Built"):
                self.add_child(Rec("Built", self.log))

    builder = Builder("Builder", log)
    entered: list[str] = []
    tree.node_added.connect(lambda n: entered.append(n.name))
    tree.root.add_child(builder)
    assert log.count(("enter", "Built")) == 1
    assert entered.count("Built") == 1
    assert log.count(("ready", "Built")) == 1


def test_notifications(tree: SceneTree, log: list) -> None:
    node = NoteRec("N", log)
    parent = Node("P")
    parent.add_child(node)
    assert log == [("note", "N", "PARENTED")]
    log.clear()
    tree.root.add_child(parent)
    assert log == [
        ("enter", "N"),
        ("note", "N", "ENTER_TREE"),
        ("ready", "N"),
        ("note", "N", "READY"),
    ]
    log.clear()
    tree.root.remove_child(parent)
    assert log == [("exit", "N"), ("note", "N", "EXIT_TREE")]
    log.clear()
    parent.remove_child(node)
    assert log == [("note", "N", "UNPARENTED")]


def test_notifications_when_added_directly(tree: SceneTree, log: list) -> None:
    node = NoteRec("N", log)
    tree.root.add_child(node)
    tree.root.remove_child(node)
    tree.root.add_child(node)
    assert [entry[2] for entry in log if entry[0] == "note"] == [
        "PARENTED",
        "ENTER_TREE",
        "READY",
        "EXIT_TREE",
        "UNPARENTED",
        "PARENTED",
        "ENTER_TREE",
    ]


# --- queue_free ------------------------------------------------------------------------------


def test_queue_free_outside_tree_is_immediate(log: list) -> None:
    parent = NoteRec("P", log)
    child = NoteRec("C", log)
    parent.add_child(child)
    log.clear()
    parent.queue_free()
    assert parent.is_freed() and child.is_freed()
    assert not parent.is_queued_for_deletion()
    assert log == [("note", "C", "PREDELETE"), ("note", "P", "PREDELETE")]


def test_queue_free_in_tree_is_deferred(tree: SceneTree, log: list) -> None:
    nodes = build_abcd(log)
    tree.root.add_child(nodes["A"])
    log.clear()
    nodes["B"].queue_free()
    assert nodes["B"].is_queued_for_deletion()
    assert not nodes["B"].is_freed()
    assert nodes["B"].is_inside_tree()
    assert log == []
    tree.process(0.0)
    assert log == [("exit", "D"), ("exit", "B")]
    assert nodes["B"].is_freed() and nodes["D"].is_freed()
    assert not nodes["B"].is_queued_for_deletion()
    assert not nodes["A"].is_freed() and not nodes["C"].is_freed()
    assert nodes["A"].get_children() == [nodes["C"]]
    assert nodes["B"].parent is None
    assert not nodes["B"].is_inside_tree() and not nodes["D"].is_inside_tree()


def test_queue_free_inside_pass_waits_for_end_of_frame(tree: SceneTree, log: list) -> None:
    class Doomed(Node):
        def _process(self, delta: float) -> None:
            self.queue_free()
            self.queue_free()  # safe to repeat
            log.append(("doomed", self.is_inside_tree(), self.is_freed()))

    class Witness(Node):
        def _process(self, delta: float) -> None:
            doomed = self.get_node_or_null("../Doomed")
            log.append(("witness", doomed is not None and not doomed.is_freed()))

    doomed = Doomed("Doomed")
    doomed.add_child(Node("Inner"))
    inner = doomed.get_child(0)
    tree.root.add_child(doomed)
    tree.root.add_child(Witness("Witness"))
    tree.process(0.1)
    assert log == [("doomed", True, False), ("witness", True)]
    assert doomed.is_freed() and inner.is_freed()
    assert not tree.root.has_node("Doomed")
    tree.process(0.1)
    assert log[-1] == ("witness", False)


def test_queue_free_twice_frees_once(tree: SceneTree, log: list) -> None:
    node = NoteRec("N", log)
    tree.root.add_child(node)
    log.clear()
    node.queue_free()
    node.queue_free()
    tree.process(0.0)
    node.queue_free()  # already freed: nothing happens
    tree.process(0.0)
    assert log == [
        ("exit", "N"),
        ("note", "N", "EXIT_TREE"),
        ("note", "N", "UNPARENTED"),
        ("note", "N", "PREDELETE"),
    ]


def test_freed_nodes_cannot_be_added(tree: SceneTree) -> None:
    parent, child = Node("P"), Node("C")
    parent.add_child(child)
    tree.root.add_child(parent)
    parent.queue_free()
    tree.process(0.0)
    with pytest.raises(ValueError, match="cannot add 'P': it was freed"):
        tree.root.add_child(parent)
    with pytest.raises(ValueError, match="freed"):
        Node("Other").add_child(child)  # child still has the freed parent, and is freed itself
    assert tree.root.get_children() == []


# --- mutations during a processing pass ------------------------------------------------------


class Spawner(Node):
    """Adds ``self.spawn`` as a child during its first _process."""

    def __init__(self, log: list) -> None:
        super().__init__("Spawner")
        self.log = log
        self.spawn = Rec("Spawned", log)

    def _process(self, delta: float) -> None:
        if self.spawn.parent is None:
            self.add_child(self.spawn)
            self.log.append(("after add", self.get_children(), self.spawn.is_inside_tree()))


class Observer(Node):
    """Later in tree order: records what it sees of the spawner's children."""

    def __init__(self, log: list) -> None:
        super().__init__("Observer")
        self.log = log

    def _process(self, delta: float) -> None:
        self.log.append(("observer", names(self.get_node("../Spawner").get_children())))


def test_add_child_during_process_is_deferred(tree: SceneTree, log: list) -> None:
    spawner = Spawner(log)
    tree.root.add_child(spawner)
    tree.root.add_child(Observer(log))
    tree.process(0.1)
    assert log == [
        ("after add", [], False),
        ("observer", []),
        ("enter", "Spawned"),
        ("ready", "Spawned"),
    ]
    assert spawner.get_children() == [spawner.spawn]
    assert spawner.spawn.is_inside_tree() and spawner.spawn.is_node_ready()


def test_remove_child_during_physics_process_is_deferred(tree: SceneTree, log: list) -> None:
    class Remover(Node):
        def _physics_process(self, delta: float) -> None:
            if self.get_child_count():
                self.remove_child(self.get_child(0))
                log.append(("after remove", names(self.get_children())))

    remover = Remover("Remover")
    victim = Rec("Victim", log)
    remover.add_child(victim)
    tree.root.add_child(remover)
    log.clear()
    tree.physics_tick()
    assert log == [("after remove", ["Victim"]), ("exit", "Victim")]
    assert remover.get_children() == []
    assert victim.parent is None and not victim.is_inside_tree()


def test_deferred_add_is_processed_from_next_frame(tree: SceneTree, log: list) -> None:
    class Ticker(Node):
        def _process(self, delta: float) -> None:
            log.append(("tick", self.name))

    class Parent(Node):
        def _process(self, delta: float) -> None:
            if not self.get_child_count():
                self.add_child(Ticker("Kid"))

    tree.root.add_child(Parent("Parent"))
    tree.process(0.1)
    assert log == []
    tree.process(0.1)
    assert log == [("tick", "Kid")]


def test_mutations_outside_pass_are_immediate(tree: SceneTree, log: list) -> None:
    keeper = Node("Keeper")
    tree.root.add_child(keeper)
    old = Node("Old")
    keeper.add_child(old)

    def mutate() -> None:
        new = Rec("New", log)
        keeper.add_child(new)
        log.append(("added", new.is_inside_tree(), names(keeper.get_children())))
        keeper.remove_child(old)
        log.append(("removed", old.is_inside_tree(), names(keeper.get_children())))

    tree.call_deferred(mutate)
    assert log == []
    tree.process(0.1)
    assert log == [
        ("enter", "New"),
        ("ready", "New"),
        ("added", True, ["Old", "New"]),
        ("removed", False, ["New"]),
    ]


def test_deferred_mutation_errors_surface_at_flush(tree: SceneTree) -> None:
    other = Node("Other")
    tree.root.add_child(other)
    taken = Node("Taken")
    other.add_child(taken)

    class Thief(Node):
        def _process(self, delta: float) -> None:
            self.add_child(taken)  # deferred, so the check happens after the pass

    tree.root.add_child(Thief("Thief"))
    with pytest.raises(ValueError, match="already a child of 'Other'"):
        tree.process(0.1)
    assert taken.parent is other


class _NoSuperInit(Node):
    def __init__(self) -> None:
        self.speed = 1.0  # forgot super().__init__()


def test_a_node_without_super_init_is_named_when_added() -> None:
    message = (
        r"_NoSuperInit was not set up as a node: call super\(\)\.__init__\(\) in "
        r"_NoSuperInit\.__init__"
    )
    with pytest.raises(TypeError, match=message):
        Node("Parent").add_child(_NoSuperInit())
    with pytest.raises(TypeError, match=message):
        _NoSuperInit().add_child(Node("Child"))


def test_an_agent_or_environment_without_super_init_is_named() -> None:
    from examples.faulty import BrittleAgent, BrittleEnvironment
    from rlenv_client import LocalClient

    class AgentNoSuperInit(BrittleAgent):
        def __init__(self) -> None:
            self.push = 0.0

    class EnvironmentNoSuperInit(BrittleEnvironment):
        def __init__(self) -> None:
            self.level = 1

    class Hosting(BrittleEnvironment):
        def __init__(self) -> None:
            super().__init__()
            self.add_child(AgentNoSuperInit())

    with pytest.raises(
        TypeError,
        match=r"AgentNoSuperInit was not set up as a node: call "
        r"super\(\)\.__init__\(\) in AgentNoSuperInit",
    ):
        LocalClient(Hosting)
    with pytest.raises(TypeError, match=r"EnvironmentNoSuperInit was not set up as a node"):
        LocalClient(EnvironmentNoSuperInit)
