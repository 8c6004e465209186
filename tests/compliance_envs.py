"""Environments for the compliance suite's own tests (``rlenv serve compliance_envs:...``).

- :class:`DriftingEnvironment`: breaks the contract on purpose: every reset starts a new count
  of episodes that the observation shows, so the same seed never gives the same episode twice,
  and neither a reset after a set nor a restore replays a trajectory. It exports a writable
  float (``Agent:gain``), so the suite's set and restore probes run, and must fail.
- :class:`GainPairEnvironment`: the Pair environment whose two agents each have a setting, for
  the inspector's per-agent edits.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from examples.faulty import CountingWorld
from examples.pair import NAMES, PairAgent, PairEnvironment, PairWorld
from rlenv.agent import RLAgent
from rlenv.environment import RLEnvironment


class DriftingAgent(RLAgent):
    """Observes how many episodes began (never reset: the bug) and ``gain`` times the ticks."""

    exported = ("gain",)
    action_space = spaces.Discrete(2)
    observation_space = spaces.Box(-1e9, 1e9, (2,), np.float64)

    def __init__(self) -> None:
        super().__init__("Agent")
        self.gain = 1.0
        self.episodes = 0

    def reset(self, arguments: Any) -> None:
        """Count one more episode: this count survives every reset."""
        self.episodes += 1

    def set_action(self, action: Any) -> None:
        """Actions change nothing."""

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Episodes begun so far, and ``gain`` times the ticks of this one."""
        world = self.environment.world
        assert isinstance(world, CountingWorld)
        return np.array([self.episodes, self.gain * world.ticks], dtype=np.float64)


class DriftingEnvironment(RLEnvironment):
    """An environment whose episodes depend on how many came before."""

    def __init__(self) -> None:
        super().__init__("Drifting", repeat_action=2)
        self.add_child(DriftingAgent())
        self.add_child(CountingWorld())


class GainAgent(PairAgent):
    """A Pair agent with a setting of its own (``gain``), for per-agent edits."""

    configurable = ("gain",)

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.gain = 1.0


class GainPairEnvironment(PairEnvironment):
    """The Pair environment with :class:`GainAgent` s: several agents, each configurable."""

    def __init__(self) -> None:
        RLEnvironment.__init__(self, "Pair", repeat_action=4)
        for name in NAMES:
            self.add_child(GainAgent(name))
        self.add_child(PairWorld())
