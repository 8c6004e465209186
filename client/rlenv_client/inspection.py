"""What a client may ask of an environment besides stepping it: its state, its tree, frames.

:class:`Inspection` holds the requests an inspector makes (any client may, whoever controls
the environment): snapshots and restores, the node tree and exported properties (read and set),
configuration changes, episode statistics, the last finished episodes as recordings, draw
lists and rendered frames. It is part of every
:class:`~rlenv_client.base.BaseClient`, whose ``_call`` carries its requests.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, MutableMapping
from typing import TYPE_CHECKING, Any

import numpy as np

from rlenv.protocol import ErrorReply, Hello, Request, Response
from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv.protocol.snapshots import WHOLE_EVENTS
from rlenv.protocol.spaces import codec_for
from rlenv_client.replay import EpisodeFile

__all__ = [
    "CLAIMS_SINCE",
    "EPISODES_SINCE",
    "PAGED_EPISODES_SINCE",
    "Inspection",
    "config_request",
    "episode_files",
    "episodes_refusal",
    "fetch_episodes",
]

EPISODES_SINCE = (2, 5)
"""The protocol version that brought the ``episodes`` part (:meth:`Inspection.episodes`)."""

AGENT_SETTINGS_SINCE = (2, 6)
"""The protocol whose ``config.agent`` may set one agent, keyed by its name."""

CLAIMS_SINCE = (2, 6)
"""The protocol version that brought the ``claim`` part (:meth:`Inspection.claim`)."""

PAGED_EPISODES_SINCE = (2, 6)
"""The protocol version that serves the ``episodes`` part by index and in pages."""


class Inspection:
    """The inspection requests of a client (see the module docstring)."""

    if TYPE_CHECKING:  # what BaseClient provides
        hello: Hello
        _observation_request: Mapping[str, Any]

        def _call(self, **parts: Any) -> Response: ...
        def _observation(self, response: Response, writable: bool = True) -> Any: ...
        def _info(self, response: Response) -> dict[str, Any]: ...
        def _part(self, response: Response, part: str) -> Any: ...
        def _response(self, message: Response | ErrorReply) -> Response: ...
        def send_request(self, request: Request) -> None: ...  # noqa: D102
        def receive_reply(self) -> Response | ErrorReply: ...  # noqa: D102

    def inspect_configure(
        self,
        *,
        agent: Mapping[str, Any] | None = None,
        world: Mapping[str, Any] | None = None,
        **environment: Any,
    ) -> None:
        """Change settings as ``configure`` does (``agent`` by name too), but as an inspector.

        (:meth:`~rlenv_client.base.BaseClient.configure` needs control.)

        The server applies it between two of the controller's requests, keeps it across
        episodes and logs it for snapshots; it takes no control (protocol 2.2).

        Raises:
            RemoteError: ``invalid_config`` naming the key the server refused; nothing was
                applied.
        """
        self._call(inspect={"configure": config_request(environment, agent, world)})

    def claim(self, agent: str, action: Any) -> list[str]:
        """Play ``agent`` (one of several) beside the controller: hold ``action`` for it.

        Call it again to change the held action. The controller's steps then act for the agent
        with the held action instead of the controller's own, and the episode records it; the
        claim lasts until :meth:`release_claim`, until this client takes control, or until it
        disconnects (protocol 2.6, the ``claim`` part; see :mod:`rlenv.serving._claims`).

        Returns:
            The agents claimed now, by any client (as the controller's ``info["claimed"]``).

        Raises:
            RemoteError: ``busy``: another client claimed the agent; ``bad_request``: this
                client controls the environment, claims another agent already, names no agent
                of several or a driven one, or the server is older than 2.6;
                ``invalid_action``: the action is not in the agent's space.
        """
        hello = self.hello
        if hello.protocol < CLAIMS_SINCE:
            raise RemoteError(
                ErrorCode.BAD_REQUEST,
                "the server speaks protocol {}.{}; claims need 2.6".format(*hello.protocol),
            )
        space = hello.action_space
        packed = action
        if len(hello.agents) > 1 and agent in hello.agents:
            packed = codec_for(space[agent]).pack_exact(action)  # type: ignore[index]
        return list(self._call(claim={"agent": agent, "action": packed}).info["claimed"])

    def release_claim(self) -> None:
        """End this client's claim (see :meth:`claim`), if it holds one.

        Its agent goes back to the controller's actions.
        """
        self._call(claim=None)

    def snapshot(self) -> dict[str, Any]:
        """The environment's state as data (see :mod:`rlenv.serving._snapshots`).

        Restore it later with :meth:`restore`.

        Raises:
            RemoteError: ``reset_required`` before the first reset.
        """
        return dict(self._call(snapshot={}).info["snapshot"])

    def restore(self, snapshot: Mapping[str, Any]) -> tuple[Any, dict[str, Any]]:
        """Bring the environment to the state of a :meth:`snapshot`.

        The snapshot may come from this server or any other serving the same environment; the
        same actions then give the same observations, bit for bit.

        Returns:
            ``(observation, info)`` in the restored state.

        Raises:
            RemoteError: ``bad_request`` / ``invalid_action`` / ``invalid_config`` naming what
                in the snapshot is wrong (nothing changed), or ``environment_error`` if
                replaying it failed (reset next).
        """
        response = self._call(restore=snapshot, observation=self._observation_request)
        return self._observation(response), self._info(response)

    def episodes(self, last: int | None = None) -> list[EpisodeFile]:
        """The environment's last finished episodes, as recordings, oldest first.

        The server keeps each instance's last few once a client asks for them (this call does;
        ``rlenv serve --keep-episodes N`` from the start; see :mod:`rlenv.serving._recent`) at
        no cost to the steps; any client may ask, an observer beside a trainer included
        (protocol 2.5, the ``episodes`` part; from a 2.6 server by index and in pages). Each
        snapshot restores the episode's start on any server of the environment and replays to
        the observations the episode had.

        Args:
            last: only the ``last`` most recent ones (an integer >= 1); all kept if ``None``.

        Returns:
            One :class:`~rlenv_client.replay.EpisodeFile` per episode: ``target`` the server's
            (``None`` if it cannot name one: pass yours to whatever replays it), its
            ``snapshot``, ``observations=[]`` (the server keeps no digests: not recorded), and
            how it ended (``terminated``, ``truncated``; both false when a reset cut it short).

        Raises:
            RemoteError: ``bad_request``: the server speaks a protocol older than 2.5, or
                ``last`` is not an integer >= 1.
        """
        hello = self.hello
        refusal = episodes_refusal(hello)
        if refusal is not None:
            raise RemoteError(ErrorCode.BAD_REQUEST, refusal)
        if last is not None and (type(last) is not int or last < 1):
            raise RemoteError(
                ErrorCode.BAD_REQUEST, f"episodes.last must be an integer >= 1, got {last!r:.40}"
            )
        return fetch_episodes(lambda part: self._call(episodes=part), hello, last)

    def tree(self) -> list[dict[str, Any]]:
        """The environment's node tree: every node's path, type and exported properties."""
        return list(self._call(inspect={"tree": {}}).info["tree"])

    def get_property(self, path: str, name: str) -> Any:
        """The exported property ``name`` of the node at ``path``.

        Paths are absolute (``/root/...``) or relative to the environment node.

        Raises:
            RemoteError: ``bad_request`` naming the missing node or property.
        """
        return self._call(inspect={"get": {"path": path, "property": name}}).info["value"]

    def node(self, path: str) -> dict[str, Any]:
        """One node of :meth:`tree`: its path, type and exported properties.

        Raises:
            RemoteError: ``bad_request`` naming the missing node.
        """
        return dict(self._call(inspect={"node": {"path": path}}).info["node"])

    def set_property(self, path: str, name: str, value: Any) -> None:
        """Set an exported property for this episode (type-checked; snapshots reproduce it).

        Any client may, whoever controls the environment (an inspector's edit); the next
        reset gives the property back its value from before the episode's first set.

        Raises:
            RemoteError: ``bad_request`` naming the node, property or expected type.
        """
        self._call(inspect={"set": {"path": path, "property": name, "value": value}})

    def stats(self, since: int = 0) -> dict[str, Any]:
        """The controller's episodes as the server counted them, numbered ``since`` and later.

        See :mod:`rlenv.serving._stats` (totals, the episode under way).
        """
        return dict(self._call(inspect={"stats": {"since": since}}).info["stats"])

    def draw(self) -> dict[str, Any]:
        """The scene as a vector draw list (see :func:`rlenv.scene2d.render.draw_list`).

        Raises:
            RemoteError: ``reset_required`` before the first reset.
        """
        return dict(self._part(self._call(observation={"draw": {}}), "draw"))

    def render(self, width: int | None = None, height: int | None = None) -> np.ndarray:
        """Draw the environment's current state: an ``(height, width, 3)`` uint8 array.

        The size defaults to the environment's ``render_size``.
        """
        self.send_request(self.render_request(width, height))
        return self.render_result(self.receive_reply())

    def render_request(self, width: int | None = None, height: int | None = None) -> Request:
        """The request :meth:`render` sends, for a batch."""
        size = {k: v for k, v in (("width", width), ("height", height)) if v is not None}
        return Request(0, {"observation": {"render": size}})

    def render_result(self, reply: Response | ErrorReply) -> np.ndarray:
        """A render's answer as an ``(height, width, 3)`` uint8 array.

        Raises:
            RemoteError: the answer is an error.
        """
        frame = np.asarray(self._part(self._response(reply), "render"))
        return frame if frame.flags.writeable else frame.copy()


def episodes_refusal(hello: Hello, server: str = "the server") -> str | None:
    """Why the server of ``hello`` cannot serve recent episodes (older than 2.5), or ``None``.

    Args:
        hello: the server's hello.
        server: how the message names the server.
    """
    if hello.protocol >= EPISODES_SINCE:
        return None
    return "{} speaks protocol {}.{}; recent episodes need {}.{}".format(
        server, *hello.protocol, *EPISODES_SINCE
    )


def fetch_episodes(
    ask: Callable[[dict[str, Any]], Response],
    hello: Hello,
    last: int | None = None,
    cache: MutableMapping[int, EpisodeFile] | None = None,
) -> list[EpisodeFile]:
    """An instance's kept episodes (the ``last`` ones), oldest first, as recordings.

    From a 2.6 server, by index and in pages (no answer holds more than a page, and each
    episode is asked for once if ``cache`` keeps them by id: a kept episode never changes);
    from a 2.5 server, whole in one answer.

    Args:
        ask: sends an ``episodes`` part to the instance; its answer.
        hello: the server's hello (its protocol and target).
        last: only the ``last`` most recent.
        cache: the episodes fetched before, by id (updated: those no longer kept leave it).
    """
    if hello.protocol < PAGED_EPISODES_SINCE:
        part = {} if last is None else {"last": last}
        return episode_files(ask(part).info["episodes"], hello.target)
    index = ask({"index": True}).info["episodes"]
    if cache is None:
        cache = {}
    for identifier in set(cache) - {entry["id"] for entry in index}:
        del cache[identifier]
    wanted = index if last is None else index[-last:]
    missing = [entry for entry in wanted if entry["id"] not in cache]
    if missing and sum(entry["events"] for entry in index) <= WHOLE_EVENTS:
        # in one answer, as they are now: an instance that finishes episodes faster than
        # pages come would replace them between pages
        try:
            whole = ask({} if last is None else {"last": last}).info["episodes"]
        except RemoteError as error:  # more came meanwhile than one answer carries: page them
            if error.code != ErrorCode.BAD_REQUEST:
                raise
        else:
            files = [
                cache.setdefault(entry["id"], _episode_file(entry, hello.target)) for entry in whole
            ]
            if last is None:  # what the index listed and is gone since
                for identifier in set(cache) - {entry["id"] for entry in whole}:
                    del cache[identifier]
            return files
    files = []
    for entry in wanted:
        identifier = entry["id"]
        found = cache.get(identifier)
        if found is None:
            found = _fetch_episode(ask, identifier, hello.target)
            if found is None:  # dropped meanwhile (newer ones finished)
                continue
            cache[identifier] = found
        files.append(found)
    return files


def _fetch_episode(
    ask: Callable[[dict[str, Any]], Response], identifier: int, target: str | None
) -> EpisodeFile | None:
    """One kept episode, page by page (``None``: no longer kept)."""
    events: list[Any] = []
    while True:
        page = ask({"episode": identifier, "from": len(events)}).info["episode"]
        if page is None:
            return None
        snapshot = dict(page["snapshot"])
        got = snapshot["events"]
        events.extend(got)
        if not got or len(events) >= page["events"]:
            snapshot["events"] = events
            return EpisodeFile(
                target, snapshot, [], bool(page["terminated"]), bool(page["truncated"])
            )


def episode_files(entries: list[Mapping[str, Any]], target: str | None) -> list[EpisodeFile]:
    """The ``episodes`` part's answer (``info["episodes"]``) as recordings of ``target``."""
    return [_episode_file(entry, target) for entry in entries]


def _episode_file(entry: Mapping[str, Any], target: str | None) -> EpisodeFile:
    return EpisodeFile(
        target, dict(entry["snapshot"]), [], bool(entry["terminated"]), bool(entry["truncated"])
    )


def config_request(
    environment: Mapping[str, Any], agent: Mapping[str, Any] | None, world: Mapping[str, Any] | None
) -> dict[str, Any]:
    """A ``config`` part from ``configure``'s arguments.

    Its keys: ``environment`` (the environment's settings), ``agent`` and ``world``.
    """
    config: dict[str, Any] = {}
    if environment:
        config["environment"] = dict(environment)
    if agent is not None:
        config["agent"] = dict(agent)
    if world is not None:
        config["world"] = dict(world)
    return config
