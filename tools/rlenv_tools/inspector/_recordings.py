"""The recordings the inspector's page offers as timelines, and which of them are open.

:class:`Recordings` numbers each recording offered (a file, or a live instance's recent
episode), opens its :class:`~rlenv_tools.timeline.Timeline` when the page first asks for it, and
closes the oldest opened past its bounds (``max_recent``, ``max_files``), giving each open one
an equal share of the page's processes and memory. Each recording is a :class:`Root`: its
timeline once opened, its tree of branches, the agent's keys, and the lock they share.
:class:`~rlenv_tools.inspector._timelines.Timelines` answers the page from them.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gymnasium import spaces

from rlenv.protocol.errors import RemoteError
from rlenv_client.launcher import ServerStartError
from rlenv_client.replay import EpisodeFile, digest
from rlenv_client.session import LOST
from rlenv_tools.inspector._control import key_map
from rlenv_tools.inspector._watch import InspectorError
from rlenv_tools.timeline import Timeline

__all__ = ["Branch", "Recordings", "Root", "episode_id", "key_name"]

_LISTED = 32  # recent episodes remembered per instance once the page was shown them


@dataclass
class Branch:
    """One node of a timeline's tree: a branch (or the episode itself, number 0)."""

    number: int
    parent: int | None
    at: int  # the branch point: the last step it shares with its parent
    how: str  # "episode", "keys" or "policy"
    timeline: Timeline
    actions: list[str] = field(default_factory=list)  # the keys pressed, or the policy's name

    def describe(self) -> dict[str, Any]:
        label = {"episode": "the episode", "policy": f"policy {''.join(self.actions)}"}.get(
            self.how,
            f"keys {' '.join(key_name(k) for k in self.actions[-6:])}"
            + (" …" if len(self.actions) > 6 else ""),
        )
        return {
            "branch": self.number,
            "parent": self.parent,
            "at": self.at,
            "how": self.how,
            "label": label,
            "length": len(self.timeline),
            "ended": self.timeline.ended,
        }


class Root:
    """A recording, its timeline once opened, its branches, and the lock they share."""

    def __init__(
        self, number: int, name: str, load: Callable[[], EpisodeFile], origin: dict[str, Any]
    ) -> None:
        self.number = number
        self.name = name
        self.load = load
        self.origin = origin
        self.lock = threading.Lock()
        self.branches: dict[int, Branch] = {}
        self.keys: dict[str, Any] = {}
        self.keys_error = ""
        self.agents: list[str] = []
        self.diffs: dict[tuple[int, int], tuple[Timeline, Timeline, Any]] = {}
        self.error = ""
        self.closed = False
        self.opened = 0  # when it was last opened (the order of openings), 0: not open

    @property
    def timeline(self) -> Timeline | None:
        branch = self.branches.get(0)
        return None if branch is None else branch.timeline

    def shut(self) -> None:
        """End the timeline and its branches (the lock held)."""
        if self.timeline is not None:
            self.timeline.close()
        self.branches.clear()
        self.diffs.clear()
        self.opened = 0

    def learn_keys(self, timeline: Timeline) -> None:
        """The agent's key map and names, from the timeline's hello and node tree."""
        try:
            hello = timeline.hello
            self.agents = list(hello.agents)
            space: spaces.Space = hello.action_space
            self.keys = key_map(timeline.tree(0), space)
        except InspectorError as error:
            self.keys, self.keys_error = {}, str(error)
        except Exception as error:  # the page still scrubs; it says why keys are off
            self.keys, self.keys_error = {}, f"the timeline did not say: {error!r:.200}"


class Recordings:
    """The recordings offered, by number, opened on first use and closed past the bounds.

    Args: as :class:`~rlenv_tools.inspector._timelines.Timelines` takes them.
    """

    def __init__(
        self,
        *,
        target: str | None,
        trust_target: bool,
        checkpoint_every: int | None,
        max_recent: int,
        max_files: int,
        max_processes: int,
        max_memory: int,
    ) -> None:
        self._target = target
        self._trust = trust_target
        self._every = checkpoint_every
        self._max_recent = max_recent
        self._max_files = max_files
        self._share = {
            "max_processes": max_processes // (max_recent + max_files),
            "max_memory": max_memory // (max_recent + max_files),
        }
        self._openings = 0
        self._lock = threading.Lock()  # the registry; each root has its own
        self._roots: dict[int, Root] = {}
        self._listed: dict[tuple[int, int], dict[str, EpisodeFile]] = {}
        self._next = 0

    def add_file(self, path: str | Path) -> int:
        """Offer the recording at ``path`` (read now); its number. Names tell files apart.

        Raises:
            ValueError: the file is not an rlenv episode.
        """
        episode = EpisodeFile.load(path)
        number = self.add(Path(path).name, lambda: episode, {"file": str(path)})
        with self._lock:
            files = [root for root in self._roots.values() if "file" in root.origin]
            for root, name in zip(
                files, _distinct([Path(r.origin["file"]) for r in files]), strict=True
            ):
                root.name = name
        return number

    def add(self, name: str, load: Callable[[], EpisodeFile], origin: dict[str, Any]) -> int:
        """Offer the recording ``load`` gives as ``name``; its number."""
        with self._lock:
            number, self._next = self._next, self._next + 1
            self._roots[number] = Root(number, name, load, origin)
            return number

    def find_recent(
        self, episodes: list[EpisodeFile], server: int, instance: int, identifier: str
    ) -> EpisodeFile:
        """The recent episode ``identifier``: in ``episodes``, else among those last listed.

        Raises:
            InspectorError: 404, no such episode (or no longer kept).
        """
        with self._lock:
            listed = self._listed.get((server, instance), {})
        found = [episode for episode in episodes if episode_id(episode) == identifier]
        if not found and identifier in listed:
            found = [listed[identifier]]
        if not found:
            raise InspectorError(
                404,
                f"instance {instance} of server {server} keeps no episode "
                f"{identifier!r:.40} (any more: newer ones replaced it)",
            )
        return found[0]

    def listed(self, server: int, instance: int, episodes: list[EpisodeFile]) -> None:
        """Remember the recent ``episodes`` the page was shown for an instance (the last 32)."""
        with self._lock:
            kept = self._listed.setdefault((server, instance), {})
            for episode in episodes:
                kept[episode_id(episode)] = episode
            for identifier in list(kept)[: max(0, len(kept) - _LISTED)]:
                del kept[identifier]  # the oldest listed first

    def roots(self) -> list[Root]:
        """Every recording offered, in the order they were."""
        with self._lock:
            return list(self._roots.values())

    @contextmanager
    def using(self, number: int) -> Iterator[Root]:
        """The root ``number``, its lock held; then the oldest opened closed past the bounds."""
        root = self._root(number)
        try:
            with root.lock:
                yield root
        finally:
            self._make_room()

    def opened(self, root: Root) -> Timeline:
        """The root's timeline, opened (its environment started) on first use."""
        if root.closed:
            raise InspectorError(404, f"timeline {root.number} was closed")
        if root.timeline is not None:
            return root.timeline
        try:  # a live server's recent episode has no digests: the timeline records them
            timeline = Timeline(
                root.load(),
                target=self._target,
                trust_target=self._trust,
                checkpoint_every=self._every,
                **self._share,
            )
        except (ValueError, ServerStartError, RuntimeError, OSError, RemoteError, *LOST) as error:
            root.error = f"cannot open {root.name}: {error}"
            raise InspectorError(422, root.error) from None
        root.error = ""
        with self._lock:
            self._openings += 1
            root.opened = self._openings
        root.branches[0] = Branch(0, None, 0, "episode", timeline)
        root.learn_keys(timeline)
        return timeline

    def close(self) -> None:
        """Close every timeline (its processes end); safe to repeat."""
        for root in self.roots():
            self._remove(root)

    def _remove(self, root: Root) -> None:
        with self._lock:
            self._roots.pop(root.number, None)
        with root.lock:
            root.closed = True
            root.shut()

    def _make_room(self) -> None:
        """Close the oldest opened timelines past ``max_recent`` and ``max_files``.

        A recent episode leaves the list; a file stays in it, to open again.
        """
        with self._lock:
            opened = sorted(
                (root for root in self._roots.values() if root.opened), key=lambda root: root.opened
            )
        recent = [root for root in opened if "recent" in root.origin]
        files = [root for root in opened if "recent" not in root.origin]
        for root in recent[: max(0, len(recent) - self._max_recent)]:
            self._remove(root)
        for root in files[: max(0, len(files) - self._max_files)]:
            with root.lock:
                root.shut()

    def _root(self, number: int) -> Root:
        with self._lock:
            root = self._roots.get(number)
        if root is None:
            raise InspectorError(404, f"no timeline {number}: see api/timelines")
        return root


def episode_id(episode: EpisodeFile) -> str:
    """A recent episode's identifier: the digest of its snapshot (the same at every asking)."""
    return digest(episode.snapshot)


def key_name(key: str) -> str:
    """A key as the page names it."""
    return "Space" if key == " " else key


def _distinct(paths: list[Path]) -> list[str]:
    """Each file's name, with as much of its folder as tells apart files of the same name."""
    resolved = [path.resolve().parts for path in paths]
    names = []
    for parts in resolved:
        depth = 1
        while (
            depth < len(parts) and sum(other[-depth:] == parts[-depth:] for other in resolved) > 1
        ):
            depth += 1
        names.append("/".join(parts[-depth:]).lstrip("/"))
    return names
