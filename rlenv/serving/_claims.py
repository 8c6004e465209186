"""Claims: an observer playing one agent of several while another client controls the episode.

A client that does not control the environment may **claim** one agent of a multi-agent
instance and hold an action for it (the ``claim`` request part, protocol 2.6): the
controller's actions then act for that agent with the held action instead of the controller's
entry, inside the controller's own steps, so the episode's log records it as any action and
snapshots replay it bit for bit. An inspector's person plays one agent beside a trainer's
others this way (ML-Agents' heuristic-only agent beside trained ones).

Bounds: one claim per agent, one per client; never on an agent the server drives, nor on an
environment of one agent (its controller owns it). A claim ends when its client releases it
(``claim: nil``), takes control itself, or disconnects (:meth:`Claims.release`).
"""

from __future__ import annotations

from typing import Any

__all__ = ["Claims", "Requester"]


class Requester:
    """Who sent the request being served (a host's connection, shared by its instances).

    Attributes:
        peer: the connection (anything with an ``address``), or ``None`` in process.
    """

    __slots__ = ("peer",)

    def __init__(self) -> None:
        self.peer: Any = None


class Claims:
    """The claimed agents of one instance: each one's client and held action, in claim order."""

    __slots__ = ("actions", "owners")

    def __init__(self) -> None:
        self.owners: dict[str, Any] = {}  # agent name -> the client that plays it
        self.actions: dict[str, Any] = {}  # agent name -> its held (checked) action

    def of(self, owner: Any) -> str | None:
        """The agent ``owner`` plays, or ``None``."""
        for name, each in self.owners.items():
            if each is owner:
                return name
        return None

    def hold(self, owner: Any, name: str, action: Any) -> None:
        """``owner`` plays ``name`` (checked: it may) with ``action`` until changed."""
        self.owners[name] = owner
        self.actions[name] = action

    def release(self, owner: Any) -> bool:
        """End ``owner``'s claim, if any; whether any claim is left."""
        name = self.of(owner)
        if name is not None:
            del self.owners[name], self.actions[name]
        return bool(self.owners)

    def complete(
        self, action: dict[str, Any], heuristic: frozenset[str]
    ) -> tuple[dict[str, Any], frozenset[str]]:
        """The action with each claimed agent's held action, and the heuristic agents left.

        A claimed agent acts only while it is in the episode (it has an entry, or the step
        names it in ``heuristic``); its held action replaces the controller's entry, and its
        heuristic does not run.
        """
        claimed = {
            name: held for name, held in self.actions.items() if name in action or name in heuristic
        }
        if heuristic:
            heuristic = heuristic.difference(self.actions)
        return {**action, **claimed}, heuristic
