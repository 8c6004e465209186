"""The codec of maps by agent name that hold some of the agents: agents that come and go.

While agents come and go (the hello's ``possible_agents``), an answer's ``agent`` observation
holds the agents due and those that left, and an action the agents due: some keys of the
joint ``Dict`` space, each packed by its own agent's codec (docs/protocol.md, "Agents that
come and go"). Both ends use :func:`agent_codec`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from gymnasium import spaces

from rlenv.protocol.spaces import Codec, SpaceMismatch, codec_for

__all__ = ["SomeAgents", "agent_codec"]


def agent_codec(space: spaces.Space, some: bool) -> Codec:
    """The codec of ``space``; of maps holding ``some`` of its agents when agents come and go."""
    if not some:
        return codec_for(space)
    if not isinstance(space, spaces.Dict):
        raise TypeError(f"agents that come and go need a Dict space by agent name, got {space}")
    return SomeAgents({name: codec_for(item) for name, item in space.spaces.items()})


class SomeAgents(Codec):
    """Packs and unpacks a map from agent name to value that holds any of the agents."""

    def __init__(self, agents: dict[str, Codec]) -> None:
        self.agents = agents

    def pack(self, value: Any) -> dict[str, Any]:
        """Each agent's value packed by its codec; a name that is no agent is refused."""
        if not isinstance(value, Mapping):
            raise SpaceMismatch(f"is not a map by agent name (agents: {', '.join(self.agents)})")
        packed = {}
        for name, item in value.items():
            codec = self.agents.get(name)
            if codec is None:
                raise SpaceMismatch(f"has {name!r:.40}, which is no agent's name")
            try:
                packed[name] = codec.pack(item)
            except SpaceMismatch as error:
                raise SpaceMismatch(f"[{name!r}] {error}") from None
        return packed

    def pack_exact(self, value: Any) -> Any:
        """As :meth:`pack`, for values already of their spaces' types."""
        if isinstance(value, Mapping) and value.keys() <= self.agents.keys():
            return {name: self.agents[name].pack_exact(item) for name, item in value.items()}
        return value

    def unpack(self, wire: Any, writable: bool = True) -> dict[str, Any]:
        """The agents' values of a packed map (``KeyError`` for a name that is no agent)."""
        if not isinstance(wire, Mapping):
            raise TypeError(f"expected a map by agent name, got {type(wire).__name__}")
        return {name: self.agents[name].unpack(item, writable) for name, item in wire.items()}

    def join(self, packed: list[Any]) -> Any:
        """Not defined: rows of maps with different agents are no batch."""
        raise TypeError("maps of some agents do not join into a batch")
