"""The inspector's side of the protocol: observer connections to the servers it watches.

A :class:`Watcher` holds one connection per server, opened as any client's would be (the token
stays here, never in the page). It only sends what observers may send: ``observation``
(``draw``, ``agent``), ``snapshot``, ``episodes`` and ``inspect``, so it never takes control;
the trainer's steps go on, and a change it makes applies between two of them. Every call is
answered from a fresh request (nothing is cached, so a slow page drops frames, never queues
them), but for the recent episodes, which never change once kept: each is fetched once, in
pages, and the server is asked to keep them as soon as the watcher connects. A lost connection
is reconnected on the next call (or at a new address, see
:meth:`Watcher.follow`). A server counts as restarted when it moved to a new address, or when
after a reconnection its step count went back (another process: an idle connection the server
closed is not a restart).
"""

from __future__ import annotations

import base64
import threading
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv.protocol import ErrorReply, Request, Response
from rlenv.protocol.errors import RemoteError
from rlenv_client._addresses import parse_address
from rlenv_client.client import Client
from rlenv_client.inspection import (
    AGENT_SETTINGS_SINCE,
    PAGED_EPISODES_SINCE,
    episodes_refusal,
    fetch_episodes,
)
from rlenv_client.replay import EpisodeFile
from rlenv_client.session import LOST

__all__ = ["InspectorError", "Watcher", "to_json"]

_RETRY_AFTER = 0.5  # seconds between attempts to reach a lost server
_MAX_NUMBERS = 64  # a non-image observation shows at most this many numbers


class InspectorError(Exception):
    """What the page is told when a server cannot answer (lost, or refused the request).

    Attributes:
        status: the HTTP status the page gets (404 no such server or instance, 422 refused,
            503 unreachable).
    """

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


class _Watched:
    """One server: its address, its connection (``None`` while lost), its restarts."""

    def __init__(self, address: str) -> None:
        self.address = address
        self.client: Client | None = None
        self.lock = threading.Lock()
        self.restarts = 0
        self.reconnected: set[int] = set()  # instances whose statistics may be another process's
        self.steps: dict[int, int] = {}  # per instance, the step count its last statistics gave
        self.lost_at = -_RETRY_AFTER
        self.error = ""
        self.recent: dict[int, dict[int, EpisodeFile]] = {}  # fetched, by instance and id


class Watcher:
    """Observer connections to ``addresses`` (``HOST:PORT`` each).

    Args:
        addresses: the servers to watch.
        token: the servers' secret, if they need one (default ``$RLENV_TOKEN``).
        timeout: seconds to wait for an answer.
    """

    def __init__(
        self, addresses: Sequence[str], token: str | None = None, timeout: float = 5.0
    ) -> None:
        for address in addresses:
            parse_address(address)  # refuses a malformed one now
        self._servers = [_Watched(address) for address in addresses]
        self._token = token
        self._timeout = timeout
        self._lock = threading.Lock()

    # --- what the page asks for -----------------------------------------------------------

    def servers(self) -> list[dict[str, Any]]:
        """Every server: its address, environment, spaces, instances and restarts."""
        described = []
        for index, watched in enumerate(self._servers):
            entry: dict[str, Any] = {
                "index": index,
                "address": watched.address,
                "restarts": watched.restarts,
            }
            try:
                client = self._client(index)
            except InspectorError as error:
                entry["error"] = str(error)
            else:
                hello = client.hello
                entry.update(
                    environment=hello.environment,
                    instances=hello.instances,
                    agents=list(hello.agents),
                    driven=list(hello.driven),
                    action_space=_short(hello.action_space),
                    observation_space=_short(hello.observation_space),
                    ticks_per_second=hello.physics_ticks_per_second,
                    protocol=".".join(map(str, hello.protocol)),
                )
            described.append(entry)
        return described

    def frame(self, server: int, instance: int) -> dict[str, Any]:
        """The scene's draw list and the agents' observations, now."""
        reply = self._ask(server, instance, {"observation": {"draw": {}, "agent": {}}})
        client = self._client(server)
        agents = client.hello.agents
        try:
            unpacked = client.observation_result(reply)
        except LOST as error:
            raise InspectorError(503, str(error)) from None
        shown = (
            {name: _shown(unpacked[name]) for name in agents}
            if len(agents) > 1
            else {agents[0] if agents else "agent": _shown(unpacked)}
        )
        return {"draw": to_json((reply.observation or {}).get("draw")), "observation": shown}

    def tree(self, server: int, instance: int) -> list[dict[str, Any]]:
        """The node tree (see ``inspect tree``)."""
        return list(to_json(self._ask(server, instance, {"inspect": {"tree": {}}}).info["tree"]))

    def node(self, server: int, instance: int, path: str) -> dict[str, Any]:
        """One node, with its exported values.

        ``settings`` names those an edit keeps across episodes: its configurable ones. One
        agent of several has them on a server that sets one agent by its name (protocol 2.6);
        on an older one a setting would change every agent, so it has none.
        """
        node = dict(
            to_json(self._ask(server, instance, {"inspect": {"node": {"path": path}}}).info["node"])
        )
        hello = self._client(server).hello
        shared = (
            node.get("config") == "agent"
            and len(hello.agents) > 1
            and hello.protocol < AGENT_SETTINGS_SINCE
        )
        node["settings"] = [] if shared else list(node.get("configurable", ()))
        return node

    def edit(self, server: int, instance: int, path: str, name: str, value: Any) -> str:
        """Change a property; returns which kind of change it was.

        ``setting`` (a ``configure``: it lasts) where the node's config section reaches the
        property (an agent of several: that agent's, by its name), else ``episode`` (a
        ``set``, until the next reset).
        """
        node = self.node(server, instance, path)
        if name in node["settings"]:
            settings = {name: value}
            if node["config"] == "agent" and len(self._client(server).hello.agents) > 1:
                settings = {node["path"].rsplit("/", 1)[-1]: settings}
            self._ask(server, instance, {"inspect": {"configure": {node["config"]: settings}}})
            return "setting"
        self._ask(
            server, instance, {"inspect": {"set": {"path": path, "property": name, "value": value}}}
        )
        return "episode"

    def stats(self, server: int, instance: int, since: int) -> dict[str, Any]:
        """The server's episode statistics (see ``inspect stats``), and this server's restarts."""
        stats = dict(
            self._ask(server, instance, {"inspect": {"stats": {"since": since}}}).info["stats"]
        )
        watched = self._servers[server]
        with watched.lock:
            if instance in watched.reconnected and stats["steps"] < watched.steps[instance]:
                watched.restarts += 1  # a new process at the same address
                watched.reconnected.clear()
            watched.reconnected.discard(instance)
            watched.steps[instance] = stats["steps"]
            stats["restarts"] = watched.restarts
        stats["time"] = time.monotonic()
        return stats

    def snapshot(self, server: int, instance: int) -> dict[str, Any]:
        """The episode so far, as JSON-ready data."""
        return to_json(self._ask(server, instance, {"snapshot": {}}).info["snapshot"])

    def recent_episodes(self, server: int, instance: int) -> list[EpisodeFile]:
        """The instance's last finished episodes, as recordings, oldest first.

        See :meth:`rlenv_client.inspection.Inspection.episodes`: ``target`` is the server's
        (``None`` if it cannot name one), ``observations`` empty (not recorded).

        Raises:
            InspectorError: no such server or instance (404), a server older than protocol 2.5
                (422), or one that cannot be reached (503).
        """
        hello = self._client(server).hello
        refusal = episodes_refusal(hello, f"server {server}")
        if refusal is not None:
            raise InspectorError(422, refusal)
        cache = self._watched(server).recent.setdefault(instance, {})
        return fetch_episodes(
            lambda part: self._ask(server, instance, {"episodes": part}), hello, cache=cache
        )

    def address(self, server: int) -> str:
        """The ``HOST:PORT`` of ``server`` (a controller of its own connects there).

        Raises:
            InspectorError: 404, no such server.
        """
        return self._watched(server).address

    def follow(self, addresses: Sequence[str]) -> None:
        """Watch these addresses from now on (a restarted server's new one, say).

        A server whose address changed is counted as restarted.
        """
        with self._lock:
            for index, address in enumerate(addresses):
                parse_address(address)
                if index >= len(self._servers):
                    self._servers.append(_Watched(address))
                    continue
                watched = self._servers[index]
                if watched.address != address:
                    with watched.lock:
                        self._drop(watched, "moved")
                        watched.address = address
                        watched.restarts += 1
                        watched.reconnected.clear()
                        watched.steps.clear()

    def close(self) -> None:
        """Close every connection."""
        for watched in self._servers:
            with watched.lock:
                self._drop(watched, "closed")

    # --- connections ------------------------------------------------------------------------

    def _ask(self, server: int, instance: int, parts: Mapping[str, Any]) -> Response:
        """One request to ``instance`` of ``server``; its answer.

        Raises:
            InspectorError: no such server or instance (404), the server refused (422), or it
                cannot be reached (503).
        """
        watched = self._watched(server)
        with watched.lock:
            client = self._connected(watched)
            count = client.hello.instances
            if not 0 <= instance < count:
                raise InspectorError(
                    404, f"server {server} has {count} instances, not {instance + 1}"
                )
            try:
                if count == 1:
                    client.send_request(Request(0, dict(parts)))
                    reply: Response | ErrorReply | None = client.receive_reply()
                else:
                    client.send_batch([None] * instance + [Request(0, dict(parts))])
                    reply = client.receive_batch()[instance]
            except RemoteError as error:
                raise InspectorError(422, f"{error.code}: {error.message}") from None
            except LOST as error:
                self._drop(watched, str(error))
                raise InspectorError(503, f"{watched.address}: {error}") from None
        if isinstance(reply, ErrorReply):
            raise InspectorError(422, f"{reply.code}: {reply.message.splitlines()[0]}")
        assert isinstance(reply, Response)
        return reply

    def _client(self, server: int) -> Client:
        watched = self._watched(server)
        with watched.lock:
            return self._connected(watched)

    def _watched(self, server: int) -> _Watched:
        if not 0 <= server < len(self._servers):
            raise InspectorError(404, f"no server {server}: watching {len(self._servers)}")
        return self._servers[server]

    def _connected(self, watched: _Watched) -> Client:
        """The server's connection, reconnecting (at most every half second) if it was lost."""
        if watched.client is not None and not watched.client.closed:
            return watched.client
        now = time.monotonic()
        if now - watched.lost_at < _RETRY_AFTER:
            raise InspectorError(503, f"{watched.address} is unreachable: {watched.error}")
        try:
            watched.client = Client(
                *parse_address(watched.address), timeout=self._timeout, token=self._token
            )
        except RemoteError as error:
            watched.lost_at, watched.error = now, f"{error.code}: {error.message}"
            raise InspectorError(503, f"{watched.address} refused: {watched.error}") from None
        except LOST as error:
            watched.lost_at, watched.error = now, str(error)
            raise InspectorError(503, f"{watched.address} is unreachable: {error}") from None
        watched.reconnected = set(watched.steps)  # the instances seen before: still the same?
        watched.recent.clear()  # perhaps another process: its ids name other episodes
        _start_keeping(watched.client)
        return watched.client

    @staticmethod
    def _drop(watched: _Watched, why: str) -> None:
        if watched.client is not None:
            watched.client.close()
            watched.client = None
        watched.lost_at, watched.error = time.monotonic(), why


def _start_keeping(client: Client) -> None:
    """Ask every instance for its recent episodes' index: a server keeps none until asked."""
    hello = client.hello
    if hello.protocol < PAGED_EPISODES_SINCE:
        return
    part = {"episodes": {"index": True}}
    try:
        if hello.instances == 1:
            client.send_request(Request(0, part))
            client.receive_reply()
        else:
            client.send_batch([Request(0, part)] * hello.instances)
            client.receive_batch()
    except (RemoteError, *LOST):
        pass  # the next call says what is wrong


def _short(space: spaces.Space) -> str:
    """A space in a few words: ``Box(5,) float32``, ``Discrete(5)``, ``Dict(a: ..., b: ...)``."""
    if isinstance(space, spaces.Box):
        return f"Box{space.shape} {space.dtype}"
    if isinstance(space, spaces.Dict):
        return (
            "Dict("
            + ", ".join(f"{key}: {_short(inner)}" for key, inner in space.spaces.items())
            + ")"
        )
    if isinstance(space, spaces.Tuple):
        return "Tuple(" + ", ".join(_short(inner) for inner in space.spaces) + ")"
    return str(space)


def _shown(observation: Any) -> dict[str, Any]:
    """An agent's observation as the page shows it: an image, or its first numbers."""
    if isinstance(observation, np.ndarray):
        image = _as_image(observation)
        if image is not None:
            height, width, channels = image.shape
            return {
                "image": {
                    "width": width,
                    "height": height,
                    "channels": channels,
                    "data": base64.b64encode(image.tobytes()).decode("ascii"),
                }
            }
        flat = observation.ravel()
        return {
            "numbers": [_number(x) for x in flat[:_MAX_NUMBERS].tolist()],
            "shape": list(observation.shape),
            "dtype": observation.dtype.str,
        }
    if isinstance(observation, Mapping):
        return {"parts": {str(key): _shown(value) for key, value in observation.items()}}
    if isinstance(observation, tuple | list):
        return {"parts": {str(index): _shown(value) for index, value in enumerate(observation)}}
    return {"numbers": [_number(observation)], "shape": [], "dtype": type(observation).__name__}


def _as_image(array: np.ndarray) -> np.ndarray | None:
    """``array`` as (height, width, 1, 3 or 4) uint8 if it looks like a camera's frame."""
    if array.dtype != np.uint8 or array.ndim not in (2, 3):
        return None
    if array.ndim == 2:
        array = array[:, :, np.newaxis]
    if array.shape[2] not in (1, 3, 4) or min(array.shape[:2]) < 8:
        return None
    return np.ascontiguousarray(array)


def _number(value: Any) -> Any:
    if isinstance(value, float):
        return round(value, 5) if np.isfinite(value) else str(value)
    return value if isinstance(value, bool | int) else str(value)


def to_json(value: Any) -> Any:
    """Decoded msgpack data as JSON-ready data: arrays as nested lists, bytes as hex."""
    if isinstance(value, Mapping):
        return {str(key): to_json(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [to_json(item) for item in value]
    if isinstance(value, np.ndarray):
        return to_json(value.tolist())
    if isinstance(value, bytes):
        return {"hex": value.hex()}
    if isinstance(value, float) and not np.isfinite(value):
        return str(value)
    if isinstance(value, np.generic):
        return to_json(value.item())
    return value
