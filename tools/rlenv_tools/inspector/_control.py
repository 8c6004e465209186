"""A person's control of an environment from the inspector's page: demonstrations.

The page's "Take control" asks :meth:`Demonstrator.take`: a connection of its own (not the
watcher's observer connections) resets the chosen instance, which takes control as any
trainer's reset would, so it is refused (``busy``) while another client controls the server.
A thread then steps the instance at the environment's real-time rate (its physics ticks a
second over the ticks an action runs; or a fixed rate) with the action of the keys the person
holds (:meth:`Demonstrator.hold`, the page sends them at every press and release; no key held:
the idle action, see :func:`held_action`), and records every episode
into the directory given at the start, as :class:`~rlenv_client.replay.RecordEpisodes` would.
"Release" (:meth:`Demonstrator.release`) drops the episode under way and closes the
connection, which frees control. The keys are the agent's ``demonstration_keys`` (see
:mod:`rlenv.demonstration_keys`), read from the server's node tree.

With several agents the person chooses the one to play (``agent``; needed when more than one
may be played). The others keep what drives them: the agents the server drives (``rlenv serve
--policy``: a policy file or their heuristic) go on by themselves; each other agent whose class
has a ``heuristic`` plays it (the step's ``heuristic`` part, protocol 2.6), and the rest take
their idle action. The recorded files say which agent the person played
(``EpisodeFile.agent``, see :class:`~rlenv_client.replay.EpisodeFile`).

While a trainer controls an environment of several agents, the reset is refused ``busy`` and
the person **claims** the chosen agent instead (protocol 2.6, :mod:`rlenv.serving._claims`): the
thread then holds the keys' action for it (a ``claim`` request whenever it changes) and the
trainer's steps play it, while the trainer acts for the others. The recorded files are then the
trainer's episodes, as it played them (from the server's recent episodes, see
:meth:`~rlenv_client.inspection.Inspection.episodes`): each one that ends while the person
plays, the one under way at Take control included, with ``agent`` naming the person's agent
and no observation digests (the inspector does not see the trainer's observations); each
replays bit for bit from its snapshot. "Release" ends the claim, and the agent is the
trainer's again.
"""

from __future__ import annotations

import functools
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv.protocol import ErrorReply, Request, Response
from rlenv.protocol.errors import RemoteError
from rlenv.protocol.spaces import codec_for
from rlenv_client._addresses import parse_address
from rlenv_client.client import Client
from rlenv_client.inspection import fetch_episodes
from rlenv_client.replay import EpisodeFile, digest, next_episode_path
from rlenv_client.session import LOST
from rlenv_tools.inspector._watch import InspectorError, Watcher, to_json

__all__ = ["Demonstrator", "held_action", "idle_action", "key_map"]


class _Control:
    """One taken instance: its connection, the agent played, key map, held keys, the thread."""

    def __init__(self, client: Client, server: int, instance: int, keys: dict[str, Any]) -> None:
        self.client = client
        self.server = server
        self.instance = instance
        self.keys = keys
        self.agent: str | None = None  # the agent played, with several
        self.space: spaces.Space = client.hello.action_space  # the played agent's
        self.idle: dict[str, Any] = {}  # the other agents' idle actions, by name
        self.heuristic: list[str] = []  # the other agents that play their heuristic
        self.held: list[str] = []
        self.claim = False  # the person plays a claimed agent beside a trainer (2.6)
        self.stop = threading.Event()
        self.thread: threading.Thread | None = None

    def step_parts(self, action: Any) -> dict[str, Any]:
        """The parts of a step that plays ``action`` for the person's agent."""
        client = self.client
        if self.agent is None:
            return client.step_request(action).parts
        parts = client.step_request({**self.idle, self.agent: action}).parts
        if self.heuristic:
            parts["heuristic"] = self.heuristic
        return parts

    def send_claim(self, action: Any) -> None:
        """Claim the person's agent (protocol 2.6), or change its held action, to ``action``."""
        packed = codec_for(self.space).pack_exact(action)
        _answer(self.exchange({"claim": {"agent": self.agent, "action": packed}}))

    def exchange(self, parts: Mapping[str, Any]) -> Response | ErrorReply:
        """One request to this instance (in a batch when the server hosts several)."""
        count = self.client.hello.instances
        if count == 1:
            self.client.send_request(Request(0, dict(parts)))
            return self.client.receive_reply()
        self.client.send_batch([None] * self.instance + [Request(0, dict(parts))])
        reply = self.client.receive_batch()[self.instance]
        assert reply is not None
        return reply


class Demonstrator:
    """Takes control of a watched environment for a person and records their episodes.

    Args:
        watcher: the inspector's observer connections (for the servers' addresses).
        directory: where the ``episode-NNNN.rlenv`` files go (created if missing).
        target: the environment's ``MODULE:CLASS``, written into each file (``rlenv replay``
            then needs no ``--target``).
        rate: actions a second; ``None``: the environment's real-time rate.
        token: the servers' secret, if they need one (default ``$RLENV_TOKEN``).
    """

    def __init__(
        self,
        watcher: Watcher,
        directory: str | Path,
        *,
        target: str | None = None,
        rate: float | None = None,
        token: str | None = None,
    ) -> None:
        if rate is not None and not rate > 0:
            raise ValueError(f"the demonstration rate must be > 0 actions a second, got {rate}")
        self.watcher = watcher
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.target = target
        self.rate = rate
        self.episodes = 0
        self.error = ""
        self._token = token
        self._lock = threading.Lock()
        self._control: _Control | None = None

    def status(self) -> dict[str, Any]:
        """What the page shows: who controls, the keys, the episodes recorded, the last error."""
        with self._lock:
            control = self._control
            running = control is not None and not control.stop.is_set()
            return {
                "controlling": running,
                "server": control.server if running else None,  # type: ignore[union-attr]
                "instance": control.instance if running else None,  # type: ignore
                "agent": control.agent if running else None,  # type: ignore[union-attr]
                "heuristic": list(control.heuristic) if running else [],  # type: ignore
                "claim": control.claim if running else False,  # type: ignore[union-attr]
                "keys": sorted(control.keys) if running else [],  # type: ignore[union-attr]
                "held": list(control.held) if running else [],  # type: ignore[union-attr]
                "episodes": self.episodes,
                "directory": str(self.directory),
                "error": self.error,
            }

    def take(self, server: int, instance: int, agent: str | None = None) -> dict[str, Any]:
        """Take control of ``instance`` of ``server`` and play ``agent`` (see the module).

        ``agent`` may be left out when only one agent can be played.

        Raises:
            InspectorError: 409 already controlling, or another client controls it (with one
                agent; with several, the person claims the agent, see the module) or claimed
                the agent; 422 its agent has no key map, no ``agent`` was chosen among several,
                or the one chosen is driven by the server; 404 no such server, instance or
                agent; 503 unreachable.
        """
        with self._lock:
            if self._control is not None and not self._control.stop.is_set():
                raise InspectorError(409, "already in control: release first")
            self._release_locked()
            address = self.watcher.address(server)
            try:
                client = Client(*parse_address(address), token=self._token)
            except (RemoteError, *LOST) as error:
                raise InspectorError(503, f"{address}: {error}") from None
            try:
                control = self._start(client, server, instance, agent)
            except BaseException:
                client.close()
                raise
            self._control, self.error = control, ""
        return self.status()

    def hold(self, held: Sequence[str]) -> dict[str, Any]:
        """The keys the person holds now, oldest first (keys outside the map are ignored).

        Raises:
            InspectorError: 409 not in control.
        """
        with self._lock:
            control = self._control
            if control is None or control.stop.is_set():
                raise InspectorError(409, "not in control: take control first")
            control.held = [key for key in dict.fromkeys(held) if key in control.keys]
        return self.status()

    def release(self) -> dict[str, Any]:
        """Stop playing and give control back (the episode under way is not recorded)."""
        with self._lock:
            self._release_locked()
        return self.status()

    def close(self) -> None:
        """Release control, if held; safe to repeat."""
        self.release()

    # --- taking, stepping ---------------------------------------------------------------------

    def _start(self, client: Client, server: int, instance: int, agent: str | None) -> _Control:
        hello = client.hello
        count = hello.instances
        if not 0 <= instance < count:
            raise InspectorError(404, f"server {server} has {count} instances, not {instance + 1}")
        control = _Control(client, server, instance, {})
        tree = _answer(control.exchange({"inspect": {"tree": {}}})).info["tree"]
        if len(hello.agents) > 1:
            _choose(control, tree, agent)
        elif agent is not None and agent not in hello.agents:
            raise InspectorError(404, f"no agent {agent!r:.40}: the agent is {hello.agents[0]}")
        control.keys = key_map(tree, control.space, control.agent)
        idle = idle_action(control.space)  # refuses a space without one now
        rate = self.rate or hello.physics_ticks_per_second / hello.repeat_action
        reply = control.exchange(client.reset_request().parts)
        if isinstance(reply, ErrorReply) and reply.code == "busy" and control.agent is not None:
            control.claim = True  # a trainer controls it: play the agent beside it
            kept: dict[int, EpisodeFile] = {}  # the server keeps them from now on
            fetch_episodes(
                lambda part: _answer(control.exchange({"episodes": part})), hello, cache=kept
            )
            control.send_claim(idle)  # refused here: 409 claimed by another, 422 otherwise
            play: Callable[[], None] = functools.partial(
                self._play_beside, control, idle, rate, kept
            )
        else:
            observation, _ = client.reset_result(_answer(reply))
            play = functools.partial(self._play, control, observation, rate)
        control.thread = threading.Thread(target=play, name="rlenv-demonstration", daemon=True)
        control.thread.start()
        return control

    def _play(self, control: _Control, observation: Any, rate: float) -> None:
        """Step at ``rate`` with the held keys' action; record each episode as it ends."""
        client, space = control.client, control.space
        seen = [digest(observation)]
        due = time.monotonic()
        try:
            while not control.stop.is_set():
                with self._lock:
                    actions = [control.keys[key] for key in control.held]
                observation, _, terminated, truncated, _ = client.step_result(
                    control.exchange(control.step_parts(held_action(space, actions)))
                )
                seen.append(digest(observation))
                if terminated or truncated:
                    snapshot = _answer(control.exchange({"snapshot": {}})).info["snapshot"]
                    with self._lock:
                        EpisodeFile(
                            self.target, snapshot, seen, terminated, truncated, agent=control.agent
                        ).save(next_episode_path(self.directory))
                        self.episodes += 1
                    observation, _ = client.reset_result(
                        control.exchange(client.reset_request().parts)
                    )
                    seen = [digest(observation)]
                due = max(due + 1.0 / rate, time.monotonic() - 1.0)  # no burst after a stall
                control.stop.wait(max(0.0, due - time.monotonic()))
        except (RemoteError, InspectorError, *LOST) as error:
            with self._lock:
                self.error = f"the demonstration stopped: {error}"
                control.stop.set()

    def _play_beside(
        self, control: _Control, idle: Any, rate: float, cache: dict[int, EpisodeFile]
    ) -> None:
        """Hold the keys' action for the claimed agent; record the trainer's episodes that end.

        The agent was claimed (with ``idle``) before the thread started, and ``cache`` holds
        the episodes kept then (not the person's). Every second the server's recent episodes
        are looked at, and each one that ended since is saved.
        """
        client, space = control.client, control.space

        def ask(part: dict[str, Any]) -> Response:
            return _answer(control.exchange({"episodes": part}))

        try:
            known = set(cache)
            held = sent = idle
            looked = time.monotonic()
            while not control.stop.is_set():
                if not np.array_equal(to_json(held), to_json(sent)):
                    control.send_claim(held)
                    sent = held
                if time.monotonic() - looked >= 1.0:
                    looked = time.monotonic()
                    fetch_episodes(ask, client.hello, cache=cache)
                    self._save_new(control, cache, known)
                control.stop.wait(1.0 / rate)
                with self._lock:
                    held = held_action(space, [control.keys[key] for key in control.held])
            _answer(control.exchange({"claim": None}))
        except (RemoteError, InspectorError, *LOST) as error:
            with self._lock:
                self.error = f"the demonstration stopped: {error}"
                control.stop.set()

    def _save_new(
        self, control: _Control, kept: Mapping[int, EpisodeFile], known: set[int]
    ) -> None:
        """Save each ``kept`` episode (by id) not ``known`` before, as the person's."""
        for identifier in sorted(kept.keys() - known):
            known.add(identifier)
            episode = kept[identifier]
            with self._lock:
                EpisodeFile(
                    self.target or episode.target,
                    episode.snapshot,
                    [],
                    episode.terminated,
                    episode.truncated,
                    agent=control.agent,
                ).save(next_episode_path(self.directory))
                self.episodes += 1

    def _release_locked(self) -> None:
        control, self._control = self._control, None
        if control is None:
            return
        control.stop.set()
        if control.thread is not None and control.thread is not threading.current_thread():
            self._lock.release()  # the thread may be waiting for it to record an episode
            try:
                control.thread.join()
            finally:
                self._lock.acquire()
        control.client.close()


def _answer(reply: Response | ErrorReply) -> Response:
    """``reply`` as a response, or the page's error (409 when another client controls)."""
    if isinstance(reply, ErrorReply):
        status = 409 if reply.code == "busy" else 422
        raise InspectorError(status, f"{reply.code}: {reply.message.splitlines()[0]}")
    return reply


def _choose(control: _Control, tree: Sequence[Mapping[str, Any]], agent: str | None) -> None:
    """Set the agent ``control`` plays among several, and what the others do.

    Raises:
        InspectorError: 422 none chosen among several, or a driven one; 404 no such agent.
    """
    hello = control.client.hello
    playable = [name for name in hello.agents if name not in hello.driven]
    if agent is None:
        if len(playable) != 1:
            raise InspectorError(
                422,
                f"this environment has {len(hello.agents)} agents: "
                f"choose the one to play ({', '.join(playable)})",
            )
        agent = playable[0]
    if agent not in hello.agents:
        raise InspectorError(404, f"no agent {agent!r:.40}; the agents: {', '.join(hello.agents)}")
    if agent in hello.driven:
        raise InspectorError(
            422,
            f"agent {agent!r} is driven by the server (rlenv serve "
            f"--policy); choose another: {', '.join(playable)}",
        )
    joint = hello.action_space
    assert isinstance(joint, spaces.Dict)
    nodes = _agent_nodes(tree)
    control.agent, control.space = agent, joint[agent]
    others = [name for name in playable if name != agent]
    control.heuristic = [name for name in others if nodes[name].get("heuristic")]
    control.idle = {
        name: idle_action(joint[name]) for name in others if name not in control.heuristic
    }


def _agent_nodes(tree: Sequence[Mapping[str, Any]]) -> dict[str, Mapping[str, Any]]:
    """The agents' nodes of an ``inspect tree``, by agent name (the last part of the path)."""
    return {
        str(node["path"]).rsplit("/", 1)[-1]: node for node in tree if node.get("config") == "agent"
    }


def key_map(
    tree: Sequence[Mapping[str, Any]], space: spaces.Space, agent: str | None = None
) -> dict[str, Any]:
    """The keys of ``agent`` (the only one if ``None``), as actions of its ``space``.

    The tree is ``inspect tree``'s (its agent nodes carry ``demonstration_keys``); the
    inspector's timelines branch with the same map (:mod:`~rlenv_tools.inspector._timelines`).

    Raises:
        InspectorError: 422, no agent named, among several, or one with no key map; 404 no
            such agent.
    """
    agents = _agent_nodes(tree)
    if agent is None:
        if len(agents) != 1:
            raise InspectorError(
                422,
                f"this environment has {len(agents)} agents: choose "
                f"the one to play ({', '.join(agents)})",
            )
        (node,) = agents.values()
    elif agent in agents:
        node = agents[agent]
    else:
        raise InspectorError(404, f"no agent {agent!r:.40}; the agents: {', '.join(agents)}")
    keys = {key: _action(space, value) for key, value in node.get("demonstration_keys", {}).items()}
    if not keys:
        raise InspectorError(
            422,
            f"demonstrations need a key map: {node['type']} "
            f"names no demonstration_keys for {space}",
        )
    return keys


def _action(space: spaces.Space, value: Any) -> Any:
    """A key's action as the tree gave it, made a value of ``space``."""
    if isinstance(space, spaces.Discrete):
        return int(value)
    if isinstance(space, spaces.Box | spaces.MultiDiscrete | spaces.MultiBinary):
        return np.asarray(to_json(value), dtype=space.dtype).reshape(space.shape)
    return value


def idle_action(space: spaces.Space) -> Any:
    """The action while no key is held: 0 (clipped into a ``Box``'s bounds), ``start``.

    ``Tuple`` and ``Dict`` spaces get their items' idle actions.

    Raises:
        ValueError: a space with no such action (a ``Text``, a ``Graph``...).
    """
    if isinstance(space, spaces.Discrete):
        return int(space.start)
    if isinstance(space, spaces.Box):
        return np.clip(np.zeros(space.shape), space.low, space.high).astype(space.dtype)
    if isinstance(space, spaces.MultiDiscrete):
        return np.array(space.start, dtype=space.dtype)
    if isinstance(space, spaces.MultiBinary):
        return np.zeros(space.shape, dtype=space.dtype)
    if isinstance(space, spaces.Tuple):
        return tuple(idle_action(item) for item in space.spaces)
    if isinstance(space, spaces.Dict):
        return {key: idle_action(item) for key, item in space.spaces.items()}
    raise ValueError(f"{space} has no idle action for demonstrations")


def held_action(space: spaces.Space, actions: Sequence[Any]) -> Any:
    """The action of the held keys' ``actions`` (oldest first), or the idle action.

    In a ``Box`` the keys add up (left and up: a diagonal), clipped into the bounds; in any
    other space the last pressed counts.
    """
    idle = idle_action(space)
    if not actions:
        return idle
    if isinstance(space, spaces.Box):
        total = idle + sum(np.asarray(action, space.dtype) - idle for action in actions)
        return np.clip(total, space.low, space.high).astype(space.dtype)
    return actions[-1]
