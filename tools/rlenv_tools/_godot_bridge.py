"""An rlenv server in a Godot game's part, for Godot RL Agents' trainer (``rlenv godot-rl``).

The bridge dials into godot-rl's trainer, as a Godot game's ``Sync`` node does, and answers its
messages (``handshake``, ``env_info``, ``reset``, ``action``, ``call``, ``close``) by driving
an rlenv server through :class:`~rlenv_client.client.Client`, as any client would. Every agent
of every instance of the server is one AIController, instance by instance, agents in the
hello's order (driven agents left out).

What godot-rl's wire has no room for, and what the bridge does about it:

- An episode's end: the trainer gets ``done`` true once, with the first observation of the
  next episode (the instance is reset at once, as a vector environment autoresets), and the
  AIController's ``info`` carries ``terminal_observation`` (the observation the episode ended
  on, in the form of ``obs``) and ``TimeLimit.truncated`` (truncated, not terminated), the keys
  Stable-Baselines3 bootstraps from. godot-rl's own ``step`` copies ``done`` into both its
  terminated and truncated; ``info`` is the only place the difference survives.
- Several agents: an agent whose episode ended before the others' reports ``done`` at that
  step; until the joint episode ends it reports reward 0, not done, and its last observation
  (godot-rl has no agent that sits out).
- Seeds: the first reset of instance ``i`` is seeded ``env_seed * instances + i``, so the
  processes of ``n_parallel`` (seeded ``seed + p``) play disjoint seeds; later resets go on
  from there, as gymnasium's do.
- ``call``: rlenv's agents run in the server, out of a client's reach; every AIController
  answers ``null``.
"""

from __future__ import annotations

import logging
import socket
import time
from collections.abc import Mapping, Sequence
from typing import Any

from gymnasium import spaces

from rlenv_client.client import Client
from rlenv_client.time_limits import truncate_agents
from rlenv_tools._godot_wire import (
    AgentWire,
    GodotWireError,
    agent_wire,
    read_message,
    send_message,
)

__all__ = ["GODOT_RL_VERSION", "GodotBridge", "dial_trainer"]

logger = logging.getLogger(__name__)

GODOT_RL_VERSION = ("0", "7")
"""The handshake's ``major_version`` and ``minor_version`` that godot-rl 0.8 and its plugin send."""

_RETRY = 0.1  # seconds between attempts to reach a trainer that is not listening yet


def dial_trainer(host: str, port: int, timeout: float) -> socket.socket:
    """A connection to godot-rl's trainer at ``host:port``, tried until ``timeout`` seconds.

    The trainer may not be listening yet (godot-rl starts the game first): a refused connection
    is tried again until the deadline.

    Raises:
        ConnectionRefusedError: nothing listened there within ``timeout``.
    """
    deadline = time.monotonic() + timeout
    while True:
        try:
            sock = socket.create_connection((host, port), timeout=timeout)
        except ConnectionRefusedError:
            if time.monotonic() >= deadline:
                raise ConnectionRefusedError(
                    f"no godot-rl trainer listens on {host}:{port} (tried for {timeout:g} s)"
                ) from None
            time.sleep(_RETRY)
            continue
        sock.settimeout(None)  # a trainer may think (train) for as long as it likes
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return sock


class GodotBridge:
    """Answers one godot-rl trainer's messages with an rlenv server's instances.

    Args:
        client: a client of the server; its instances are played at once.
        trainer: the connection to the trainer (see :func:`dial_trainer`).
        env_seed: seeds the first reset of each instance (see the module docstring); ``None``:
            unseeded.
        repeat_action: physics ticks per action (``--action_repeat``); ``None``: the server's.
        max_episode_steps: a time limit kept here (a registered id's), which truncates.

    Raises:
        GodotWireError: an agent has spaces godot-rl cannot carry.
    """

    def __init__(
        self,
        client: Client,
        trainer: socket.socket,
        *,
        env_seed: int | None = None,
        repeat_action: int | None = None,
        max_episode_steps: int | None = None,
    ) -> None:
        self.client = client
        self.trainer = trainer
        self.env_seed = env_seed
        self.repeat_action = repeat_action
        self.max_episode_steps = max_episode_steps
        hello = client.hello
        self.instances = hello.instances
        self.several = len(hello.agents) > 1
        self.agents = tuple(name for name in hello.agents if name not in hello.driven)
        self.wires: dict[str, AgentWire] = {
            name: agent_wire(*self._spaces(name)) for name in self.agents
        }
        self._seeded = False
        self._observations: list[Any] = [None] * self.instances
        self._steps = [0] * self.instances
        self._ended: list[set[str]] = [set() for _ in range(self.instances)]

    @property
    def controllers(self) -> int:
        """How many AIControllers the trainer sees: agents times instances."""
        return len(self.agents) * self.instances

    def serve(self) -> None:
        """Answer the trainer until it says ``close`` or hangs up.

        Raises:
            GodotWireError: the trainer sent something godot-rl's trainer never sends (the
                message says what).
            RemoteError: the server refused a request.
        """
        handshake = read_message(self.trainer)
        if handshake is None:
            return
        self._check_handshake(handshake)
        while (message := read_message(self.trainer)) is not None:
            kind = message["type"]
            if kind == "close":
                logger.info("the trainer said close")
                return
            send_message(self.trainer, self._answer(kind, message))

    def _answer(self, kind: str, message: Mapping[str, Any]) -> dict[str, Any]:
        """The reply to one message of the trainer's."""
        if kind == "env_info":
            return self.env_info()
        if kind == "reset":
            return {"type": "reset", "obs": self.reset(), "info": [{}] * self.controllers}
        if kind == "action":
            return {"type": "step", **self.step(message.get("action"))}
        if kind == "call":
            return {"type": "call", "returns": [None] * self.controllers}
        raise GodotWireError(
            f"a message of type {kind!r}: godot-rl's trainer sends handshake, env_info, reset, "
            "action, call and close"
        )

    def _check_handshake(self, message: Mapping[str, Any]) -> None:
        if message["type"] != "handshake":
            raise GodotWireError(f"the trainer began with {message['type']!r}, not a handshake")
        version = (message.get("major_version"), message.get("minor_version"))
        if version != GODOT_RL_VERSION:
            logger.warning(
                "the trainer speaks godot-rl's wire %s.%s; this bridge speaks %s.%s",
                *version,
                *GODOT_RL_VERSION,
            )

    def env_info(self) -> dict[str, Any]:
        """The ``env_info`` reply: every AIController's spaces and policy name."""
        wires = [self.wires[name] for _ in range(self.instances) for name in self.agents]
        shared = len({repr((w.observation_space, w.action_space)) for w in wires}) == 1
        return {
            "type": "env_info",
            "observation_space": [wire.observation_space for wire in wires],
            "action_space": [wire.action_space for wire in wires],
            "n_agents": self.controllers,
            "agent_policy_names": [
                "shared_policy" if shared else name
                for _ in range(self.instances)
                for name in self.agents
            ],
        }

    def reset(self) -> list[dict[str, Any]]:
        """Reset every instance; every AIController's observation."""
        self._reset(range(self.instances))
        return [
            self._observed(instance, name)
            for instance in range(self.instances)
            for name in self.agents
        ]

    def step(self, actions: Any) -> dict[str, list[Any]]:
        """Run one action of every AIController: the ``step`` reply's lists.

        Raises:
            GodotWireError: ``actions`` is not one action map per AIController.
        """
        if not isinstance(actions, list) or len(actions) != self.controllers:
            raise GodotWireError(
                f"an action message needs a list of {self.controllers} action maps (one per "
                f"AIController), got {type(actions).__name__} of "
                f"{len(actions) if isinstance(actions, list) else 'no'} entries"
            )
        if not self._seeded:
            self._reset(range(self.instances))  # a game steps from where it is: a first episode
        width = len(self.agents)
        requests = [
            self.client.step_request(
                self._action(actions[instance * width : (instance + 1) * width]),
                self.repeat_action,
            )
            for instance in range(self.instances)
        ]
        self.client.send_batch(requests)
        replies = self.client.receive_batch()
        reply: dict[str, list[Any]] = {"obs": [], "reward": [], "done": [], "info": []}
        ended = []
        outcomes = []
        for instance, answer in enumerate(replies):
            assert answer is not None
            observation, reward, terminated, truncated, info = self.client.step_result(answer)
            self._observations[instance] = observation
            self._steps[instance] += 1
            if self._timed_out(instance) and not (terminated or truncated):
                truncated, info = True, truncate_agents(info)
            outcomes.append(self._outcomes(reward, terminated, truncated, info))
            if terminated or truncated:
                ended.append(instance)
        finals = {
            instance: {name: self._observed(instance, name) for name in self.agents}
            for instance in ended
        }
        sitting_out = [set(names) for names in self._ended]  # ended before the others
        self._reset(ended)
        for instance, outcome in enumerate(outcomes):
            for name in self.agents:
                if name in sitting_out[instance]:
                    outcome[name] = (0.0, False, False)
                final = finals[instance][name] if instance in finals else None
                report = self._report(instance, name, outcome[name], final)
                for key, value in zip(reply, report, strict=True):
                    reply[key].append(value)
        return reply

    def _report(
        self,
        instance: int,
        name: str,
        outcome: tuple[float, bool, bool],
        final: dict[str, Any] | None,
    ) -> tuple[dict[str, Any], float, bool, dict[str, Any]]:
        """One AIController's ``(obs, reward, done, info)`` after a step.

        ``final`` is its observation at the end of an episode whose instance was reset since
        (``None`` if it was not: then an agent that ended sits out until the others end).
        """
        reward, terminated, truncated = outcome
        observed = self._observed(instance, name)
        if not (terminated or truncated):
            return observed, float(reward), False, {}
        if final is None:
            self._ended[instance].add(name)
        ending = {
            "terminal_observation": observed if final is None else final,
            "TimeLimit.truncated": truncated and not terminated,
        }
        return observed, float(reward), True, ending

    def _action(self, actions: Sequence[Any]) -> Any:
        """One instance's action from its AIControllers' action maps."""
        per_agent = {
            name: self.wires[name].act(action)
            for name, action in zip(self.agents, actions, strict=True)
        }
        return per_agent if self.several else per_agent[self.agents[0]]

    def _outcomes(
        self, reward: float, terminated: bool, truncated: bool, info: Mapping[str, Any]
    ) -> dict[str, tuple[float, bool, bool]]:
        """Each agent's ``(reward, terminated, truncated)`` in one step."""
        if not self.several:
            return {self.agents[0]: (reward, terminated, truncated)}
        agents = info["agents"]
        return {
            name: (agents[name]["reward"], agents[name]["terminated"], agents[name]["truncated"])
            for name in self.agents
        }

    def _timed_out(self, instance: int) -> bool:
        return (
            self.max_episode_steps is not None and self._steps[instance] >= self.max_episode_steps
        )

    def _reset(self, instances: Sequence[int] | range) -> None:
        """Reset these instances (seeded the first time, see the module docstring)."""
        if not instances:
            return
        chosen = set(instances)
        requests = [
            self.client.reset_request(self._seed(instance)) if instance in chosen else None
            for instance in range(self.instances)
        ]
        self._seeded = True
        self.client.send_batch(requests)
        for instance, answer in enumerate(self.client.receive_batch()):
            if instance in chosen:
                assert answer is not None
                self._observations[instance], _ = self.client.reset_result(answer)
                self._steps[instance] = 0
                self._ended[instance].clear()

    def _seed(self, instance: int) -> int | None:
        if self._seeded or self.env_seed is None:
            return None
        return self.env_seed * self.instances + instance

    def _observed(self, instance: int, name: str) -> dict[str, Any]:
        """Agent ``name``'s observation in ``instance``, as its AIController's ``get_obs``."""
        observation = self._observations[instance]
        return self.wires[name].observe(observation[name] if self.several else observation)

    def _spaces(self, name: str) -> tuple[Any, Any]:
        hello = self.client.hello
        if not self.several:
            return hello.observation_space, hello.action_space
        observations, actions = hello.observation_space, hello.action_space
        assert isinstance(observations, spaces.Dict) and isinstance(actions, spaces.Dict)
        return observations[name], actions[name]
