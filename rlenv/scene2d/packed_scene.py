"""PackedScene: a subtree as plain data, to instantiate again anywhere (Godot's PackedScene).

::

    scene = PackedScene.pack(level)            # the subtree as it is now
    copy = scene.instantiate()                 # a new subtree, outside any tree
    data = scene.to_data()                     # plain msgpack types: maps, lists, numbers...
    scene = PackedScene.from_data(data, allowed=(Peg, Bin))   # from a file, a reset's options

Data never runs code: :meth:`PackedScene.from_data` builds rlenv's own node classes and the
classes in ``allowed`` (named by their class name), refuses any other class with a clear
error, and never imports a module. A node is built without calling its class's ``__init__``
(as unpickling would): the nearest of rlenv's classes it derives from builds what rlenv owns
(a body's pymunk body, a shape's geometry), then the attributes the class added are restored.
Everything is checked before anything is built, so a refused scene builds nothing.

The data (``FORMAT``, version 1)::

    {"format": "rlenv.PackedScene", "version": 1, "root": NODE}
    NODE = {"class": "Peg", "name": "Peg3",
            "properties": {...},          # what rlenv's own class keeps: pose, shape, mass...
            "attributes": {...},          # the node's other attributes, as plain data
            "tuples": [...],              # those of the attributes that were tuples
            "nodes": {attribute: path},   # attributes referring to nodes of the scene
            "groups": [...], "signals": [...],   # its groups; its user signals
            "connections": [[signal, path, method, one_shot], ...],
            "children": [NODE, ...]}      # every key but "class" and "name" optional

What packs: attributes holding plain data (numbers, strings, bytes, lists, tuples, maps) or a
node of the scene; signal connections to a method of a node of the scene (others, such as
connections to nodes outside or to functions, are not part of the scene: connect them after
instantiating, as in Godot). Anything else is refused by :meth:`PackedScene.pack`, naming the
node and the attribute. Tuples nested in lists come back as lists.

**What data may connect to.** Data comes from clients (a reset's ``level`` option), so a
connection is code it makes run. A signal may be connected to a *public* method that a class of
``allowed`` adds itself, or to one of :data:`CONNECTABLE` (rlenv's methods a level needs). Never
to a private method (``_on_hit``), a lifecycle method (``_enter_tree``, ``_ready``...) or
another of rlenv's methods (``remove_child``...), nor to a method of rlenv's that an allowed
class overrides. :meth:`PackedScene.pack` leaves such connections out, as Godot packs only the
connections marked persistent: make them in ``_ready``, which runs on the instantiated scene
too (one made in ``__init__`` is not made again). What data may set is as narrow: the properties
each of rlenv's classes packs (``scene_codecs``), and attributes that are plain data and hide no
method, property, signal or attribute of rlenv's.
"""

from __future__ import annotations

import inspect
import keyword
import types
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from rlenv._node_paths import check_name
from rlenv.node import Node
from rlenv.scene2d._scene_codecs import OWN_CLASSES, Codec, codec_for
from rlenv.signals import Signal

__all__ = [
    "CONNECTABLE",
    "FORMAT",
    "MAX_DEPTH",
    "MAX_NODES",
    "PackedScene",
    "PackedSceneError",
    "check_size",
]

FORMAT = "rlenv.PackedScene"
VERSION = 1
MAX_DEPTH = 64
"""Deepest nesting of nodes (and of plain values) that :meth:`PackedScene.from_data` reads by
default: levels go 5 deep (Plinko's, Maze's), and the tree enters a node a few calls deeper
than its parent, so that 64 leaves room below Python's recursion limit (the hello's
``limits.max_level_depth``)."""
MAX_NODES = 1_024
"""Most nodes that :meth:`PackedScene.from_data` reads by default (the hello's
``limits.max_level_nodes``). The examples' levels hold at most about 200 nodes, and stay there
however often they are edited (Plinko's pegs keep their distances, Maze's walls fill a grid);
a Plinko level of 1,000 nodes costs a reset under 0.2 s, where 4,000 cost 1.4 s and 200,000
held the server's loop for 7.7 s. Pass ``max_nodes`` to read larger scenes of your own."""
CONNECTABLE = frozenset({"queue_free"})
"""The methods of rlenv's own classes that a scene's data may connect a signal to."""

_NODE_KEYS = frozenset(
    {
        "class",
        "name",
        "properties",
        "attributes",
        "tuples",
        "nodes",
        "groups",
        "signals",
        "connections",
        "children",
    }
)
_PLAIN: tuple[type, ...] = (bool, int, float, str, bytes, type(None))


class PackedSceneError(ValueError):
    """A subtree that cannot be packed, or data that is not a scene this may build."""


class _Plan:
    """One node of a checked scene: everything needed to build it, nothing left to check."""

    __slots__ = (
        "attributes",
        "children",
        "codec",
        "connections",
        "groups",
        "kind",
        "name",
        "nodes",
        "parent",
        "properties",
        "signals",
        "where",
    )

    def __init__(
        self, kind: type[Node], codec: Codec, name: str, where: str, parent: _Plan | None
    ) -> None:
        self.kind = kind
        self.codec = codec
        self.name = name
        self.where = where
        self.parent = parent
        self.properties: dict[str, Any] = {}
        self.attributes: dict[str, Any] = {}
        self.nodes: dict[str, str] = {}
        self.groups: list[str] = []
        self.signals: list[str] = []
        self.connections: list[tuple[str, str, str, bool]] = []
        self.children: list[_Plan] = []


class _PackMethod:
    """``PackedScene.pack(node)`` makes a scene; ``scene.pack(node)`` packs into ``scene``."""

    def __get__(self, scene: PackedScene | None, owner: type[PackedScene]) -> Any:
        if scene is None:
            return lambda node: owner()._pack(node)
        return scene._pack


class PackedScene:
    """A subtree kept as plain data, to :meth:`instantiate` as often as needed.

    Make one with :meth:`pack` (``PackedScene.pack(node)``, or Godot's ``PackedScene()``
    then ``scene.pack(node)``) or :meth:`from_data`.
    """

    pack = _PackMethod()
    """``pack(node)``: capture ``node`` and its subtree as they are now; returns the scene.

    Raises:
        PackedSceneError: something in the subtree cannot be packed (an attribute holding
            neither plain data nor a node of the subtree, a joint made from a factory
            function, two classes with one name), naming the node.
    """

    def __init__(self) -> None:
        self._data: dict[str, Any] | None = None
        self._root: _Plan | None = None

    def _pack(self, node: Node) -> PackedScene:
        subtree = list(node.iter_subtree())
        classes: dict[str, type[Node]] = {}
        for member in subtree:
            kind = type(member)
            if classes.setdefault(kind.__name__, kind) is not kind:
                raise PackedSceneError(
                    f"two classes named {kind.__name__!r} in the subtree of "
                    f"{node.name!r}: a packed scene names classes by name"
                )
        inside = {id(member) for member in subtree}
        data = {"format": FORMAT, "version": VERSION, "root": _packed(node, inside)}
        self._root = _compile(data, {**OWN_CLASSES, **classes})
        self._data = data
        return self

    @classmethod
    def from_data(
        cls,
        data: Any,
        allowed: Iterable[type[Node]] = (),
        *,
        max_nodes: int = MAX_NODES,
        max_depth: int = MAX_DEPTH,
    ) -> PackedScene:
        """The scene ``data`` describes (see :meth:`to_data`), checked all through.

        Its nodes are counted first (:func:`check_size`), before anything else is read.

        Args:
            data: a scene's data, e.g. from ``msgpack.unpackb``.
            allowed: node classes the data may name besides rlenv's own (an environment
                passes its own classes).
            max_nodes: the most nodes the data may hold.
            max_depth: the deepest the data may nest its nodes (the root is at depth 0).

        Raises:
            PackedSceneError: the data holds more than ``max_nodes`` nodes or nests them more
                than ``max_depth`` deep, names a class that is neither rlenv's nor in
                ``allowed``, or is not a scene; the message says where.
            TypeError: ``allowed`` holds something that is not a Node class.
        """
        check_size(data, max_nodes, max_depth)
        registry = dict(OWN_CLASSES)
        for kind in allowed:
            if not (isinstance(kind, type) and issubclass(kind, Node)):
                raise TypeError(f"allowed holds {kind!r:.60}, which is not a Node class")
            if registry.setdefault(kind.__name__, kind) is not kind:
                raise TypeError(f"two allowed classes are named {kind.__name__!r}")
        scene = cls()
        scene._root = _compile(data, registry)
        scene._data = _plain_copy(data)
        return scene

    def to_data(self) -> dict[str, Any]:
        """The scene as plain msgpack types (a new copy each time).

        Raises:
            RuntimeError: the scene is empty (nothing packed yet).
        """
        return _plain_copy(self._checked()[0])

    def instantiate(self) -> Node:
        """A new subtree built from the scene, outside any tree.

        Raises:
            RuntimeError: the scene is empty (nothing packed yet).
        """
        root = self._checked()[1]
        built: dict[int, Node] = {}
        node = _build(root, built)
        _link(root, built)
        return node

    def _checked(self) -> tuple[dict[str, Any], _Plan]:
        if self._data is None or self._root is None:
            raise RuntimeError("this PackedScene is empty: pack a node or use from_data")
        return self._data, self._root

    def __repr__(self) -> str:
        if self._root is None:
            return "<PackedScene (empty)>"
        return f"<PackedScene {self._root.kind.__name__} {self._root.name!r}>"


# --- packing ---------------------------------------------------------------------------------


def _packed(node: Node, inside: set[int]) -> dict[str, Any]:
    kind = type(node)
    codec = codec_for(kind)
    where = f"{kind.__name__} {node.name!r}"
    try:
        properties = codec.pack(node)
    except (TypeError, ValueError) as error:
        raise PackedSceneError(f"{where}: {error}") from None
    entry: dict[str, Any] = {"class": kind.__name__, "name": node.name}
    if properties:
        entry["properties"] = properties
    attributes, tuples, references = {}, [], {}
    skipped = kind._TREE_STATE | codec.handled
    for key, value in node.__dict__.items():
        if key in skipped:
            continue
        if isinstance(value, Node):
            if id(value) not in inside:
                raise PackedSceneError(
                    f"{where}: attribute {key!r} refers to {value!r}, outside the packed subtree"
                )
            references[key] = node.get_path_to(value)
            continue
        attributes[key] = _plain(value, f"{where}: attribute {key!r}", 0)
        if isinstance(value, tuple):
            tuples.append(key)
    for name, value in (
        ("attributes", attributes),
        ("tuples", tuples),
        ("nodes", references),
        ("groups", node.get_groups()),
        ("signals", _user_signals(node)),
        ("connections", _connections(node, inside)),
        ("children", [_packed(child, inside) for child in node._children]),
    ):
        if value:
            entry[name] = value
    return entry


def _plain(value: Any, where: str, depth: int) -> Any:
    """``value`` as plain msgpack data (subclasses of plain types as the plain type)."""
    if depth > MAX_DEPTH:
        raise PackedSceneError(f"{where} is nested more than {MAX_DEPTH} deep")
    if value.__class__ in _PLAIN:
        return value
    for plain in _PLAIN:  # bool before int: bool is an int
        if isinstance(value, plain):
            return plain(value)
    if isinstance(value, np.generic) and not isinstance(value, np.object_):
        return _plain(value.item(), where, depth)
    if isinstance(value, list | tuple):
        return [_plain(item, where, depth + 1) for item in value]
    if isinstance(value, dict):
        return {
            _plain(key, where, depth + 1): _plain(item, where, depth + 1)
            for key, item in value.items()
        }
    raise PackedSceneError(
        f"{where} holds a {type(value).__name__}, which a packed scene cannot "
        "hold: keep plain data there (numbers, strings, lists, tuples, maps) "
        "or a node of the scene"
    )


def _user_signals(node: Node) -> list[str]:
    kind = type(node)
    return [name for name in node._signals if not isinstance(getattr(kind, name, None), Signal)]


def _connections(node: Node, inside: set[int]) -> list[list[Any]]:
    """Connections to methods of nodes of the scene: [signal, path, method, one_shot]."""
    found = []
    for name, bound in node._signals.items():
        for callback, one_shot in bound._connections:
            target = getattr(callback, "__self__", None)
            if not (
                isinstance(callback, types.MethodType)
                and isinstance(target, Node)
                and id(target) in inside
            ):
                continue
            method = callback.__func__.__name__
            if getattr(type(target), method, None) is not callback.__func__:
                continue  # not the class's method of that name: it cannot be found again
            if _not_connectable(type(target), method) is not None:
                continue  # data may not carry it: _ready connects it again (Godot's rule too)
            found.append([name, node.get_path_to(target), method, one_shot])
    return found


def _not_connectable(kind: type, method: str) -> str | None:
    """Why a scene's data may not connect a signal to ``kind.method``; ``None`` if it may."""
    if method.startswith("_"):
        return "a private method, which data may not connect to"
    if method in CONNECTABLE:
        return None
    for klass in kind.__mro__:
        if method in vars(klass) and klass.__module__.split(".")[0] == "rlenv":
            return f"a method of rlenv's {klass.__name__}, which data may not connect to"
    return None


# --- checking ----------------------------------------------------------------------------------


def check_size(data: Any, max_nodes: int = MAX_NODES, max_depth: int = MAX_DEPTH) -> None:
    """Refuse scene data with more than ``max_nodes`` nodes, or nested more than ``max_depth``.

    It counts the nodes under ``data["root"]`` through their ``children`` lists, without
    recursion and reading nothing else, so that data beyond the limits is refused before it
    costs anything (and never by a ``RecursionError``). Anything that is not shaped as a scene
    is left to :meth:`PackedScene.from_data`'s checks.

    Raises:
        PackedSceneError: too many nodes, or too deep.
    """
    root = data.get("root") if isinstance(data, Mapping) else None
    waiting: list[tuple[Any, int]] = [] if root is None else [(root, 0)]
    count = 0
    while waiting:
        entry, depth = waiting.pop()
        count += 1
        if depth > max_depth:
            raise PackedSceneError(
                f"nodes nested more than {max_depth} deep: a scene's data "
                f"nests at most {max_depth} (limits.max_level_depth)"
            )
        children = entry.get("children") if isinstance(entry, Mapping) else None
        if isinstance(children, list | tuple):
            waiting.extend((child, depth + 1) for child in children)
        if count + len(waiting) > max_nodes:
            raise PackedSceneError(
                f"a scene holds at most {max_nodes:,} nodes (limits.max_level_nodes)"
            )


def _compile(data: Any, registry: Mapping[str, type[Node]]) -> _Plan:
    """Check ``data`` all through; the plan that builds it."""
    if not isinstance(data, Mapping) or set(data) != {"format", "version", "root"}:
        raise PackedSceneError(
            "a scene's data is a map with exactly 'format', 'version' and 'root'"
        )
    if data["format"] != FORMAT or data["version"] != VERSION:
        raise PackedSceneError(
            f"this reads {FORMAT!r} version {VERSION}, not "
            f"{data['format']!r:.40} version {data['version']!r:.20}"
        )
    root = _compile_node(data["root"], registry, None, "")
    _check_links(root)
    return root


def _compile_node(
    entry: Any, registry: Mapping[str, type[Node]], parent: _Plan | None, where: str
) -> _Plan:
    """One node's plan and its children's (data from outside was sized by check_size)."""
    if not isinstance(entry, Mapping):
        raise PackedSceneError(f"{where or 'root'}: a node is a map")
    unknown = set(entry) - _NODE_KEYS
    if unknown:
        raise PackedSceneError(
            f"{where or 'root'}: a node has no {sorted(map(str, unknown))[0]!r}"
            f"; it has {sorted(_NODE_KEYS)}"
        )
    name = entry.get("name")
    try:
        name = check_name(name)
    except ValueError as error:
        raise PackedSceneError(f"{where or 'root'}: {error}") from None
    where = f"{where}/{name}" if where else name
    class_name = entry.get("class")
    kind = registry.get(class_name) if isinstance(class_name, str) else None
    if kind is None:
        raise PackedSceneError(
            f"{where}: class {class_name!r:.60} is not allowed; this scene may build "
            f"{', '.join(sorted(registry))} (an environment allows its own classes with "
            "PackedScene.from_data(data, allowed=...))"
        )
    codec = codec_for(kind)
    plan = _Plan(kind, codec, name, where, parent)
    try:
        plan.properties = codec.check(_map(entry.get("properties", {}), "properties"))
    except (TypeError, ValueError) as error:
        raise PackedSceneError(f"{where} ({class_name}): {error}") from None
    _compile_members(plan, entry)
    names = set()
    for child in _list(entry.get("children", []), f"{where}: children"):
        built = _compile_node(child, registry, plan, where)
        if built.name in names:
            raise PackedSceneError(f"{where}: two children named {built.name!r}")
        names.add(built.name)
        plan.children.append(built)
    return plan


def _compile_members(plan: _Plan, entry: Mapping[str, Any]) -> None:
    where, kind = plan.where, plan.kind
    reserved = kind._TREE_STATE | plan.codec.handled
    attributes = _map(entry.get("attributes", {}), f"{where}: attributes")
    for key, value in attributes.items():
        _check_attribute_name(kind, key, reserved, where)
        plan.attributes[key] = _checked_plain(value, f"{where}: attribute {key}", 0)
    for key in _list(entry.get("tuples", []), f"{where}: tuples"):
        if key not in plan.attributes or not isinstance(plan.attributes[key], list):
            raise PackedSceneError(f"{where}: tuples names {key!r:.40}, not a list attribute")
        plan.attributes[key] = _tuples(plan.attributes[key])
    for key, path in _map(entry.get("nodes", {}), f"{where}: nodes").items():
        _check_attribute_name(kind, key, reserved, where)
        if key in plan.attributes:
            raise PackedSceneError(f"{where}: {key!r} is both an attribute and a node")
        plan.nodes[key] = _path(path, f"{where}: nodes.{key}")
    for group in _list(entry.get("groups", []), f"{where}: groups"):
        if not isinstance(group, str) or not group:
            raise PackedSceneError(f"{where}: a group is a non-empty string, got {group!r:.40}")
        plan.groups.append(group)
    for signal in _list(entry.get("signals", []), f"{where}: signals"):
        if not _identifier(signal) or hasattr(kind, signal) or signal in plan.signals:
            raise PackedSceneError(
                f"{where}: {signal!r:.40} cannot be a user signal of {kind.__name__}"
            )
        plan.signals.append(signal)
    for connection in _list(entry.get("connections", []), f"{where}: connections"):
        plan.connections.append(_connection(plan, connection))


def _check_attribute_name(kind: type, key: Any, reserved: frozenset[str], where: str) -> None:
    if not _identifier(key) or key.startswith("__") or key in reserved:
        raise PackedSceneError(
            f"{where}: {key!r:.40} is not an attribute a scene may set on a {kind.__name__}"
        )
    found = inspect.getattr_static(kind, key, None)
    if callable(found) or hasattr(found, "__get__") or isinstance(found, Signal):
        raise PackedSceneError(f"{where}: attribute {key!r} would hide {kind.__name__}.{key}")


def _connection(plan: _Plan, connection: Any) -> tuple[str, str, str, bool]:
    where, kind = plan.where, plan.kind
    if not isinstance(connection, list | tuple) or len(connection) != 4:
        raise PackedSceneError(f"{where}: a connection is [signal, path, method, one_shot]")
    signal, path, method, one_shot = connection
    declared = _identifier(signal) and isinstance(getattr(kind, signal, None), Signal)
    if not declared and signal not in plan.signals:
        raise PackedSceneError(f"{where}: {kind.__name__} has no signal {signal!r:.40}")
    if not _identifier(method) or method.startswith("__"):
        raise PackedSceneError(f"{where}: {method!r:.40} is not a method name")
    if not isinstance(one_shot, bool):
        raise PackedSceneError(f"{where}: a connection's one_shot is a boolean")
    return (signal, _path(path, f"{where}: connection {signal}"), method, one_shot)


def _check_links(root: _Plan) -> None:
    """Every node path resolves inside the scene; every connection reaches a method."""
    stack = [root]
    while stack:
        plan = stack.pop()
        stack.extend(plan.children)
        for key, path in plan.nodes.items():
            _resolve(plan, path, f"{plan.where}: nodes.{key}")
        for signal, path, method, _ in plan.connections:
            target = _resolve(plan, path, f"{plan.where}: connection {signal}")
            if not inspect.isfunction(inspect.getattr_static(target.kind, method, None)):
                raise PackedSceneError(
                    f"{plan.where}: connection {signal}: "
                    f"{target.kind.__name__} has no method {method!r}"
                )
            why = _not_connectable(target.kind, method)
            if why is not None:
                raise PackedSceneError(
                    f"{plan.where}: connection {signal}: {target.kind.__name__}.{method} is {why}"
                )
            declared = getattr(plan.kind, signal, None)
            if isinstance(declared, Signal):  # a user signal's arguments are its emitter's
                _check_arguments(declared, target.kind, method, plan.where)


def _check_arguments(signal: Signal, kind: type, method: str, where: str) -> None:
    """``kind.method`` takes the arguments ``signal`` passes (Godot checks this on connecting)."""
    function = inspect.getattr_static(kind, method)
    try:
        inspect.signature(function).bind(None, *signal.arguments)
    except TypeError:
        passes = ", ".join(signal.arguments) or "no arguments"
        raise PackedSceneError(
            f"{where}: connection {signal.name}: it passes ({passes}), which "
            f"{kind.__name__}.{method} does not take"
        ) from None


def _resolve(plan: _Plan, path: str, where: str) -> _Plan:
    node: _Plan | None = plan
    for part in path.split("/"):
        if part in ("", "."):
            continue
        if node is not None:
            node = (
                node.parent
                if part == ".."
                else next((child for child in node.children if child.name == part), None)
            )
        if node is None:
            raise PackedSceneError(f"{where}: {path!r:.60} is not a node of the scene")
    assert node is not None
    return node


def _map(value: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise PackedSceneError(f"{where} must be a map")
    return value


def _list(value: Any, where: str) -> list[Any] | tuple[Any, ...]:
    if not isinstance(value, list | tuple):
        raise PackedSceneError(f"{where} must be a list")
    return value


def _path(value: Any, where: str) -> str:
    if not isinstance(value, str) or not value or value.startswith("/") or len(value) > 4096:
        raise PackedSceneError(f"{where}: {value!r:.40} is not a relative node path")
    return value


def _identifier(value: Any) -> bool:
    return isinstance(value, str) and value.isidentifier() and not keyword.iskeyword(value)


def _checked_plain(value: Any, where: str, depth: int) -> Any:
    """``value`` if it is plain data (lists for sequences), else an error."""
    if depth > MAX_DEPTH:
        raise PackedSceneError(f"{where} is nested more than {MAX_DEPTH} deep")
    if value.__class__ in _PLAIN:
        return value
    if value.__class__ in (list, tuple):
        return [_checked_plain(item, where, depth + 1) for item in value]
    if value.__class__ is dict:
        return {
            _checked_plain(key, where, depth + 1): _checked_plain(item, where, depth + 1)
            for key, item in value.items()
        }
    raise PackedSceneError(
        f"{where} holds a {type(value).__name__}: a scene's data holds plain "
        "data only (maps, lists, numbers, strings, bytes, booleans, nil)"
    )


def _tuples(value: Any) -> Any:
    return tuple(_tuples(item) for item in value) if isinstance(value, list) else value


def _plain_copy(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {key: _plain_copy(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_plain_copy(item) for item in value]
    return value


# --- building ----------------------------------------------------------------------------------


def _build(plan: _Plan, built: dict[int, Node]) -> Node:
    kind = plan.kind
    node = kind.__new__(kind)
    plan.codec.build(node, plan.name, plan.properties)
    node.__dict__.update(
        {
            key: _plain_copy(value) if isinstance(value, list | dict) else value
            for key, value in plan.attributes.items()
        }
    )
    node._groups = set(plan.groups)
    for signal in plan.signals:
        node.add_user_signal(signal)
    built[id(plan)] = node
    for child in plan.children:
        node.add_child(_build(child, built))
    return node


def _link(root: _Plan, built: dict[int, Node]) -> None:
    """Node references and signal connections, once every node exists."""
    stack = [root]
    while stack:
        plan = stack.pop()
        stack.extend(plan.children)
        node = built[id(plan)]
        for key, path in plan.nodes.items():
            node.__dict__[key] = built[id(_resolve(plan, path, plan.where))]
        for signal, path, method, one_shot in plan.connections:
            target = built[id(_resolve(plan, path, plan.where))]
            node.get_signal(signal).connect(getattr(target, method), one_shot=one_shot)
