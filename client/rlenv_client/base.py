"""The client API, independent of how requests reach the environment.

:class:`BaseClient` turns calls (``reset``, ``step`` ...) into :class:`rlenv.protocol.Request`
records and answers back into gymnasium-shaped results. A subclass supplies the transport:
:class:`~rlenv_client.client.Client` over TCP, :class:`~rlenv_client.local.LocalClient` inside
this process. Stepping is split into :meth:`BaseClient.send_step` and
:meth:`BaseClient.receive_step` so that a vector of clients can send every request before
waiting for any answer.

Values of the declared spaces travel in their packed form (:mod:`rlenv.protocol.spaces`): the codecs
that pack actions and unpack observations are prepared once, from the hello.

A client waits for one answer at a time: the answer to the request it sent last. An answer to
an earlier request, whose caller gave up on it (a ``KeyboardInterrupt`` while it waited, as in
a notebook), is read when it comes and dropped, never taken for the answer to a later request
(the client's ``Answers``, in ``_answers.py``, keep that order and check each answer).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from itertools import count
from typing import Any

import numpy as np
from gymnasium import spaces

from rlenv.protocol import (
    BatchResponse,
    ErrorReply,
    GroupSpec,
    Hello,
    Reply,
    Request,
    Response,
    StepsResponse,
)
from rlenv.protocol._agent_maps import agent_codec
from rlenv.protocol.errors import ConnectionLost
from rlenv.protocol.spaces import Codec
from rlenv_client._answers import Answers
from rlenv_client._messages import Requests, answer_info
from rlenv_client.inspection import Inspection, config_request

__all__ = ["BaseClient", "StepResult"]

StepResult = tuple[Any, float, bool, bool, dict[str, Any]]
"""``(observation, reward, terminated, truncated, info)``, as gymnasium's ``step`` returns."""

AGENT_ONLY: Mapping[str, Any] = {"agent": {}}
"""What a step observes by default: the agent's observation alone."""
_AGENT_AND_WORLD: Mapping[str, Any] = {"agent": {}, "world": {}}


class BaseClient(Inspection, ABC):
    """configure / reset / step / observe / render over some transport.

    Attributes:
        hello (Hello): everything the server said on connecting.
        action_space (gymnasium.spaces.Space): the agent's action space, as the server
            declared it.
        observation_space (gymnasium.spaces.Space): the agent's observation space, as the
            server declared it.
        address (str): where the environment is, for messages.
        groups (dict[str, GroupSpec]): the environment's groups of agents (protocol 2.7), by
            agent name: each one's ``instance_count`` and one member's spaces (empty when
            none). A group's observation is one array ``(instance_count, *obs_shape)``, its
            action one array ``(instance_count, *act_shape)``, and its entry in
            ``info["agents"]`` arrays ``reward``, ``terminated``, ``truncated``, ``active``
            and ``joined`` (docs/several-agents.md, "Swarms").
    """

    hello: Hello
    address: str

    def __init__(self, *, world_data: bool = False) -> None:
        self._observation_request = _AGENT_AND_WORLD if world_data else AGENT_ONLY
        self._ids = count(1)

    def _set_hello(self, hello: Hello) -> None:
        """Take the server's ``hello`` (once :attr:`address` is set), before any request."""
        self.hello = hello
        self._answers = Answers(self.address, self._receive, self.close)
        self.action_space: spaces.Space = hello.action_space
        self.observation_space: spaces.Space = hello.observation_space
        self.groups: dict[str, GroupSpec] = hello.groups
        self._requests = Requests(hello, self._observation_request)
        self._observations: Codec = agent_codec(
            hello.observation_space, hello.possible_agents is not None
        )

    # --- the API ----------------------------------------------------------------------------

    def configure(
        self,
        *,
        agent: Mapping[str, Any] | None = None,
        world: Mapping[str, Any] | None = None,
        **environment: Any,
    ) -> None:
        """Configure the environment (keywords), the agents and the world.

        Example: ``client.configure(repeat_action=7, agent={"max_force": 20.0})``.

        ``agent`` sets every agent; keyed by an agent's name (as :attr:`hello`'s ``agents``
        lists them) or its class's name, it sets that agent or that class's agents (protocol
        2.6): ``agent={"Runner1": {"max_force": 6.0}}``. The forms mix, the more precise
        winning (every agent < class < name): ``agent={"max_force": 9.0, "Runner":
        {"max_force": 8.0}, "Runner1": {"max_force": 6.0}}``.

        Raises:
            RemoteError: ``invalid_config`` naming the key the server refused; nothing was
                applied.
        """
        self._call(config=config_request(environment, agent, world))

    def reset(
        self, *, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Start an episode; the same seed gives the same episode.

        Returns:
            ``(observation, info)``.
        """
        self.send_reset(seed=seed, options=options)
        return self.receive_reset()

    def send_reset(
        self, *, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> None:
        """Send a reset request without waiting; collect the answer with :meth:`receive_reset`."""
        self._post(self.reset_request(seed, options, request_id=next(self._ids)))

    def receive_reset(self) -> tuple[Any, dict[str, Any]]:
        """Wait for the answer to the reset sent by :meth:`send_reset`."""
        return self.reset_result(self._answers.reply())  # type: ignore[arg-type]

    def step(self, action: Any, repeat_action: int | None = None) -> StepResult:
        """Run ``action`` for ``repeat_action`` physics ticks (default: the server's setting).

        Returns:
            ``(observation, reward, terminated, truncated, info)``; ``info["frames"]`` is the
            number of ticks that ran (fewer than asked only if the episode ended).

        Raises:
            TypeError: ``action`` is ``None`` (to read the state without acting: :meth:`poll`).
            RemoteError: ``invalid_action`` (shape, dtype, bounds, NaN) or ``reset_required``;
                the environment is unchanged and the client can go on.
        """
        self.send_step(action, repeat_action)
        return self.receive_step()

    def send_step(self, action: Any, repeat_action: int | None = None) -> None:
        """Send a step request without waiting; collect the answer with :meth:`receive_step`.

        Raises:
            TypeError: ``action`` is ``None``.
        """
        if action is None:
            raise TypeError(
                "step() needs an action, got None; to read the episode's state "
                "without acting, call poll()"
            )
        self._post(self.step_request(action, repeat_action, request_id=next(self._ids)))

    def receive_step(self) -> StepResult:
        """Wait for the answer to the step sent by :meth:`send_step`."""
        return self.step_result(self._answers.reply())  # type: ignore[arg-type]

    def poll(self) -> StepResult:
        """The episode's state without acting, as :meth:`step` returns it.

        The reward and ticks are those since the previous answer (in real time the world
        moves on its own; in lockstep nothing ran, so they are 0), the flags say whether the
        episode ended. It sends the protocol's ``action: nil``.

        Raises:
            RemoteError: ``reset_required`` before the first reset.
        """
        self._post(self._requests.poll(next(self._ids)))
        return self.step_result(self._answers.reply())  # type: ignore[arg-type]

    def step_result(self, reply: Response | ErrorReply, *, writable: bool = True) -> StepResult:
        """A step's answer as ``(observation, reward, terminated, truncated, info)``.

        With ``writable=False`` arrays of the observation may be read-only views of the
        received bytes (for callers that copy them anyway, such as vector environments).

        Raises:
            RemoteError: the answer is an error.
        """
        response = reply if reply.__class__ is Response else self._response(reply)
        return (
            self._observation(response, writable),
            response.reward,
            response.terminated,
            response.truncated,
            self._info(response),
        )

    def reset_result(self, reply: Response | ErrorReply) -> tuple[Any, dict[str, Any]]:
        """A reset's answer as ``(observation, info)``.

        Raises:
            RemoteError: the answer is an error.
        """
        response = self._response(reply)
        return self._observation(response), self._info(response)

    def observation_result(self, reply: Response | ErrorReply) -> Any:
        """An answer's agent observation, unpacked (arrays may be read-only views).

        Raises:
            RemoteError: the answer is an error.
        """
        return self._observation(self._response(reply), writable=False)

    def step_request(
        self, action: Any, repeat_action: int | None = None, *, request_id: int = 0
    ) -> Request:
        """The request :meth:`send_step` sends, for a batch (whose parts need no id)."""
        return self._requests.step(action, repeat_action, request_id)

    def reset_request(
        self,
        seed: int | None = None,
        options: Mapping[str, Any] | None = None,
        *,
        request_id: int = 0,
    ) -> Request:
        """The request :meth:`send_reset` sends, for a batch (whose parts need no id)."""
        return self._requests.reset(seed, options, request_id)

    def send_request(self, request: Request) -> None:
        """Send a prepared request (see :meth:`step_request`); its id is assigned here."""
        self._post(Request(next(self._ids), request.parts, request.token))

    def receive_reply(self) -> Response | ErrorReply:
        """Wait for the answer to :meth:`send_request`; an error reply is returned, not raised."""
        return self._answers.reply_or_error()

    def send_batch(self, requests: Sequence[Request | None]) -> None:
        """Send one request per instance of the server (``None``: skip one)."""
        self._post(
            Request(
                next(self._ids),
                {"batch": [None if request is None else request.parts for request in requests]},
            )
        )

    def receive_batch(self) -> tuple[Response | ErrorReply | None, ...]:
        """Wait for the answer to :meth:`send_batch`: one reply per instance.

        Raises:
            RemoteError: the whole batch was refused.
        """
        return self._answers.of_kind(BatchResponse, "a batch").replies

    def send_steps(
        self,
        action: Any,
        reset: np.ndarray | None = None,
        repeat_action: int | None = None,
        reset_with: Sequence[Mapping[str, Any] | None] | None = None,
    ) -> None:
        """Step every instance of the server at once, in columns.

        ``action`` stacks one action per instance (gymnasium's ``batch_space`` layout);
        ``reset`` marks the instances to reset instead (their action is ignored). Collect the
        answer with :meth:`receive_steps`.

        ``reset_with`` (protocol 2.4) holds one entry per instance: ``None``, or the parts its
        reset carries, ``{"reset": {"seed": s, "options": {...}}, "config": {...}}`` (both
        optional), for an instance that ``reset`` marks. Without entries (or with only
        ``None``) the request is as without ``reset_with``.
        """
        self._post(self._requests.steps(action, reset, repeat_action, reset_with, next(self._ids)))

    def receive_steps(self, *, copy: bool = True) -> StepsResponse:
        """Wait for the answer to :meth:`send_steps`.

        Its ``observation`` is the batch of observations (arrays may be read-only views of the
        received bytes); an instance that failed has its error reply in ``errors``. Without
        ``copy``, its arrays may be read-only views of the shared-memory lane, valid only until
        the next request (a vector copies them into its own columns at once).

        Raises:
            RemoteError: the whole request was refused (nothing changed).
        """
        answer = self._answers.of_kind(StepsResponse, "steps", copy)
        _, observations = self._requests.column_codecs()
        answer.observation = self._answers.unpack(observations, answer.observation, writable=False)
        return answer

    def observe(self) -> dict[str, Any]:
        """The current observation without stepping: ``{"agent": ..., "world": ...}``."""
        response = self._call(observation=_AGENT_AND_WORLD)
        return {"agent": self._observation(response), "world": self._part(response, "world")}

    def edit_level(self, level: Any, seed: int, n_edits: int = 1) -> Any:
        """``level`` with ``n_edits`` random changes: the environment's edit, for ACCEL.

        The same level, seed and ``n_edits`` give the same edit; other seeds, other edits. It
        needs no episode and changes nothing of the environment: the episode under way goes on
        as if it had not been asked (protocol 2.4, the ``edit_level`` part). It takes control
        (protocol 2.6; before, it took no control and an observer could ask): the edit holds
        the server while it builds, so only the controller may have it cost the episode that
        time.

        Args:
            level: a level's data, as ``reset(options={"level": ...})`` takes it, or an int
                seed (the level a reset with that seed builds).
            seed: an integer >= 0: where the edit's random choices come from.
            n_edits: how many changes, 1 to 64.

        Returns:
            The edited level's data; play it with ``reset(options={"level": edited})``.

        Raises:
            RemoteError: ``bad_request``: the environment offers no edits (its world has no
                ``_edit_level``), a bad ``seed`` or ``n_edits``, a level beyond the hello's
                ``limits`` (``max_level_nodes``, ``max_level_depth``) or one the environment
                refuses (the message says why); ``environment_error``: its ``_edit_level``
                raised (the episode goes on); ``busy``: another client controls the
                environment.
        """
        edit = {"level": level, "seed": seed, "n_edits": n_edits}
        return self._call(edit_level=edit).info["level"]

    @abstractmethod
    def close(self) -> None:
        """Release the connection (or the in-process environment); safe to repeat."""

    def __enter__(self) -> BaseClient:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # --- transport --------------------------------------------------------------------------

    @abstractmethod
    def _send(self, request: Request) -> None:
        """Deliver ``request`` to the environment."""

    @abstractmethod
    def _receive(self, copy: bool = True) -> Reply:
        """Wait for the environment's next answer (to the oldest request not answered yet).

        Without ``copy``, a ``steps`` answer may hold views valid until the next request.
        """

    def answer_arrived(self) -> bool:
        """Whether the next answer has arrived: receiving it would not wait (a hint).

        In process, every answer is made as its request is sent, so this is always true. A
        vector uses it to wait first for the server that answers last.
        """
        return True

    # --- internals --------------------------------------------------------------------------

    def _call(self, **parts: Any) -> Response:
        self._post(Request(next(self._ids), parts))
        return self._response(self.receive_reply())

    def _post(self, request: Request) -> None:
        """Send ``request``; its answer is the one to wait for from now on."""
        self._answers.awaited = request.id
        self._send(request)

    def _response(self, message: Response | ErrorReply) -> Response:
        return self._answers.response(message)

    def _observation(self, response: Response, writable: bool = True) -> Any:
        observation = response.observation
        if observation is None or "agent" not in observation:
            self._part(response, "agent")  # raises
        try:
            return self._observations.unpack(observation["agent"], writable)  # type: ignore[index]
        except (KeyError, TypeError, ValueError) as error:
            self.close()
            raise ConnectionLost(f"{self.address} broke the protocol: {error}") from None

    def _part(self, response: Response, part: str) -> Any:
        return self._answers.part(response, part)

    _info = staticmethod(answer_info)  # an answer's info, frames and all
