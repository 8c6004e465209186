"""An environment written from the Godot seed's RLEnvironment page: every hook overridden.

``python tests/seed_hooks.py PORT`` hosts it (``rlenv.run``); ``rlenv serve
seed_hooks:HookedEnvironment`` serves it (with ``tests/`` on ``PYTHONPATH``). Every hook adds
its name to :attr:`HookedEnvironment.calls`, which ``info["calls"]`` reports, so a client sees
which hooks ran, and in what order.

``seed_hooks:SilentEnvironment`` overrides ``_on_got_connection`` without calling ``super()``;
``seed_hooks:StubbornEnvironment``'s ``_after_send_response`` raises after its second answer.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

import rlenv
from rlenv import RLAgent, RLEnvironment, RLEnvWorld


class Track(RLEnvWorld):
    """A point on a line; ``friction`` is configurable."""

    configurable = ("friction",)

    def __init__(self) -> None:
        super().__init__("World")
        self.friction = 0.0
        self.x = 0.0

    def reset(self, options: Mapping[str, Any]) -> None:
        """Back to 0."""
        self.x = 0.0

    def sample_initial_position(self) -> float:
        """Where the runner starts (seeded)."""
        return float(self.np_random.uniform(-1.0, 1.0))

    def get_data(self, observation_request: Mapping[str, Any]) -> dict[str, Any]:
        """Where the point is."""
        return {"x": self.x}


class Runner(RLAgent):
    """Moves the point by ``gain * action`` per second."""

    configurable = ("gain",)
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
    observation_space = spaces.Box(-1e6, 1e6, (2,), np.float32)

    def __init__(self) -> None:
        super().__init__("Agent")
        self.gain = 1.0
        self.speed = 0.0
        self.start = 0.0

    def reset(self, arguments: Any) -> None:
        """Start where the world says."""
        self.start, self.speed = float(arguments), 0.0
        self.environment.world.x = self.start

    def set_action(self, action: Any) -> None:
        """The speed for the ticks of this action."""
        self.speed = float(action[0]) * self.gain

    def _physics_process(self, delta: float) -> None:
        self.environment.world.x += self.speed * delta

    def _after_physics_tick(self, delta: float) -> None:
        self.add_reward(1.0)

    def get_data(self, observation_request: Mapping[str, Any]) -> np.ndarray:
        """Position and start."""
        return np.array([self.environment.world.x, self.start], np.float32)


class HookedEnvironment(RLEnvironment):
    """The seed's environment, with every hook overridden (each calls ``super()``)."""

    def __init__(self, port: int | None = None) -> None:
        super().__init__("Hooked", repeat_action=2)
        self.port = int(os.environ.get("SEED_HOOKS_PORT", 9090)) if port is None else port
        self.calls: list[str] = []
        self.add_child(Runner())
        self.add_child(Track())

    def _ready(self) -> None:
        self.world = self.get_node("World")
        self.agent = self.get_node("Agent")
        self.communication.start_server(self.port, "127.0.0.1")

    def _on_got_connection(self, request: dict[str, Any]) -> None:
        self.calls.append("_on_got_connection:" + ",".join(request))
        super()._on_got_connection(request)

    def _configure(self, configuration_request: Mapping[str, Any]) -> None:
        self.calls.append("_configure:" + ",".join(configuration_request))
        super()._configure(configuration_request)

    def _reset(self, options: Mapping[str, Any]) -> None:
        self.calls.append("_reset")
        super()._reset(options)

    def _step(self, action: Any, frames: int | None = None) -> None:
        self.calls.append(f"_step:{frames}")
        super()._step(action, frames)

    def _send_response(self, observation_request: Mapping[str, Any] | None) -> None:
        self.calls.append("_send_response:" + ",".join(observation_request or ["-"]))
        super()._send_response(observation_request)

    def _after_send_response(self) -> None:
        self.calls.append("_after_send_response")

    def _get_info(self) -> dict[str, Any]:
        return {"calls": list(self.calls)}


class SilentEnvironment(HookedEnvironment):
    """Forgets to call ``super()._on_got_connection``: its requests get no answer of theirs."""

    def _on_got_connection(self, request: dict[str, Any]) -> None:
        self.calls.append("ignored")


class StubbornEnvironment(HookedEnvironment):
    """``_after_send_response`` raises after the second answer."""

    def _after_send_response(self) -> None:
        super()._after_send_response()
        if self.calls.count("_after_send_response") == 2:
            raise RuntimeError("the trail would not clear")


if __name__ == "__main__":
    rlenv.run(HookedEnvironment(int(sys.argv[1])))
