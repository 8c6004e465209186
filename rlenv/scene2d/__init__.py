"""The 2D scene: pymunk physics as nodes, and what places, builds, draws, films and queries it.

- :mod:`~rlenv.scene2d.node2d`: Node2D, a node placed relative to the Node2D above it;
- :mod:`~rlenv.scene2d.marker2d`: Marker2D, a mounting point copies are attached to;
- :mod:`~rlenv.scene2d.raycast_sensor`: RaycastSensor2D, rays and the distances to what they hit;
- :mod:`~rlenv.scene2d.physics`: the world (a pymunk space), bodies, collision shapes, joints;
- :mod:`~rlenv.scene2d.lattice`, :mod:`~rlenv.scene2d.colors`: copies along a pattern, and
  colours and gradients;
- :mod:`~rlenv.scene2d.packed_scene` (with :mod:`~rlenv.scene2d._scene_codecs` and
  :mod:`~rlenv.scene2d._pymunk_data`): subtrees as plain data and back;
- :mod:`~rlenv.scene2d.render`: frames and vector draw lists of the pymunk shapes (numpy only);
- :mod:`~rlenv.scene2d.camera`: a camera node whose frames can be observations, and films;
- :mod:`~rlenv.scene2d.recording`: writing frames to a video file.

Querying a built tree (``view``) is not 2D: :mod:`rlenv.views`.
"""
