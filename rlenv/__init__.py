"""rlenv: turn a Python simulation into a reinforcement-learning environment served over TCP.

Layout (the design card's, one concept per module):

- ``node``, ``signals``, ``tree``, ``timer``: the Godot-style scene tree runtime;
- ``environment``, ``agent``, ``world`` (and their base ``rl_node``): what users subclass;
  ``agent_group``: a group of agents of one role, stepped as arrays (``RLAgentGroup``);
  ``levels``: a world whose levels come from the seed or as data (``LevelWorld``);
- ``views``: queries over a tree, bulk reads and writes (``view``);
- ``communication``: an environment's link to its clients (``start_server``; ``run`` hosts
  an environment itself, in ``serving/self_hosting.py``);
- ``testing``: fakes and clocks for tests (the ``rlenv`` command is the tools', ``rlenv_tools``);
- ``scene2d/``: the 2D scene: Node2D and Marker2D, pymunk physics nodes, drawing, cameras,
  procedural building (lattices, gradients, packed scenes);
- ``protocol/``: the wire (sans-IO codec, messages, connection; spaces, errors), shared with
  ``rlenv_client``;
- ``serving/``: the path a request takes through a server (endpoint, host, parts, instance).

Names are imported lazily, so that ``import rlenv.protocol`` (what the client does) loads
neither the runtime nor pymunk.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from rlenv._deprecation import forward
from rlenv._moves import MOVES

__version__ = "0.1.0"
"""The package's version: its one place (pyproject.toml reads it; ``rlenv_client.__version__`` is
this one; CHANGELOG.md). The protocol's version is another: ``rlenv.protocol``."""

_EXPORTS = {
    "Node": "rlenv.node",
    "NodeNotFoundError": "rlenv.node",
    "ProcessMode": "rlenv.node",
    "Signal": "rlenv.signals",
    "SceneTree": "rlenv.tree",
    "PhysicsFramesTimer": "rlenv.timer",
    "PhysicsWorld": "rlenv.scene2d.physics",
    "RigidBody": "rlenv.scene2d.physics",
    "StaticBody": "rlenv.scene2d.physics",
    "KinematicBody": "rlenv.scene2d.physics",
    "CollisionShape": "rlenv.scene2d.physics",
    "Joint": "rlenv.scene2d.physics",
    "RLAgent": "rlenv.agent",
    "RLAgentGroup": "rlenv.agent_group",
    "RLEnvWorld": "rlenv.world",
    "LevelWorld": "rlenv.levels",
    "RLEnvironment": "rlenv.environment",
    "Server": "rlenv.serving.server",
    "Communication": "rlenv.communication",
    "run": "rlenv.serving.self_hosting",
    "Camera": "rlenv.scene2d.camera",
    "View": "rlenv.views",
    "view": "rlenv.views",
    "Node2D": "rlenv.scene2d.node2d",
    "Marker2D": "rlenv.scene2d.marker2d",
    "RaycastSensor2D": "rlenv.scene2d.raycast_sensor",
    "PackedScene": "rlenv.scene2d.packed_scene",
    "PackedSceneError": "rlenv.scene2d.packed_scene",
    "gradient": "rlenv.scene2d.colors",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'rlenv' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


if TYPE_CHECKING:
    from rlenv.agent import RLAgent as RLAgent
    from rlenv.agent_group import RLAgentGroup as RLAgentGroup
    from rlenv.communication import Communication as Communication
    from rlenv.environment import RLEnvironment as RLEnvironment
    from rlenv.levels import LevelWorld as LevelWorld
    from rlenv.node import Node as Node
    from rlenv.node import NodeNotFoundError as NodeNotFoundError
    from rlenv.node import ProcessMode as ProcessMode
    from rlenv.scene2d.camera import Camera as Camera
    from rlenv.scene2d.colors import gradient as gradient
    from rlenv.scene2d.marker2d import Marker2D as Marker2D
    from rlenv.scene2d.node2d import Node2D as Node2D
    from rlenv.scene2d.packed_scene import PackedScene as PackedScene
    from rlenv.scene2d.packed_scene import PackedSceneError as PackedSceneError
    from rlenv.scene2d.physics import CollisionShape as CollisionShape
    from rlenv.scene2d.physics import Joint as Joint
    from rlenv.scene2d.physics import KinematicBody as KinematicBody
    from rlenv.scene2d.physics import PhysicsWorld as PhysicsWorld
    from rlenv.scene2d.physics import RigidBody as RigidBody
    from rlenv.scene2d.physics import StaticBody as StaticBody
    from rlenv.scene2d.raycast_sensor import RaycastSensor2D as RaycastSensor2D
    from rlenv.serving.self_hosting import run as run
    from rlenv.serving.server import Server as Server
    from rlenv.signals import Signal as Signal
    from rlenv.timer import PhysicsFramesTimer as PhysicsFramesTimer
    from rlenv.tree import SceneTree as SceneTree
    from rlenv.views import View as View
    from rlenv.views import view as view
    from rlenv.world import RLEnvWorld as RLEnvWorld

# Moved modules keep their old names, with a warning, for one release.
forward(MOVES)
