"""The 2D scene: pymunk physics as nodes, and what draws, films and queries it.

- :mod:`~rlenv.scene2d.physics`: the world (a pymunk space), bodies, collision shapes, joints;
- :mod:`~rlenv.scene2d.render`: frames and vector draw lists of the pymunk shapes (numpy only);
- :mod:`~rlenv.scene2d.camera`: a camera node whose frames can be observations, and films;
- :mod:`~rlenv.scene2d.recording`: writing frames to a video file;
- :mod:`~rlenv.scene2d.views`: querying a built tree, and reading or setting many nodes at once.
"""
