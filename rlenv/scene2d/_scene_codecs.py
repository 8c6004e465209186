"""How each of rlenv's node classes goes into a packed scene's data and back.

A codec packs what its class owns (a body's pymunk body, a shape's geometry, a node's process
mode) as ``properties``, checks the properties of untrusted data, and builds a node of that
class, or of a user's class derived from it, without calling the user's ``__init__``. The
attributes it owns (:attr:`Codec.handled`) are not packed as plain attributes.
:func:`codec_for` finds the codec of the nearest of rlenv's classes a class derives from.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import pymunk

from rlenv.node import Node, ProcessMode, _overrides
from rlenv.scene2d import raycast_sensor
from rlenv.scene2d._pymunk_data import (
    ConstraintRecipe,
    copy_shape,
    integer,
    number,
    shape_from_data,
    shape_to_data,
    vector,
)
from rlenv.scene2d.camera import Camera
from rlenv.scene2d.colors import to_rgb
from rlenv.scene2d.marker2d import Marker2D
from rlenv.scene2d.node2d import Node2D
from rlenv.scene2d.physics import (
    CollisionShape,
    Joint,
    KinematicBody,
    PhysicsBody,
    PhysicsWorld,
    RigidBody,
    StaticBody,
)
from rlenv.scene2d.raycast_sensor import RaycastSensor2D
from rlenv.timer import PhysicsFramesTimer

__all__ = ["CODECS", "OWN_CLASSES", "Codec", "codec_for"]


class Codec:
    """Packs, checks and builds the nodes of one of rlenv's classes (plain nodes here).

    Args:
        base: the class whose ``__init__`` builds the node.

    Attributes:
        keys: the property names its data may hold.
        handled: the attributes it packs itself (as properties, or not at all).
    """

    keys = frozenset({"process_mode", "process", "physics_process"})
    handled = frozenset({"_name", "_groups", "_process_mode", "_processing", "_physics_processing"})

    def __init__(self, base: type[Node]) -> None:
        self.base = base

    def pack(self, node: Node) -> dict[str, Any]:
        """What the class owns of ``node``, as plain data (defaults left out)."""
        properties: dict[str, Any] = {}
        if node._process_mode is not ProcessMode.INHERIT:
            properties["process_mode"] = int(node._process_mode)
        if node._processing != _overrides(node, "_process"):
            properties["process"] = node._processing
        if node._physics_processing != _overrides(node, "_physics_process"):
            properties["physics_process"] = node._physics_processing
        return properties

    def check(self, properties: Mapping[str, Any]) -> dict[str, Any]:
        """``properties`` checked and converted, ready for :meth:`build`.

        Raises:
            ValueError: an unknown or wrong property, named.
        """
        unknown = set(properties) - self.keys
        if unknown:
            raise ValueError(
                f"no property {sorted(map(str, unknown))[0]!r:.40}; the properties "
                f"are {', '.join(sorted(self.keys))}"
            )
        return self._checked(properties)

    def _checked(self, properties: Mapping[str, Any]) -> dict[str, Any]:
        checked: dict[str, Any] = {}
        if "process_mode" in properties:
            checked["process_mode"] = ProcessMode(
                integer(properties["process_mode"], "process_mode", 0, len(ProcessMode) - 1)
            )
        for flag in ("process", "physics_process"):
            if flag in properties:
                checked[flag] = _boolean(properties[flag], flag)
        return checked

    def build(self, node: Node, name: str, properties: Mapping[str, Any]) -> None:
        """Make the blank ``node`` (an instance of the class or a subclass) a new node."""
        self.construct(node, name, properties)
        self.restore(node, properties)

    def construct(self, node: Node, name: str, properties: Mapping[str, Any]) -> None:
        """Call the class's ``__init__`` on ``node``."""
        self.base.__init__(node, name=name)

    def restore(self, node: Node, properties: Mapping[str, Any]) -> None:
        """Set what ``__init__`` does not take."""
        if "process_mode" in properties:
            node._process_mode = properties["process_mode"]
        if "process" in properties:
            node._processing = properties["process"]
        if "physics_process" in properties:
            node._physics_processing = properties["physics_process"]


class Node2DCodec(Codec):
    """Node2D and Marker2D: the local pose."""

    keys = Codec.keys | {"position", "rotation"}
    handled = Codec.handled | {"_position", "_rotation"}

    def pack(self, node: Node) -> dict[str, Any]:
        """See :meth:`Codec.pack`."""
        properties = super().pack(node)
        assert isinstance(node, Node2D)
        properties["position"] = list(node.position)
        if node.rotation:
            properties["rotation"] = node.rotation
        return properties

    def _checked(self, properties: Mapping[str, Any]) -> dict[str, Any]:
        checked = super()._checked(properties)
        checked["position"] = vector(properties.get("position", (0.0, 0.0)), "position")
        checked["rotation"] = number(properties.get("rotation", 0.0), "rotation")
        return checked

    def construct(self, node: Node, name: str, properties: Mapping[str, Any]) -> None:
        """See :meth:`Codec.construct`."""
        self.base.__init__(
            node,
            name,
            position=properties["position"],  # type: ignore[call-arg]
            rotation=properties["rotation"],
        )


class SensorCodec(Node2DCodec):
    """RaycastSensor2D: the pose and the rays' settings (checked: level data may hold one)."""

    settings = frozenset(
        {
            "n_rays",
            "ray_length",
            "cone_width",
            "collision_mask",
            "collide_with_sensors",
            "exclude_parent",
        }
    )
    keys = Node2DCodec.keys | settings
    handled = Node2DCodec.handled | settings | {"_hits"}
    _defaults = {
        "n_rays": 16,
        "ray_length": 5.0,
        "cone_width": math.tau,
        "collision_mask": raycast_sensor.ALL_LAYERS,
        "collide_with_sensors": False,
        "exclude_parent": True,
    }

    def pack(self, node: Node) -> dict[str, Any]:
        """See :meth:`Codec.pack`."""
        properties = super().pack(node)
        for key, default in self._defaults.items():
            value = getattr(node, key)
            if value != default:
                properties[key] = value
        return properties

    def _checked(self, properties: Mapping[str, Any]) -> dict[str, Any]:
        checked = super()._checked(properties)
        checked.update(
            raycast_sensor.check_settings(
                {
                    **self._defaults,
                    **{key: value for key, value in properties.items() if key in self.settings},
                }
            )
        )
        return checked

    def construct(self, node: Node, name: str, properties: Mapping[str, Any]) -> None:
        """See :meth:`Codec.construct`."""
        RaycastSensor2D.__init__(
            node,  # type: ignore[arg-type]
            name,
            **{key: properties[key] for key in self.settings},
            position=properties["position"],
            rotation=properties["rotation"],
        )


_BODY_TYPES = {
    "dynamic": pymunk.Body.DYNAMIC,
    "kinematic": pymunk.Body.KINEMATIC,
    "static": pymunk.Body.STATIC,
}
_IMPLIED_TYPES = {RigidBody: "dynamic", KinematicBody: "kinematic", StaticBody: "static"}


class BodyCodec(Node2DCodec):
    """Physics bodies: the pose (local), the kind, mass and moment, the velocities."""

    keys = Node2DCodec.keys | {"type", "mass", "moment", "velocity", "angular_velocity"}
    handled = Node2DCodec.handled | {"body", "_chipmunk"}  # the body's handle goes with it

    def pack(self, node: Node) -> dict[str, Any]:
        """See :meth:`Codec.pack`."""
        properties = super().pack(node)
        assert isinstance(node, PhysicsBody)
        body = node.body
        kind = next(name for name, value in _BODY_TYPES.items() if value == body.body_type)
        if self.base not in _IMPLIED_TYPES:
            properties["type"] = kind
        elif _IMPLIED_TYPES[self.base] != kind:
            raise ValueError(f"a {self.base.__name__} holds a {kind} pymunk body")
        if kind == "dynamic":
            if body.mass:
                properties["mass"] = body.mass
            if body.moment:
                properties["moment"] = body.moment
        if kind != "static":
            if body.velocity != (0.0, 0.0):
                properties["velocity"] = list(body.velocity)
            if body.angular_velocity:
                properties["angular_velocity"] = body.angular_velocity
        return properties

    def _checked(self, properties: Mapping[str, Any]) -> dict[str, Any]:
        checked = super()._checked(properties)
        implied = _IMPLIED_TYPES.get(self.base)
        kind = properties.get("type", implied or "dynamic")
        if kind not in _BODY_TYPES or (implied is not None and kind != implied):
            expected = implied or "one of " + ", ".join(_BODY_TYPES)
            raise ValueError(f"type must be {expected}, got {kind!r:.40}")
        checked["type"] = kind
        checked["mass"] = number(properties.get("mass", 0.0), "mass", low=0.0)
        checked["moment"] = number(properties.get("moment", 0.0), "moment", low=0.0, finite=False)
        if kind != "dynamic" and (checked["mass"] or checked["moment"]):
            raise ValueError(f"a {kind} body has no mass nor moment")
        checked["velocity"] = vector(properties.get("velocity", (0.0, 0.0)), "velocity")
        checked["angular_velocity"] = number(
            properties.get("angular_velocity", 0.0), "angular_velocity"
        )
        return checked

    def construct(self, node: Node, name: str, properties: Mapping[str, Any]) -> None:
        """See :meth:`Codec.construct`."""
        kind = properties["type"]
        body = (
            pymunk.Body(properties["mass"], properties["moment"])
            if kind == "dynamic"
            else pymunk.Body(body_type=_BODY_TYPES[kind])
        )
        PhysicsBody.__init__(
            node,  # type: ignore[arg-type]
            body,
            position=properties["position"],
            rotation=properties["rotation"],
            name=name,
        )

    def restore(self, node: Node, properties: Mapping[str, Any]) -> None:
        """See :meth:`Codec.restore`."""
        super().restore(node, properties)
        assert isinstance(node, PhysicsBody)
        if properties["type"] != "static":
            node.body.velocity = properties["velocity"]
            node.body.angular_velocity = properties["angular_velocity"]


class WorldCodec(Codec):
    """PhysicsWorld: gravity, solver iterations, damping, whether it monitors contacts."""

    keys = Codec.keys | {"gravity", "iterations", "damping", "contact_monitor"}
    handled = Codec.handled | {"space", "_contact_monitor"}

    def pack(self, node: Node) -> dict[str, Any]:
        """See :meth:`Codec.pack`."""
        properties = super().pack(node)
        assert isinstance(node, PhysicsWorld)
        properties["gravity"] = list(node.gravity)
        if node.iterations != 10:
            properties["iterations"] = node.iterations
        if node.damping != 1.0:
            properties["damping"] = node.damping
        if not node.contact_monitor:
            properties["contact_monitor"] = False
        return properties

    def _checked(self, properties: Mapping[str, Any]) -> dict[str, Any]:
        checked = super()._checked(properties)
        checked["gravity"] = vector(properties.get("gravity", (0.0, -9.81)), "gravity")
        checked["iterations"] = integer(properties.get("iterations", 10), "iterations", 1, 1000)
        checked["damping"] = number(properties.get("damping", 1.0), "damping", low=0.0)
        checked["contact_monitor"] = _boolean(
            properties.get("contact_monitor", True), "contact_monitor"
        )
        return checked

    def construct(self, node: Node, name: str, properties: Mapping[str, Any]) -> None:
        """See :meth:`Codec.construct`."""
        PhysicsWorld.__init__(
            node,  # type: ignore[arg-type]
            properties["gravity"],
            iterations=properties["iterations"],
            damping=properties["damping"],
            contact_monitor=properties["contact_monitor"],
            name=name,
        )


class ShapeCodec(Codec):
    """CollisionShape: the geometry and mass (see pymunk_data), material and colour."""

    keys = Codec.keys | {"shape", "friction", "elasticity", "sensor", "color"}
    handled = Codec.handled | {"shape", "_color"}

    def pack(self, node: Node) -> dict[str, Any]:
        """See :meth:`Codec.pack`."""
        properties = super().pack(node)
        assert isinstance(node, CollisionShape)
        properties["shape"] = shape_to_data(node.shape)
        if node.friction != 0.5:
            properties["friction"] = node.friction
        if node.elasticity:
            properties["elasticity"] = node.elasticity
        if node.sensor:
            properties["sensor"] = True
        if node.color is not None:
            properties["color"] = list(node.color)
        return properties

    def _checked(self, properties: Mapping[str, Any]) -> dict[str, Any]:
        checked = super()._checked(properties)
        if "shape" not in properties:
            raise ValueError("a CollisionShape needs its shape")
        checked["shape"] = shape_from_data(properties["shape"])  # a template, copied per build
        checked["friction"] = number(properties.get("friction", 0.5), "friction", low=0.0)
        checked["elasticity"] = number(properties.get("elasticity", 0.0), "elasticity", low=0.0)
        checked["sensor"] = _boolean(properties.get("sensor", False), "sensor")
        color = properties.get("color")
        try:
            checked["color"] = None if color is None else to_rgb(color)
        except TypeError as error:
            raise ValueError(str(error)) from None
        return checked

    def construct(self, node: Node, name: str, properties: Mapping[str, Any]) -> None:
        """See :meth:`Codec.construct`."""
        CollisionShape.__init__(
            node,  # type: ignore[arg-type]
            copy_shape(properties["shape"]),
            friction=properties["friction"],
            elasticity=properties["elasticity"],
            sensor=properties["sensor"],
            color=properties["color"],
            name=name,
        )


class JointCodec(Codec):
    """Joint: the paths of its bodies, its constraint's recipe, its options."""

    keys = Codec.keys | {"a", "b", "constraint", "collide_bodies", "max_force"}
    handled = Codec.handled | {"node_a", "node_b", "_make", "_collide_bodies", "_max_force"}

    def pack(self, node: Node) -> dict[str, Any]:
        """See :meth:`Codec.pack`."""
        properties = super().pack(node)
        assert isinstance(node, Joint)
        recipe = node.recipe
        if recipe is None:
            raise ValueError(
                "its constraint comes from a factory function, which is code, not "
                "data: build it with Joint.pivot, groove, motor or spring"
            )
        properties.update(a=node.node_a, b=node.node_b, constraint=recipe.to_data())
        if node._collide_bodies:
            properties["collide_bodies"] = True
        if node._max_force != math.inf:
            properties["max_force"] = node._max_force
        return properties

    def _checked(self, properties: Mapping[str, Any]) -> dict[str, Any]:
        checked = super()._checked(properties)
        for key in ("a", "b"):
            path = properties.get(key)
            if not isinstance(path, str) or not path or len(path) > 4096:
                raise ValueError(f"{key} must be the path of a body node, got {path!r:.40}")
            checked[key] = path
        checked["constraint"] = ConstraintRecipe.from_data(properties.get("constraint"))
        checked["collide_bodies"] = _boolean(
            properties.get("collide_bodies", False), "collide_bodies"
        )
        checked["max_force"] = number(
            properties.get("max_force", math.inf), "max_force", low=0.0, finite=False
        )
        return checked

    def construct(self, node: Node, name: str, properties: Mapping[str, Any]) -> None:
        """See :meth:`Codec.construct`."""
        Joint.__init__(
            node,  # type: ignore[arg-type]
            properties["a"],
            properties["b"],
            properties["constraint"],
            collide_bodies=properties["collide_bodies"],
            max_force=properties["max_force"],
            name=name,
        )


def _boolean(value: Any, what: str) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{what} must be true or false, got {value!r:.40}")
    return value


CODECS: dict[type[Node], Codec] = {
    Node: Codec(Node),
    Node2D: Node2DCodec(Node2D),
    Marker2D: Node2DCodec(Marker2D),
    RaycastSensor2D: SensorCodec(RaycastSensor2D),
    PhysicsWorld: WorldCodec(PhysicsWorld),
    PhysicsBody: BodyCodec(PhysicsBody),
    RigidBody: BodyCodec(RigidBody),
    StaticBody: BodyCodec(StaticBody),
    KinematicBody: BodyCodec(KinematicBody),
    CollisionShape: ShapeCodec(CollisionShape),
    Joint: JointCodec(Joint),
    Camera: Codec(Camera),
    PhysicsFramesTimer: Codec(PhysicsFramesTimer),
}
"""The codec of each of rlenv's node classes a scene may hold."""

OWN_CLASSES: dict[str, type[Node]] = {kind.__name__: kind for kind in CODECS}
"""rlenv's node classes, by name: what every scene's data may name."""


def codec_for(kind: type[Node]) -> Codec:
    """The codec of the nearest of rlenv's classes ``kind`` derives from (itself included)."""
    for klass in kind.__mro__:
        codec = CODECS.get(klass)
        if codec is not None:
            return codec
    raise TypeError(f"{kind.__name__} is not a Node class")
