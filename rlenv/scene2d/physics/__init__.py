"""2D physics nodes over pymunk: a world that owns a space, and the bodies, shapes and joints in it.

A :class:`PhysicsWorld` owns one ``pymunk.Space`` and steps it once per physics tick with the
tree's fixed delta (in its ``_physics_step``, after every node's ``_physics_process`` of that tick,
as a physics server would). Body, shape and joint nodes below it put their pymunk objects into
that space when they enter the tree and take them out when they leave::

    World (PhysicsWorld)
    |___Cart (RigidBody)
    |   |___Box (CollisionShape)
    |___Pole (RigidBody)
    |   |___Stick (CollisionShape)
    |___Hinge (Joint: PivotJoint between Cart and Pole)

Collisions are reported as signals: every shape's ``collision_started(shape)`` /
``collision_ended(shape)`` and every body's ``body_entered(body)`` / ``body_exited(body)``, with
the other shape or body node as the argument. They are emitted from inside the step (the space
is locked; changes to the tree made by handlers are deferred to the end of the tick).

Bodies are :class:`~rlenv.scene2d.node2d.Node2D` s: a body below a Node2D frame enters its space
at the pose composed from the frames above it (under plain nodes, its pose is the world's), and
its ``position`` and ``rotation`` read back relative to that frame. Every node here can be
copied (:meth:`~rlenv.node.Node.duplicate`: a copy owns its own pymunk objects) and packed
(:class:`~rlenv.scene2d.packed_scene.PackedScene`).

**Units.** pymunk has none of its own: any consistent set works. rlenv's defaults read as SI
units (gravity ``(0, -9.81)`` in metres per second squared, y up; ``delta`` in seconds), and
the examples use metres, kilograms and seconds: then forces are in newtons, impulses in
newton-seconds, torques in newton-metres. Angles are in radians, counter-clockwise (with y up).

**Frames.** A point or vector is either in *world* coordinates, in a *body's* own frame, whose
origin is the body's position and whose axes turn with its angle, or relative to a Node2D.
Shape geometry (``offset``, box, segment and polygon points) and joint anchors other than
:meth:`Joint.pivot`'s are in the body's frame; a body's :attr:`~PhysicsBody.position` and
:attr:`~PhysicsBody.rotation` are relative to its nearest Node2D ancestor (world coordinates
without one); velocities, gravity, forces and impulses are in world coordinates. Values read
back are ``pymunk.Vec2d`` (a tuple of two floats with vector arithmetic); any ``(x, y)`` pair
sets them.

One module per family, as Godot's ``scene/2d/physics``: :mod:`~rlenv.scene2d.physics.world`
(the world and its space), :mod:`~rlenv.scene2d.physics.body` (the bodies),
:mod:`~rlenv.scene2d.physics.collision_shape`, :mod:`~rlenv.scene2d.physics.joint`;
:mod:`~rlenv.scene2d.physics._space_owner` is what the last three know of a world. What reaches
below pymunk's public API is in :mod:`rlenv.scene2d._chipmunk`.
"""

from rlenv.scene2d._chipmunk import step_space
from rlenv.scene2d.physics.body import KinematicBody, PhysicsBody, RigidBody, StaticBody
from rlenv.scene2d.physics.collision_shape import CollisionShape
from rlenv.scene2d.physics.joint import Joint
from rlenv.scene2d.physics.world import PhysicsWorld

__all__ = [
    "CollisionShape",
    "Joint",
    "KinematicBody",
    "PhysicsBody",
    "PhysicsWorld",
    "RigidBody",
    "StaticBody",
    "step_space",
]
