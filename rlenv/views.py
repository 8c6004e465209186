"""Tree views: query a scene tree and read or set attributes of many nodes at once.

Blueprints-style access to a built world, without keeping references by hand::

    arm = view(environment)
    arm.all.bodies                      # View[3|CartPole.all.bodies]
    arm.all.bodies.angular_velocity     # [0.0, 0.12, -0.3]: one value per node
    arm.all.shapes.color = (255, 0, 0)  # set on every node of the view
    arm.all.joints["Hinge*"]            # by name pattern
    arm.all.in_group("sensors")         # by group
    arm.all.bodies.where(lambda b: b.position.y > 1.0)
    row.shapes.set("color", gradient("purple", "blue", n_steps=20))   # one value per node
    table.placeholders.named("leg*").attach(leg)   # a copy of leg on every leg marker

Steps chain: ``.all`` (the nodes and every node below them), ``.children``, ``.parent``, and the
typed steps ``.bodies``, ``.shapes``, ``.joints``: the children of those kinds. So
``.bodies.bodies`` are the bodies attached below the bodies, and ``.all.bodies`` every body in
the subtree; ``.placeholders`` are the Marker2D nodes anywhere below. Reading any other
attribute returns a list with that attribute of every node, in tree order; assigning one sets
it on every node (which must all have it).
"""

from __future__ import annotations

import fnmatch
from collections.abc import Callable, Iterable, Iterator
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # Node.placeholders is a View: this module knows nodes' classes by name
    from rlenv.node import Node

__all__ = ["View", "view"]

_OWN = frozenset({"_nodes", "_label"})


class View:
    """An ordered set of nodes (tree order, no duplicates) with chainable queries."""

    __slots__ = ("_label", "_nodes")

    def __init__(self, nodes: Iterable[Node], label: str = "") -> None:
        unique: dict[int, Node] = {}
        for node in nodes:
            unique.setdefault(id(node), node)
        object.__setattr__(self, "_nodes", tuple(unique.values()))
        object.__setattr__(self, "_label", label)

    # --- steps ------------------------------------------------------------------------------

    @property
    def all(self) -> View:
        """The nodes of this view and every node below them."""
        return self._step("all", (n for node in self._nodes for n in node.iter_subtree()))

    @property
    def children(self) -> View:
        """The children of the nodes of this view."""
        return self._step("children", (c for node in self._nodes for c in node.get_children()))

    @property
    def parent(self) -> View:
        """The parents of the nodes of this view."""
        return self._step(
            "parent", (node.parent for node in self._nodes if node.parent is not None)
        )

    @property
    def bodies(self) -> View:
        """The children of this view's nodes that are physics bodies."""
        return self._typed("bodies", _BODY)

    @property
    def shapes(self) -> View:
        """The children of this view's nodes that are collision shapes."""
        return self._typed("shapes", _SHAPE)

    @property
    def joints(self) -> View:
        """The children of this view's nodes that are joints."""
        return self._typed("joints", _JOINT)

    @property
    def placeholders(self) -> View:
        """The Marker2D nodes below the nodes of this view (their mounting points)."""
        return self._step(
            "placeholders",
            (
                n
                for node in self._nodes
                for n in node.iter_subtree()
                if n is not node and _is_a(n, _MARKER)
            ),
        )

    def of_type(self, kind: type[Any] | tuple[type[Any], ...]) -> View:
        """The nodes of this view that are instances of ``kind``."""
        name = kind.__name__ if isinstance(kind, type) else "|".join(k.__name__ for k in kind)
        return self._step(f"of_type({name})", (n for n in self._nodes if isinstance(n, kind)))

    def named(self, pattern: str) -> View:
        """The nodes of this view whose name matches the glob ``pattern``."""
        return self._step(
            f"[{pattern!r}]", (n for n in self._nodes if fnmatch.fnmatchcase(n.name, pattern))
        )

    def in_group(self, group: str) -> View:
        """The nodes of this view in ``group``."""
        return self._step(f"in_group({group!r})", (n for n in self._nodes if n.is_in_group(group)))

    def where(self, predicate: Callable[[Any], bool]) -> View:
        """The nodes of this view for which ``predicate(node)`` is true."""
        return self._step("where(...)", (n for n in self._nodes if predicate(n)))

    def __getitem__(self, key: int | str) -> Any:
        """``view[3]``: the fourth node; ``view["Cart*"]``: the nodes named like that."""
        if isinstance(key, str):
            return self.named(key)
        return self._nodes[key]

    # --- the nodes --------------------------------------------------------------------------

    @property
    def nodes(self) -> list[Node]:
        """The nodes, in tree order."""
        return list(self._nodes)

    def __iter__(self) -> Iterator[Node]:
        return iter(self._nodes)

    def __len__(self) -> int:
        return len(self._nodes)

    def __contains__(self, node: object) -> bool:
        return any(node is n for n in self._nodes)

    def __repr__(self) -> str:
        return f"View[{len(self._nodes)}|{self._label}]"

    # --- bulk attributes --------------------------------------------------------------------

    def __getattr__(self, name: str) -> list[Any]:
        if name.startswith("__"):
            raise AttributeError(name)
        missing = [n for n in self._nodes if not hasattr(n, name)]
        if missing:
            raise AttributeError(
                f"{missing[0]!r} (and {len(missing) - 1} more) in {self!r} have "
                f"no attribute {name!r}"
            )
        return [getattr(node, name) for node in self._nodes]

    def __setattr__(self, name: str, value: Any) -> None:
        if name in _OWN:
            raise AttributeError(f"{name} is read-only")
        missing = [n for n in self._nodes if not hasattr(n, name)]
        if missing:
            raise AttributeError(
                f"{missing[0]!r} in {self!r} has no attribute {name!r}; nothing was set"
            )
        for node in self._nodes:
            setattr(node, name, value)

    def set(self, name: str, values: Iterable[Any]) -> None:
        """Set ``name`` on every node, one value each (as many values as nodes).

        Raises:
            ValueError: not as many values as nodes.
        """
        values = list(values)
        if len(values) != len(self._nodes):
            raise ValueError(f"{len(values)} values for the {len(self._nodes)} nodes of {self!r}")
        for node, value in zip(self._nodes, values, strict=True):
            setattr(node, name, value)

    def attach(self, node: Node) -> View:
        """Put a :meth:`~rlenv.node.Node.duplicate` of ``node`` on every marker of this view.

        Returns:
            A View of the copies, one per marker, in the order of the markers.

        Raises:
            TypeError: a node of the view is not a :class:`~rlenv.scene2d.marker2d.Marker2D`
                (nothing was attached).
        """
        strangers = [n for n in self._nodes if not _is_a(n, _MARKER)]
        if strangers:
            raise TypeError(
                f"{strangers[0]!r} in {self!r} is not a Marker2D: attach puts "
                "copies on markers only; nothing was attached"
            )
        return View(
            [marker.attach(node) for marker in self._nodes], f"{self._label}.attach({node.name})"
        )

    # --- internals --------------------------------------------------------------------------

    def _step(self, step: str, nodes: Iterable[Node]) -> View:
        return View(_tree_order(nodes), f"{self._label}.{step}" if self._label else step)

    def _typed(self, step: str, kind: str) -> View:
        return self._step(
            step, (c for node in self._nodes for c in node.get_children() if _is_a(c, kind))
        )


_BODY = "rlenv.scene2d.physics.body.PhysicsBody"
_SHAPE = "rlenv.scene2d.physics.collision_shape.CollisionShape"
_JOINT = "rlenv.scene2d.physics.joint.Joint"
_MARKER = "rlenv.scene2d.marker2d.Marker2D"
_KINDS: dict[type, frozenset[str]] = {}


def _is_a(node: Any, kind: str) -> bool:
    """Whether ``node`` is an instance of the class named ``kind`` (module and name).

    As Godot's ``is_class``: by name, so that this module, which :class:`~rlenv.node.Node`
    itself uses, imports none of the classes it asks about.
    """
    cls = node.__class__
    names = _KINDS.get(cls)
    if names is None:
        names = _KINDS[cls] = frozenset(f"{k.__module__}.{k.__qualname__}" for k in cls.__mro__)
    return kind in names


def view(*nodes: Node) -> View:
    """A view of ``nodes`` to start queries from, e.g. ``view(environment).all.bodies``."""
    return View(nodes, "+".join(node.name for node in nodes))


def _tree_order(nodes: Iterable[Node]) -> list[Node]:
    """``nodes`` sorted in tree order (pre-order) when they share a tree (View drops repeats).

    Each node's key is its path of child indices from the top of its tree, so the cost grows
    with the nodes and their depth, not with the size of the tree around them.
    """
    found = list(nodes)
    if len(found) < 2:
        return found
    keys: dict[int, tuple[int, ...]] = {}  # node id -> its path, shared by its descendants
    indices: dict[int, dict[int, int]] = {}  # parent id -> {child id: index}

    def key(node: Node) -> tuple[int, ...]:
        chain = []  # the node and its ancestors whose path is not known yet, upwards
        while id(node) not in keys:
            chain.append(node)
            if node.parent is None:
                keys[id(node)] = (id(node),)  # nodes of different trees stay apart
                chain.pop()
                break
            node = node.parent
        path = keys[id(node)]
        for step in reversed(chain):
            parent = step.parent
            assert parent is not None
            index = indices.get(id(parent))
            if index is None:
                index = indices[id(parent)] = {
                    id(child): position for position, child in enumerate(parent._children)
                }
            path = keys[id(step)] = (*path, index[id(step)])
        return path

    roots: dict[int, int] = {}
    for node in found:
        roots.setdefault(key(node)[0], len(roots))
    return sorted(found, key=lambda node: (roots[keys[id(node)][0]], keys[id(node)][1:]))
