"""rlenv: turn a Python simulation into a reinforcement-learning environment served over TCP.

Layout (one concept per module):

- ``node``, ``signals``, ``tree``, ``timer``: the Godot-style scene tree runtime;
- ``physics``: pymunk world, body, shape and joint nodes;
- ``rl_nodes``: the RL nodes users subclass (environment, agent, world);
- ``protocol`` (sans-IO), ``spaces``, ``errors``: the wire, shared with ``rlenv_client``;
- ``serving`` (the request path: endpoint, host, parts, instance), ``server``, ``cli``: serving
  an environment.

Names are imported lazily, so that ``import rlenv.protocol`` (what the client does) loads
neither the runtime nor pymunk.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

_EXPORTS = {
    "Node": "rlenv.node",
    "NodeNotFoundError": "rlenv.node",
    "ProcessMode": "rlenv.node",
    "Signal": "rlenv.signals",
    "SceneTree": "rlenv.tree",
    "PhysicsFramesTimer": "rlenv.timer",
    "PhysicsWorld": "rlenv.physics",
    "RigidBody": "rlenv.physics",
    "StaticBody": "rlenv.physics",
    "KinematicBody": "rlenv.physics",
    "CollisionShape": "rlenv.physics",
    "Joint": "rlenv.physics",
    "RLAgent": "rlenv.rl_nodes",
    "RLEnvWorld": "rlenv.rl_nodes",
    "RLEnvironment": "rlenv.rl_nodes",
    "Server": "rlenv.server",
    "Camera": "rlenv.camera",
    "View": "rlenv.views",
    "view": "rlenv.views",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'rlenv' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


if TYPE_CHECKING:
    from rlenv.camera import Camera as Camera
    from rlenv.node import Node as Node
    from rlenv.node import NodeNotFoundError as NodeNotFoundError
    from rlenv.node import ProcessMode as ProcessMode
    from rlenv.physics import CollisionShape as CollisionShape
    from rlenv.physics import Joint as Joint
    from rlenv.physics import KinematicBody as KinematicBody
    from rlenv.physics import PhysicsWorld as PhysicsWorld
    from rlenv.physics import RigidBody as RigidBody
    from rlenv.physics import StaticBody as StaticBody
    from rlenv.rl_nodes import RLAgent as RLAgent
    from rlenv.rl_nodes import RLEnvironment as RLEnvironment
    from rlenv.rl_nodes import RLEnvWorld as RLEnvWorld
    from rlenv.server import Server as Server
    from rlenv.signals import Signal as Signal
    from rlenv.timer import PhysicsFramesTimer as PhysicsFramesTimer
    from rlenv.tree import SceneTree as SceneTree
    from rlenv.views import View as View
    from rlenv.views import view as view
