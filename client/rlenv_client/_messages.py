"""What a client's messages hold: the requests it builds, and the info its answers carry.

:class:`Requests` is prepared once from the hello (by
:class:`~rlenv_client.base.BaseClient`): the codec that packs the agent's action, the
observation each request asks for, and, when first needed, the codecs of K actions and K
observations (K: the server's instances) that a ``steps`` request and its answer carry: a
step's, a reset's, a poll's and a ``steps`` request in columns. :func:`reset_part` is a
reset's part, also for the resets a vector sets aside
(:meth:`~rlenv_client.vector.RemoteVectorEnv.set_next_reset`). :func:`answer_info` is an
answer's ``info`` as a result gives it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium.vector.utils import batch_space

from rlenv.protocol import Hello, Request, Response
from rlenv.protocol._agent_maps import agent_codec
from rlenv.protocol.spaces import Codec, codec_for

__all__ = ["Requests", "answer_info", "reset_part"]


def reset_part(seed: int | None = None, options: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """A request's ``reset`` part: the seed and the options, those given."""
    reset: dict[str, Any] = {}
    if seed is not None:
        reset["seed"] = seed
    if options is not None:
        reset["options"] = dict(options)
    return reset


def answer_info(response: Response) -> dict[str, Any]:
    """``response``'s info, with its ``frames``, its ``agents`` and the ``world`` observed."""
    info = dict(response.info)
    info["frames"] = response.frames
    if response.agents is not None:
        info["agents"] = response.agents
    observation = response.observation
    if observation is not None and "world" in observation:
        info["world"] = observation["world"]
    return info


class Requests:
    """The requests of a client of the server that said ``hello``.

    Args:
        hello: the server's hello (its spaces and instances).
        observation: the ``observation`` part a step, reset or poll asks for.
    """

    def __init__(self, hello: Hello, observation: Mapping[str, Any]) -> None:
        self._hello = hello
        self._observation = observation
        self._action: Codec = agent_codec(hello.action_space, hello.possible_agents is not None)
        self._columns: tuple[Codec, Codec] | None = None  # (actions, observations) of K

    def step(self, action: Any, repeat_action: int | None, request_id: int) -> Request:
        """A step: ``action`` packed (as it is if not exactly of the space's dtype and shape)."""
        parts = {"action": self._action.pack_exact(action), "observation": self._observation}
        if repeat_action is not None:
            parts["repeat_action"] = repeat_action
        return Request(request_id, parts)

    def reset(
        self, seed: int | None, options: Mapping[str, Any] | None, request_id: int
    ) -> Request:
        """A reset with ``seed`` and ``options``, those given."""
        return Request(
            request_id, {"reset": reset_part(seed, options), "observation": self._observation}
        )

    def poll(self, request_id: int) -> Request:
        """A look at the episode's state without acting: the protocol's ``action: nil``."""
        return Request(request_id, {"action": None, "observation": self._observation})

    def steps(
        self,
        action: Any,
        reset: np.ndarray | None,
        repeat_action: int | None,
        reset_with: Sequence[Mapping[str, Any] | None] | None,
        request_id: int,
    ) -> Request:
        """A ``steps`` request: every instance's action in columns (see ``send_steps``)."""
        actions, _ = self.column_codecs()
        steps: dict[str, Any] = {"action": actions.pack_exact(action)}
        if reset is not None:
            steps["reset"] = (
                np.asarray(reset, np.bool_).tobytes() if isinstance(reset, np.ndarray) else reset
            )
        if repeat_action is not None:
            steps["repeat_action"] = repeat_action
        if reset_with is not None and any(entry is not None for entry in reset_with):
            steps["reset_with"] = [None if entry is None else dict(entry) for entry in reset_with]
        return Request(request_id, {"steps": steps})

    def column_codecs(self) -> tuple[Codec, Codec]:
        """The codecs of K actions and K observations (K: the server's instances)."""
        if self._columns is None:
            hello, count = self._hello, self._hello.instances
            self._columns = (
                codec_for(batch_space(hello.action_space, count)),
                codec_for(batch_space(hello.observation_space, count)),
            )
        return self._columns
