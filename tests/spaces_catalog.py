"""Gymnasium spaces shared by the space and protocol tests.

Every space here is one rlenv claims to carry on the wire. Import as
``from spaces_catalog import TESTING_SPACES`` (pytest puts ``tests/`` on ``sys.path``).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

TESTING_SPACES: list[spaces.Space] = [
    # Box
    spaces.Box(low=-1.0, high=2.0, shape=(3,), dtype=np.float32),
    spaces.Box(
        low=np.array([-np.inf, 0.0, -5.0]), high=np.array([np.inf, np.inf, 5.0]), dtype=np.float64
    ),
    spaces.Box(low=-np.inf, high=np.inf, shape=(2, 2), dtype=np.float64),
    spaces.Box(low=np.array([-3, 0]), high=np.array([3, 10]), dtype=np.int64),
    spaces.Box(low=-7, high=7, shape=(4,), dtype=np.int32),
    spaces.Box(low=0, high=255, shape=(84, 84, 3), dtype=np.uint8),
    spaces.Box(low=-1.0, high=1.0, shape=(), dtype=np.float32),
    # Discrete
    spaces.Discrete(5),
    spaces.Discrete(3, start=-1),
    spaces.Discrete(4, dtype=np.int32),
    # MultiDiscrete
    spaces.MultiDiscrete([3, 4, 2]),
    spaces.MultiDiscrete(np.array([5, 2]), start=np.array([-2, 10])),
    spaces.MultiDiscrete(np.array([[2, 3], [4, 5]])),
    # MultiBinary
    spaces.MultiBinary(6),
    spaces.MultiBinary([2, 3]),
    # Tuple
    spaces.Tuple((spaces.Discrete(4), spaces.Box(-1.0, 1.0, (2,), np.float32))),
    # Dict
    spaces.Dict(
        {
            "pos": spaces.Box(-10.0, 10.0, (2,), np.float32),
            "gear": spaces.Discrete(3, start=1),
            "switches": spaces.MultiBinary([2, 2]),
        }
    ),
    # nested: Dict inside Tuple, and Tuple inside that Dict
    spaces.Tuple(
        (
            spaces.Dict(
                {
                    "arm": spaces.Box(-1.0, 1.0, (3,), np.float64),
                    "grip": spaces.Tuple((spaces.Discrete(2), spaces.MultiDiscrete([2, 3]))),
                }
            ),
            spaces.Discrete(7),
        )
    ),
]
