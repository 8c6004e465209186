"""Settings: what clients configure on one instance, and what the server handles itself.

A ``config`` part maps ``environment``, ``agent`` and ``world`` to settings of those nodes
(their ``configurable`` attributes). :class:`Settings` checks one whole before anything is
applied, applies it through the environment's ``_configure`` hook (by default to each node),
logs it for snapshots, and puts the previous values back when the request that applied it
fails.

The ``agent`` map sets every agent, one class of agents or one agent (:func:`agent_settings`):
a key that is a setting sets every agent; a key that is an agent class's name (``Runner``) maps
to settings of that class's agents, and an agent's name (``Runner1``) to settings of that
agent. Where they overlap, the more precise wins: every agent < class < name. The state a
snapshot keeps (:meth:`Settings.state`) has one agent's flat, several agents' by name.

``real_time`` and ``record`` are the server's own settings of the environment: the instance
switches real time; :class:`Settings` keeps the video recorder.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from operator import attrgetter
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.scene2d.recording import VideoRecorder
from rlenv.serving._actions import check_repeat_action
from rlenv.serving._agents_in_play import LOCKSTEP_ONLY, AgentsInPlay

if TYPE_CHECKING:
    from rlenv.serving._instance import Answer, Instance

__all__ = ["Captured", "Settings", "agent_settings", "check_keys"]

logger = logging.getLogger(__name__)

_PARTS = frozenset({"environment", "agent", "world"})
_VIDEO_SUFFIXES = frozenset({".mp4", ".webm", ".avi", ".mkv"})


class Settings:
    """The configuration of one instance (see the module docstring).

    Args:
        instance: the instance whose environment, agents and world are configured.
        record_dir: where clients may have the environment record videos (``None``: nowhere).

    Attributes:
        recorder: the video being recorded (``configure(record=...)``), one frame per tick.
    """

    def __init__(self, instance: Instance, record_dir: Path | None) -> None:
        self._instance = instance
        self.record_dir = record_dir
        self.recorder: VideoRecorder | None = None
        self._readers: _Readers | None = None  # how to capture, for the nodes as they are

    def check(self, config: Mapping[str, Any], recorded: bool = False) -> None:
        """Check a ``config`` part (every node it applies to) without applying it.

        A ``recorded`` one (a snapshot's, or the one a rebuilt environment carries) may name
        agents that may appear but are not in this tree: it sets those there are.

        Raises:
            RequestError: ``bad_request`` (its shape) or ``invalid_config`` naming the key.
        """
        check_keys(config, _PARTS, "config")
        for part in self._nodes():
            if part not in config:
                continue
            settings = config[part]
            if not isinstance(settings, Mapping):
                raise RequestError(ErrorCode.BAD_REQUEST, f"config.{part} must be a map")
            if part == "environment":
                settings = self._check_environment(settings)
            for node, own in self._reached(part, settings, recorded):
                try:
                    node.check_config(own)
                except RequestError as error:
                    if part != "agent" or not self._instance.multi_agent:
                        raise
                    raise RequestError(error.code, f"config.agent: {node.name}: {error}") from None

    def configure(self, config: Mapping[str, Any], recorded: bool = False) -> None:
        """Apply a checked ``config`` part through the environment's ``_configure``.

        The configuration it replaces is kept until the request is answered (a request that
        fails changes no setting); once applied it is logged for snapshots during an episode.
        """
        instance = self._instance
        answer = instance.answer
        if answer is not None and answer.config_before is None:
            answer.config_before = self.state()
        if instance.configures_itself:
            instance.environment._configure(config)
        else:
            self.apply(config, recorded)
        instance.log.configured(config)

    def apply(self, config: Mapping[str, Any], recorded: bool = False) -> None:
        """Apply a checked ``config`` part to its nodes (what ``_configure`` does by default).

        A configured property is the configuration's from then on: a reset keeps it, even if
        ``inspect`` set it earlier in the episode.
        """
        for part in self._nodes():
            if part not in config:
                continue
            settings = config[part]
            if part == "environment":
                settings = self._apply_environment(settings)
            for node, own in self._reached(part, settings, recorded):
                node.configure(own)
                for key in own:
                    self._instance.forget_set(node, key)

    def carry(self, config: Mapping[str, Any]) -> None:
        """Give a rebuilt environment the configuration of the one it replaces (:meth:`state`).

        It goes through the environment's ``_configure``, as any configuration; it is neither
        logged nor undone.
        """
        self._readers = None  # they read the replaced nodes
        instance = self._instance
        if instance.configures_itself:
            instance.environment._configure(config)
        else:  # agents that were in the replaced tree may not be in the new one yet
            self.apply(config, recorded=True)

    def undo(self, answer: Answer) -> None:
        """Put back the settings a failed request changed (as they were before it)."""
        if answer.config_before is None:
            return
        for part in self._nodes():
            for node, own in self._reached(part, answer.config_before[part]):
                try:
                    node.configure(own)
                except Exception as error:  # user code: what it keeps is its own
                    logger.error(
                        "could not undo the configuration of %s", node.get_path(), exc_info=error
                    )

    def state(self) -> dict[str, dict[str, Any]]:
        """The current value of everything a client may configure (for snapshots).

        A ``config`` part that sets it all again: ``agent`` holds the one agent's settings, or
        with several agents each agent's by name (those with a setting).
        """
        return self.capture().state()

    def capture(self) -> Captured:
        """:meth:`state` as it is now, read cheaply (every reset does): its map comes later."""
        readers = self._readers
        instance = self._instance
        agents = instance.roster.settable()
        if readers is None or not readers.fit(instance.environment, agents):
            readers = self._readers = _Readers(self._nodes(), instance.multi_agent)
        return Captured(
            readers.parts, readers.keys, tuple([read(node) for node, read in readers.nodes])
        )

    def record(self, name: str) -> None:
        """Record the environment's frames into ``name`` in the record directory (``""``: stop)."""
        if self.recorder is not None:
            self.recorder.close()
            self.recorder = None
        if name:
            assert self.record_dir is not None
            self.recorder = VideoRecorder(
                self.record_dir / name, self._instance.tree.physics_ticks_per_second
            )

    def _nodes(self) -> dict[str, list[Any]]:
        instance = self._instance
        environment = instance.environment
        parts: dict[str, list[Any]] = {
            "environment": [environment],
            "agent": instance.roster.settable(),
        }
        if environment.world is not None:
            parts["world"] = [environment.world]
        return parts

    def _reached(
        self, part: str, settings: Mapping[str, Any], recorded: bool = False
    ) -> list[tuple[Any, Mapping[str, Any]]]:
        """Each node a part's ``settings`` reach, with the settings it gets.

        ``recorded`` settings (from another tree: a snapshot's, a replaced environment's) may
        name agents that may appear but are not in this tree: they reach no one.
        """
        if part == "agent":
            roster = self._instance.roster
            absent = roster.absent_possible() if recorded else frozenset()
            return agent_settings(roster.settable(), settings, absent)
        return [(node, settings) for node in self._nodes()[part]]

    def _check_environment(self, settings: Mapping[str, Any]) -> dict[str, Any]:
        """Check what the server handles itself (real_time, record); the rest is the node's."""
        rest = dict(settings)
        real_time = rest.pop("real_time", False)
        if type(real_time) is not bool:
            raise RequestError(ErrorCode.INVALID_CONFIG, "real_time must be a bool")
        if real_time and isinstance(self._instance.roster, AgentsInPlay):
            raise RequestError(ErrorCode.INVALID_CONFIG, f"real_time {LOCKSTEP_ONLY}")
        if "record" in rest:
            _check_recording(rest.pop("record"), self.record_dir)
        if "repeat_action" in rest:
            check_repeat_action(rest["repeat_action"], "repeat_action", ErrorCode.INVALID_CONFIG)
        return rest

    def _apply_environment(self, settings: Mapping[str, Any]) -> dict[str, Any]:
        rest = dict(settings)
        if "real_time" in rest:
            self._instance.set_real_time(rest.pop("real_time"))
        if "record" in rest:
            self.record(rest.pop("record"))
        return rest


def agent_settings(
    agents: list[Any], settings: Mapping[str, Any], absent: frozenset[str] = frozenset()
) -> list[tuple[Any, Mapping[str, Any]]]:
    """Each agent a ``config.agent`` map reaches, with its own settings (module docstring).

    A map of settings only reaches every agent, as it always did; a map that names a class or
    an agent reaches the agents it gives a setting. A key in ``absent`` (agents that may
    appear but are not in the tree) reaches no one.

    Raises:
        RequestError: ``invalid_config`` for a key that is neither a setting nor an agent's
            (or its class's) name, naming them all; ``bad_request`` when a class's or an
            agent's entry is not a map.
    """
    names = {agent.name for agent in agents}
    classes = {type(agent).__name__ for agent in agents}
    common: dict[str, Any] = {}
    by_class: dict[str, Mapping[str, Any]] = {}
    by_name: dict[str, Mapping[str, Any]] = {}
    for key, value in settings.items():
        if key in absent and key not in names:
            continue
        if key in names or key in classes:
            kind = "agent" if key in names else "class"
            if not isinstance(value, Mapping):
                raise RequestError(
                    ErrorCode.BAD_REQUEST,
                    f"config.agent.{key} must be a map of that {kind}'s settings",
                )
            (by_name if kind == "agent" else by_class)[key] = value
        elif any(key in agent.configurable for agent in agents):
            common[key] = value
        else:
            known = sorted({name for agent in agents for name in agent.configurable})
            raise RequestError(
                ErrorCode.INVALID_CONFIG,
                f"config.agent has no setting or agent {key!r:.40}; its settings: "
                f"{', '.join(known) or 'none'}; its agents: "
                f"{', '.join(agent.name for agent in agents)} (classes: "
                f"{', '.join(sorted(classes))})",
            )
    if not by_class and not by_name:
        return [(agent, common) for agent in agents]
    reached: list[tuple[Any, Mapping[str, Any]]] = []
    for agent in agents:
        merged = {**common, **by_class.get(type(agent).__name__, {}), **by_name.get(agent.name, {})}
        if merged:
            reached.append((agent, merged))
    return reached


def check_keys(part: Mapping[str, Any], allowed: frozenset[str], where: str) -> None:
    """Refuse (``bad_request``) a key of ``part`` that is not ``allowed``, naming them all."""
    unknown = part.keys() - allowed
    if unknown:
        raise RequestError(
            ErrorCode.BAD_REQUEST,
            f"unknown key {sorted(map(str, unknown))[0]!r} in {where}; expected any of "
            + ", ".join(sorted(allowed)),
        )


class Captured:
    """The configuration at one moment, as read (see :meth:`Settings.capture`).

    Args:
        parts: the parts, in order.
        keys: for each node read, its part, its agent's name (``None``: the part's only node,
            whose settings are the part's) and its configurable keys, in order.
        values: each node's values, in the order of its keys.
    """

    __slots__ = ("keys", "parts", "values")

    def __init__(
        self,
        parts: tuple[str, ...],
        keys: tuple[tuple[str, str | None, tuple[str, ...]], ...],
        values: tuple[tuple[Any, ...], ...],
    ) -> None:
        self.parts, self.keys, self.values = parts, keys, values

    def state(self) -> dict[str, dict[str, Any]]:
        """The configuration as :meth:`Settings.state` gives it."""
        state: dict[str, dict[str, Any]] = {part: {} for part in self.parts}
        for (part, name, keys), values in zip(self.keys, self.values, strict=True):
            settings = dict(zip(keys, values, strict=True))
            if name is None:
                state[part] = settings
            else:
                state[part][name] = settings
        return state


class _Readers:
    """How to read the configurable values of each node, for the nodes as they are.

    Args:
        parts: :meth:`Settings._nodes`: environment, agents and, if any, the world.
        by_name: read each agent under its name (several agents), else the first agent only.
    """

    def __init__(self, parts: dict[str, list[Any]], by_name: bool) -> None:
        agents = parts["agent"]
        read = [("environment", None, parts["environment"][0])]
        read += (
            [("agent", agent.name, agent) for agent in agents if agent.configurable]
            if by_name
            else [("agent", None, agents[0])]
        )
        if "world" in parts:
            read.append(("world", None, parts["world"][0]))
        self.parts = tuple(parts)
        self.world = parts["world"][0] if "world" in parts else None
        self.agents = list(agents)
        self.configurables = [node.configurable for _, _, node in read]
        self.agent_configurables = [agent.configurable for agent in agents]
        self.keys = tuple((part, name, tuple(node.configurable)) for part, name, node in read)
        self.nodes = tuple(
            (node, _reader(keys))
            for (_, _, node), (_, _, keys) in zip(read, self.keys, strict=True)
        )

    def fit(self, environment: Any, agents: list[Any]) -> bool:
        """Whether these are still the nodes: the same world and agents, their keys the same."""
        world = environment.world
        if (
            world is not self.world
            or self.configurables[0] is not environment.configurable
            or agents != self.agents
        ):
            return False
        for agent, configurable in zip(agents, self.agent_configurables, strict=True):
            if agent.configurable is not configurable:  # a loop: asked at every reset
                return False
        return world is None or self.configurables[-1] is world.configurable


def _reader(keys: tuple[str, ...]) -> Callable[[Any], tuple[Any, ...]]:
    """A function giving the values of ``keys`` of a node, as a tuple (an attrgetter if it can)."""
    if len(keys) > 1:
        return attrgetter(*keys)
    if keys:
        key = keys[0]
        return lambda node: (getattr(node, key),)
    return lambda node: ()


def _check_recording(name: Any, record_dir: Path | None) -> None:
    if not isinstance(name, str):
        raise RequestError(ErrorCode.INVALID_CONFIG, "record must be a file name (or '' to stop)")
    if not name:
        return
    if record_dir is None:
        raise RequestError(
            ErrorCode.INVALID_CONFIG,
            "recording is disabled on this server; start it with rlenv serve --record-dir DIR",
        )
    if Path(name).name != name or name.startswith("."):
        raise RequestError(
            ErrorCode.INVALID_CONFIG,
            f"record must be a plain file name in the server's record directory, got {name!r:.60}",
        )
    if Path(name).suffix not in _VIDEO_SUFFIXES:
        raise RequestError(
            ErrorCode.INVALID_CONFIG,
            f"record must end with one of {', '.join(sorted(_VIDEO_SUFFIXES))}, got {name!r:.60}",
        )
