"""Node: the unit of a scene tree, with Godot 4's structure, lifecycle and process modes.

A node has a name, a parent and ordered children whose names are unique among siblings. Once
it is inside a :class:`~rlenv.tree.SceneTree` it receives, as in Godot:

- ``_enter_tree()`` when it enters the tree, parent before children;
- ``_ready()`` once, after all its children are ready (children first);
- ``_physics_process(delta)`` every physics tick and ``_process(delta)`` every frame, in tree
  order, when its process mode lets it (see :class:`ProcessMode`);
- ``_physics_step(delta)`` after every node's ``_physics_process`` of the tick, for nodes that
  simulate something (a :class:`~rlenv.scene2d.physics.PhysicsWorld` steps its pymunk space here);
- ``_exit_tree()`` when it leaves, children before parent (last child first).

Every lifecycle event also reaches ``_notification(what)`` (one of the ``NOTIFICATION_*``
constants), for code that prefers a single dispatcher. Per-tick processing calls only the
virtuals, to keep the hot path short: the tree calls them from its *tick plan*, lists of the bound
methods that can run, which the node keeps up to date by telling its tree (``_plan_changed``)
whenever its place in the tree, ``set_process``, ``set_physics_process`` or its process mode
changes.

While the tree runs a processing pass, ``add_child``, ``remove_child`` and ``queue_free`` on
nodes inside the tree are deferred to the end of the pass, like pymunk's locked space; deferred
calls (:meth:`Node.call_deferred`) run between passes, where such changes are immediate.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Callable, Iterator
from enum import IntEnum
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar, cast

from rlenv._node_paths import ancestry, check_name, relative_path, unique_name, walk
from rlenv.duplication import copied_node, duplicate_subtree
from rlenv.signals import Signal, SignalOwner
from rlenv.views import View

if TYPE_CHECKING:
    from rlenv.tree import SceneTree

__all__ = [
    "NOTIFICATION_ENTER_TREE",
    "NOTIFICATION_EXIT_TREE",
    "NOTIFICATION_PARENTED",
    "NOTIFICATION_PREDELETE",
    "NOTIFICATION_READY",
    "NOTIFICATION_UNPARENTED",
    "Node",
    "NodeNotFoundError",
    "ProcessMode",
    "check_initialised",
]

NOTIFICATION_PREDELETE = 1
NOTIFICATION_ENTER_TREE = 10
NOTIFICATION_EXIT_TREE = 11
NOTIFICATION_READY = 13
NOTIFICATION_PARENTED = 18
NOTIFICATION_UNPARENTED = 19

N = TypeVar("N", bound="Node")


class ProcessMode(IntEnum):
    """When a node processes, relative to :attr:`SceneTree.paused` (Godot 4's five modes)."""

    INHERIT = 0
    """Like the parent; the root resolves to PAUSABLE."""
    PAUSABLE = 1
    """Only while the tree is not paused."""
    WHEN_PAUSED = 2
    """Only while the tree is paused."""
    ALWAYS = 3
    """Whether or not the tree is paused."""
    DISABLED = 4
    """Never."""


class NodeNotFoundError(LookupError):
    """No node at the given path."""


class Node(SignalOwner):
    """A named node with children, groups, signals and the Godot lifecycle.

    Subclass it and override the virtuals (``_ready``, ``_physics_process`` ...) to give a node
    behaviour; declare :class:`~rlenv.signals.Signal` class attributes for what it announces.
    A node outside a :class:`~rlenv.tree.SceneTree` is only a structure: it processes nothing
    until it is added below the tree's :attr:`~rlenv.tree.SceneTree.root` (an environment's
    tree is built by the server).

    Args:
        name: the node's name; defaults to the class name. Made unique among its siblings when
            it is added (``Name``, ``Name2``, ``Name3`` ...). It may not contain
            ``/ : @ % . "`` nor be ``.`` or ``..``.
        process_mode: when the node processes; see :class:`ProcessMode`.

    Raises:
        ValueError: an invalid ``name``.
    """

    tree_entered = Signal()
    """``tree_entered()``: the node entered the tree (emitted after ``_enter_tree``)."""
    ready = Signal()
    """``ready()``: the node is ready (emitted after ``_ready``)."""
    tree_exiting = Signal()
    """``tree_exiting()``: the node is about to leave the tree (emitted after ``_exit_tree``)."""
    tree_exited = Signal()
    """``tree_exited()``: the node left the tree."""
    child_entered_tree = Signal("node")
    """``child_entered_tree(node)``: the child ``node`` entered the tree."""
    child_exiting_tree = Signal("node")
    """``child_exiting_tree(node)``: the child ``node`` is about to leave the tree."""
    renamed = Signal()
    """``renamed()``: the node's name changed."""

    _TREE_STATE: ClassVar[frozenset[str]] = frozenset(
        {
            "_parent",
            "_children",
            "_children_by_name",
            "_tree",
            "_signals",
            "_resolved_mode",
            "_processes_when",
            "_is_ready",
            "_ready_requested",
            "_queued_for_deletion",
            "_freed",
        }
    )
    """Attributes that belong to the node's place in a tree, not to the node: a duplicate and
    a packed scene rebuild them rather than copy them. Subclasses add theirs (a physics
    body's space, say)."""

    def __init__(self, name: str | None = None, *, process_mode: ProcessMode = ProcessMode.INHERIT):
        self._name = check_name(name if name is not None else type(self).__name__)
        self._parent: Node | None = None
        self._children: list[Node] = []
        self._children_by_name: dict[str, Node] = {}
        self._tree: SceneTree | None = None
        self._groups: set[str] = set()
        self._signals = {}
        self._process_mode = ProcessMode(process_mode)
        self._resolved_mode = ProcessMode.PAUSABLE
        self._processes_when = _CAN_PROCESS[ProcessMode.PAUSABLE]  # indexed by tree.paused
        self._processing = _overrides(self, "_process")
        self._physics_processing = _overrides(self, "_physics_process")
        self._is_ready = False
        self._ready_requested = False
        self._queued_for_deletion = False
        self._freed = False

    # --- identity ---------------------------------------------------------------------------

    @property
    def name(self) -> str:
        """The node's name, unique among its siblings."""
        return self._name

    @name.setter
    def name(self, value: str) -> None:
        value = check_name(value)
        if value == self._name:
            return
        if self._parent is not None:
            siblings = self._parent._children_by_name
            del siblings[self._name]
            value = unique_name(value, siblings)
            siblings[value] = self
        self._name = value
        self._emit("renamed")

    def __repr__(self) -> str:
        where = self.get_path() if self.is_inside_tree() else self._name
        return f"<{type(self).__name__} {where}>"

    # --- structure --------------------------------------------------------------------------

    @property
    def parent(self) -> Node | None:
        """The parent node, or ``None``."""
        return self._parent

    def get_parent(self) -> Node | None:
        """The parent node, or ``None`` (Godot's spelling of :attr:`parent`)."""
        return self._parent

    def get_children(self) -> list[Node]:
        """The children, in order (a new list)."""
        return list(self._children)

    def get_child(self, index: int) -> Node:
        """The child at ``index`` (negative counts from the end)."""
        return self._children[index]

    def get_child_count(self) -> int:
        """How many children the node has."""
        return len(self._children)

    def get_index(self) -> int:
        """The node's position among its parent's children.

        Raises:
            RuntimeError: the node has no parent.
        """
        if self._parent is None:
            raise RuntimeError(f"{self!r} has no parent")
        return self._parent._children.index(self)

    def add_child(self, node: Node) -> None:
        """Append ``node`` as the last child; it enters the tree if this node is inside one.

        The child's name is made unique among its new siblings. Deferred to the end of the pass
        if called while the tree is processing.

        Raises:
            ValueError: ``node`` already has a parent, is this node or one of its ancestors, or
                was freed.
            TypeError: this node or ``node`` was never set up as a node (its class's
                ``__init__`` did not call ``super().__init__()``).
        """
        try:
            if self._deferred(self.add_child, node):
                return
            freed = node._freed
        except AttributeError:
            check_initialised(self)
            check_initialised(node)
            raise
        if freed:
            raise ValueError(f"cannot add {node._name!r}: it was freed")
        if node._parent is not None:
            raise ValueError(
                f"cannot add {node._name!r} to {self._name!r}: it is already a child of "
                f"{node._parent._name!r}; remove it from there first"
            )
        ancestor: Node | None = self
        while ancestor is not None:
            if ancestor is node:
                raise ValueError(f"cannot add {node._name!r} under itself")
            ancestor = ancestor._parent
        node._name = unique_name(node._name, self._children_by_name)
        node._parent = self
        self._children.append(node)
        self._children_by_name[node._name] = node
        node.notification(NOTIFICATION_PARENTED)
        if self._tree is not None:
            node._propagate_enter_tree(self._tree)
            self._tree._plan_changed()
            node._propagate_ready()

    def remove_child(self, node: Node) -> None:
        """Detach ``node``; it leaves the tree (``_exit_tree`` bottom-up) but is not freed.

        Deferred to the end of the pass if called while the tree is processing.

        Raises:
            ValueError: ``node`` is not a child of this node.
        """
        if self._deferred(self.remove_child, node):
            return
        if node._parent is not self:
            raise ValueError(f"{node._name!r} is not a child of {self._name!r}")
        tree = self._tree
        if tree is not None:
            node._propagate_exit_tree()
        self._children.remove(node)
        del self._children_by_name[node._name]
        node._parent = None
        node.notification(NOTIFICATION_UNPARENTED)
        if tree is not None:
            tree._plan_changed()
            node._propagate_exited()

    def move_child(self, node: Node, to_index: int) -> None:
        """Move the child ``node`` to position ``to_index`` among its siblings.

        Raises:
            ValueError: ``node`` is not a child of this node.
        """
        if self._deferred(self.move_child, node, to_index):
            return
        if node._parent is not self:
            raise ValueError(f"{node._name!r} is not a child of {self._name!r}")
        self._children.remove(node)
        self._children.insert(
            to_index if to_index >= 0 else len(self._children) + 1 + to_index, node
        )
        if self._tree is not None:
            self._tree._plan_changed()

    def queue_free(self) -> None:
        """Free this node and its children at the end of the current frame; safe to repeat."""
        if self._queued_for_deletion or self._freed:
            return
        self._queued_for_deletion = True
        if self._tree is not None:
            self._tree.call_deferred(self._free)
        else:
            self._free()

    def is_queued_for_deletion(self) -> bool:
        """Whether :meth:`queue_free` was called and the node is not freed yet."""
        return self._queued_for_deletion and not self._freed

    def is_freed(self) -> bool:
        """Whether the node was freed; a freed node cannot be added again."""
        return self._freed

    def is_ancestor_of(self, node: Node) -> bool:
        """Whether ``node`` is below this node."""
        ancestor = node._parent
        while ancestor is not None:
            if ancestor is self:
                return True
            ancestor = ancestor._parent
        return False

    def iter_subtree(self) -> Iterator[Node]:
        """This node and every node below it, in tree (pre-)order."""
        stack = [self]
        while stack:
            node = stack.pop()
            yield node
            stack.extend(reversed(node._children))

    def duplicate(self: N) -> N:
        """A copy of this node and everything below it, outside any tree (Godot's duplicate).

        The copies have the same classes, names, groups and process modes. Every other
        attribute is copied deeply, never shared, except references to nodes: a reference to
        a node of the subtree points to its copy, one to a node outside stays as it is.
        Signal connections follow the same rule: a copy's connection to a method of a node of
        the subtree calls that node's copy; one to anything else (a method of an outside node,
        a function) is kept as it is. Physics nodes get their own pymunk bodies, shapes,
        constraints and spaces, and a joint between copied bodies joins the copies once in a
        tree. A body copy is placed where its original is now (relative to its parent), and
        built where it enters its space.

        Raises:
            ValueError: the node was freed.
        """
        return duplicate_subtree(self, _OUTSIDE_A_TREE)

    def __deepcopy__(self, memo: dict[int, Any]) -> Node:
        """``copy.deepcopy``: the :meth:`duplicate` of the node.

        Inside a duplicate, a node outside the duplicated subtree is kept, not copied.
        """
        return copied_node(self, memo)

    @property
    def placeholders(self) -> View:
        """The :class:`~rlenv.scene2d.marker2d.Marker2D` nodes below this one, in tree order.

        Mounting points (Blueprints' placeholders): ``table.placeholders.named("leg*")
        .attach(leg)`` puts a copy of ``leg`` on every marker named like that.
        """
        return View([self], self._name).placeholders

    def _duplicate_resources(self, memo: dict[int, Any]) -> None:
        """Hook of :meth:`duplicate`: copies of what this node owns outside Python, into ``memo``.

        Called before the attributes are copied, for objects the copy module must not copy (a
        pymunk body): ``memo[id(original)] = copy``.
        """

    def _duplicated(self, original: Node) -> None:
        """Hook of :meth:`duplicate`, on the copy of ``original``: set what is not copied.

        The copy's attributes are copied, except those of :attr:`_TREE_STATE`: set them to their
        values outside a tree.
        """

    # --- paths and lookup -------------------------------------------------------------------

    def get_path(self) -> str:
        """The absolute path, e.g. ``/root/CartPole/Agent``.

        Raises:
            RuntimeError: the node is not inside a tree.
        """
        if self._tree is None:
            raise RuntimeError(f"{self._name!r} is not inside a tree, so it has no path")
        return "/" + "/".join(node._name for node in ancestry(self))

    def get_path_to(self, node: Node) -> str:
        """The relative path from this node to ``node`` (both in the same tree)."""
        return relative_path(self, node)

    def get_node(self, path: str) -> Node:
        """The node at ``path``, relative (``World/Cart``, ``../Agent``) or absolute.

        Absolute paths start at the root: ``/root/CartPole/World``.

        Raises:
            NodeNotFoundError: nothing at that path; the message says where the walk stopped.
        """
        node, stopped_at, missing = walk(self, path)
        if node is None:
            where = stopped_at.get_path() if stopped_at._tree else repr(stopped_at._name)
            raise NodeNotFoundError(
                f"no node at path {path!r}: the walk stopped at {where}, which has no {missing!r}"
            )
        return node

    def get_node_or_null(self, path: str) -> Node | None:
        """Like :meth:`get_node`, but ``None`` when nothing is there."""
        return walk(self, path)[0]

    def has_node(self, path: str) -> bool:
        """Whether a node exists at ``path``."""
        return self.get_node_or_null(path) is not None

    def find_children(
        self,
        pattern: str = "*",
        type: type[N] | tuple[type, ...] | None = None,  # noqa: A002 - Godot's parameter name
        recursive: bool = True,
    ) -> list[N]:
        """Descendants whose name matches the glob ``pattern`` and that are instances of ``type``.

        Results are in tree order. With ``recursive=False`` only direct children are searched.
        """
        found = []
        candidates = (
            (n for n in self.iter_subtree() if n is not self) if recursive else self._children
        )
        for node in candidates:
            if type is not None and not isinstance(node, type):
                continue
            if fnmatch.fnmatchcase(node._name, pattern):
                found.append(node)
        return cast(list[N], found)  # each an instance of ``type`` (N), or of Node (no type)

    def find_child(
        self,
        pattern: str,
        type: type[N] | tuple[type, ...] | None = None,  # noqa: A002 - Godot's parameter name
        recursive: bool = True,
    ) -> N | None:
        """The first node :meth:`find_children` would return, or ``None``."""
        found = self.find_children(pattern, type, recursive)
        return found[0] if found else None

    # --- groups -----------------------------------------------------------------------------

    def add_to_group(self, group: str) -> None:
        """Put this node in ``group`` (see :meth:`SceneTree.get_nodes_in_group`)."""
        self._groups.add(group)

    def remove_from_group(self, group: str) -> None:
        """Take this node out of ``group``; nothing happens if it was not in it."""
        self._groups.discard(group)

    def is_in_group(self, group: str) -> bool:
        """Whether this node is in ``group``."""
        return group in self._groups

    def get_groups(self) -> list[str]:
        """The node's groups, sorted."""
        return sorted(self._groups)

    # --- tree membership and processing -----------------------------------------------------

    def is_inside_tree(self) -> bool:
        """Whether the node is inside a :class:`SceneTree`."""
        return self._tree is not None

    def get_tree(self) -> SceneTree:
        """The tree this node is in.

        Raises:
            RuntimeError: the node is not inside a tree.
        """
        if self._tree is None:
            raise RuntimeError(f"{self._name!r} is not inside a tree")
        return self._tree

    def is_node_ready(self) -> bool:
        """Whether ``_ready`` has run."""
        return self._is_ready

    def request_ready(self) -> None:
        """Run ``_ready`` again the next time this node enters the tree."""
        self._ready_requested = True

    def call_deferred(self, callback: Callable[..., Any], *args: Any) -> None:
        """Call ``callback(*args)`` after the current pass (right away outside a tree)."""
        if self._tree is None:
            callback(*args)
        else:
            self._tree.call_deferred(callback, *args)

    @property
    def process_mode(self) -> ProcessMode:
        """When this node processes; INHERIT follows the parent.

        A change during a pass that stops nodes skips them in the rest of the pass; one that lets
        them run takes effect from the next pass.
        """
        return self._process_mode

    @process_mode.setter
    def process_mode(self, mode: ProcessMode) -> None:
        mode = ProcessMode(mode)
        if mode is self._process_mode:
            return
        self._process_mode = mode
        if self._tree is not None:
            self._propagate_process_mode()
            self._tree._plan_changed()

    def can_process(self) -> bool:
        """Whether this node processes now, given its resolved process mode and the pause."""
        if self._tree is None:
            return False
        return self._processes_when[self._tree.paused]

    def set_process(self, enabled: bool) -> None:
        """Turn ``_process`` calls on or off (on by default when the class defines it).

        Turning them off during a pass skips this node in the rest of the pass; turning them on
        takes effect from the next pass.
        """
        self._set_flag("_processing", enabled)

    def is_processing(self) -> bool:
        """Whether ``_process`` is called for this node."""
        return self._processing

    def set_physics_process(self, enabled: bool) -> None:
        """Turn ``_physics_process`` calls on or off (on by default when the class defines it).

        Turning them off during a tick skips this node in the rest of the tick; turning them on
        takes effect from the next tick.
        """
        self._set_flag("_physics_processing", enabled)

    def is_physics_processing(self) -> bool:
        """Whether ``_physics_process`` is called for this node."""
        return self._physics_processing

    def _set_flag(self, flag: str, enabled: bool) -> None:
        """Set a processing flag; a change makes the tree's plans stale."""
        enabled = bool(enabled)
        if enabled is not getattr(self, flag):
            setattr(self, flag, enabled)
            if self._tree is not None:
                self._tree._plan_changed()

    def notification(self, what: int) -> None:
        """Deliver a lifecycle notification: the matching virtual first, then ``_notification``."""
        virtual = _VIRTUALS.get(what)
        if virtual is not None:
            getattr(self, virtual)()
        self._notification(what)

    # --- virtuals ---------------------------------------------------------------------------

    def _notification(self, what: int) -> None:
        """Override to receive every lifecycle notification (``NOTIFICATION_*``)."""

    def _enter_tree(self) -> None:
        """Called when the node enters the tree, before its children do."""

    def _ready(self) -> None:
        """Called once, when the node and all its children have entered the tree."""

    def _exit_tree(self) -> None:
        """Called when the node leaves the tree, after its children did."""

    def _process(self, delta: float) -> None:
        """Called every frame with the simulated time since the last frame, in seconds.

        In lockstep a frame follows each physics tick (``delta`` is one tick) and frames run
        while the tree is paused too (``delta`` 0). Override it, and it is called while
        :meth:`can_process` and :meth:`is_processing`.
        """

    def _physics_process(self, delta: float) -> None:
        """Called every physics tick with the fixed tick length, in seconds (1/60 by default).

        Runs before the physics spaces step in the same tick: apply forces and set velocities
        here. Override it, and it is called while :meth:`can_process` and
        :meth:`is_physics_processing`.
        """

    def _physics_step(self, delta: float) -> None:
        """Called every physics tick after every ``_physics_process``; advance a simulation.

        :class:`~rlenv.scene2d.physics.PhysicsWorld` steps its pymunk space here; few other
        nodes need it.
        """

    # --- internals --------------------------------------------------------------------------

    def _deferred(self, method: Callable[..., Any], *args: Any) -> bool:
        """Defer ``method(*args)`` if the tree is in a processing pass; whether it was deferred."""
        tree = self._tree
        if tree is not None and tree._running is not None:
            tree.call_deferred(method, *args)
            return True
        return False

    def _propagate_process_mode(self) -> None:
        for node in self.iter_subtree():
            node._resolve_process_mode()

    def _resolve_process_mode(self) -> None:
        mode = self._process_mode
        if mode is ProcessMode.INHERIT:
            parent = self._parent
            mode = parent._resolved_mode if parent is not None else ProcessMode.PAUSABLE
        self._resolved_mode = mode
        self._processes_when = _CAN_PROCESS[mode]

    def _propagate_enter_tree(self, tree: SceneTree) -> None:
        self._tree = tree
        parent = self._parent
        self._resolve_process_mode()
        self.notification(NOTIFICATION_ENTER_TREE)
        self._emit("tree_entered")
        tree._emit("node_added", self)
        if parent is not None:
            parent._emit("child_entered_tree", self)
        for child in list(self._children):
            if child._parent is self and child._tree is None:  # not added in _enter_tree
                child._propagate_enter_tree(tree)

    def _propagate_ready(self) -> None:
        for child in list(self._children):
            if child._parent is self and child._tree is not None:
                child._propagate_ready()
        if not self._is_ready or self._ready_requested:
            self._is_ready = True
            self._ready_requested = False
            self.notification(NOTIFICATION_READY)
            self._emit("ready")

    def _propagate_exit_tree(self) -> None:
        for child in reversed(list(self._children)):
            child._propagate_exit_tree()
        self.notification(NOTIFICATION_EXIT_TREE)
        self._emit("tree_exiting")
        if self._parent is not None:
            self._parent._emit("child_exiting_tree", self)
        tree, self._tree = self._tree, None
        if tree is not None:
            tree._emit("node_removed", self)

    def _propagate_exited(self) -> None:
        for child in reversed(self._children):
            child._propagate_exited()
        self._emit("tree_exited")

    def _free(self) -> None:
        if self._freed:
            return
        if self._parent is not None:
            self._parent.remove_child(self)
        for node in list(self.iter_subtree())[::-1]:
            node.notification(NOTIFICATION_PREDELETE)
            node._freed = True


_VIRTUALS = {
    NOTIFICATION_ENTER_TREE: "_enter_tree",
    NOTIFICATION_READY: "_ready",
    NOTIFICATION_EXIT_TREE: "_exit_tree",
}

# _CAN_PROCESS[resolved mode][paused]
_CAN_PROCESS = {
    ProcessMode.INHERIT: (True, False),
    ProcessMode.PAUSABLE: (True, False),
    ProcessMode.WHEN_PAUSED: (False, True),
    ProcessMode.ALWAYS: (True, True),
    ProcessMode.DISABLED: (False, False),
}
_OUTSIDE_A_TREE = {
    "_tree": None,
    "_resolved_mode": ProcessMode.PAUSABLE,
    "_processes_when": _CAN_PROCESS[ProcessMode.PAUSABLE],
    "_is_ready": False,
    "_ready_requested": False,
    "_queued_for_deletion": False,
    "_freed": False,
}
"""The tree state of a node that never entered a tree (a duplicate's)."""


def check_initialised(node: Node) -> None:
    """Refuse a node whose ``__init__`` never reached :class:`Node`'s.

    Raises:
        TypeError: naming the class, and saying to call ``super().__init__()``.
    """
    if isinstance(node, Node) and "_children" not in vars(node):
        name = type(node).__name__
        raise TypeError(
            f"{name} was not set up as a node: call super().__init__() in {name}.__init__"
        )


def _overrides(node: Node, method: str) -> bool:
    return getattr(type(node), method) is not getattr(Node, method)
