"""RemoteEnv: any rlenv environment as a ``gymnasium.Env``, a thin adaptor over a client.

The spaces come from the server's hello, never from code on this side. The environment is
reached in one of three ways:

- ``RemoteEnv("examples.cartpole:CartPoleEnvironment")`` reaches it in a server subprocess: the
  environments of one process that serve the same class share one (each has an environment of
  its own in it; :mod:`rlenv_client.sharing`), started on a free port for the first of them and
  ended, its whole process group, when the last closes (or at exit);
- ``RemoteEnv(address="127.0.0.1:7000")`` attaches to a running server;
- ``RemoteEnv("examples.cartpole:CartPoleEnvironment", in_process=True)`` runs the environment
  in this process with no socket (debugging, and the baseline for remote figures).

A server that RemoteEnv started and lost (killed, crashed, or silent past the timeout) is
restarted, up to ``max_restarts`` times: the step that was interrupted returns the episode's
last observation with reward 0 and ``truncated=True``, and ``info["server_restarted"]`` says
why. Nothing is sent twice, so no transition is invented or duplicated; call ``reset`` next.

An environment whose agents come and go (the hello's ``possible_agents``, protocol 2.6) keeps
gymnasium's fixed spaces: the observation is a ``Dict`` over every possible agent (the
trainer's), zeros for an agent not in the answer (not in play, or not due to decide), as the
vector envs' ``steps`` columns are; ``info["due"]`` names the agents that decide now, and
``info["agents"]`` holds the rewards and flags of the agents in the answer (the due, and those
that left, once). An action is a ``Dict`` over every possible agent too: only the entries of
the agents due are sent. The reward is the sum of the answer's; the episode ends when the
server's does. A learner per agent is better served by
:class:`~rlenv_client.pettingzoo.RemoteParallelEnv` or
:class:`~rlenv_client.agent_vector.AgentVectorEnv` (a slot per agent, with a mask).

A group of agents (an :class:`~rlenv.agent_group.RLAgentGroup`, protocol 2.7) is one entry of
the ``Dict`` spaces, its members' values stacked: ``observation[group]`` is ``(N, *obs)``
(zeros in the rows of members not in play), the action's entry ``(N, *act)``, and
``info["agents"][group]`` arrays over the members (``reward``, ``terminated``, ``truncated``,
``active``, ``joined``); the reward sums the group's rows with the other agents'.
"""

from __future__ import annotations

import copy
import logging
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import gymnasium
import numpy as np

from rlenv_client._agents_in_play import AgentsInPlay, answer_reward
from rlenv_client._display import Display, display_available
from rlenv_client.base import BaseClient, StepResult
from rlenv_client.launcher import ServerProcess
from rlenv_client.session import LOST, Session
from rlenv_client.time_limits import truncate_agents
from rlenv_client.trainer_view import TrainerView

if TYPE_CHECKING:
    from rlenv_tools.inspector import Inspector

__all__ = ["RemoteEnv"]

logger = logging.getLogger(__name__)


class RemoteEnv(gymnasium.Env):
    """A gymnasium environment whose simulation runs in an rlenv server.

    ``metadata["render_modes"]`` lists ``"human"`` only where a display is available.

    Args:
        target: the environment class as ``MODULE:CLASS``; a server is started for it.
        address: ``HOST:PORT`` of a running server, instead of ``target``.
        repeat_action: physics ticks each :meth:`step` runs; the server's default if ``None``.
        max_episode_steps: truncate episodes after this many steps (``None``: never), as
            gymnasium's ``TimeLimit`` does; with several agents, every agent still in the
            episode is truncated in ``info["agents"]`` too (the registered multi-agent ids
            pass theirs here).
        render_mode: ``"rgb_array"`` (frames as arrays), ``"human"`` (a window; needs a
            display) or ``None``.
        in_process: run the environment inside this process instead of a server.
        timeout: seconds to wait for each answer before :class:`RequestTimeout`.
        server_args: extra arguments for ``rlenv serve``.
        render_size: (width, height) of rendered frames; the environment's default if ``None``.
        token: the secret of a server that requires one (default ``$RLENV_TOKEN``).
        max_restarts: how many times a lost server that this environment started is replaced.
        inspector: also start the live inspector (:mod:`rlenv_tools.inspector`) on the
            server: its page's address is printed on standard error and kept in
            ``inspector.url``.
        shared_memory: step through a shared-memory lane when the server is on this
            machine (see :class:`~rlenv_client.client.Client`): by default when it can.
        share_server: with a ``target``, share this process's server of it with the other
            environments of the same target and ``server_args`` (the default), rather than
            start a server of its own. Either way the environment is this one's alone; the
            inspector always gets a server of its own.

    Attributes:
        target: the ``MODULE:CLASS`` it serves (what :class:`~rlenv_client.replay.RecordEpisodes`
            records), or ``None`` when reached at an ``address``.

    Raises:
        ServerStartError: the server could not start (its output is in the message).
        RuntimeError: ``render_mode="human"`` without a display.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array", "human"], "render_fps": 15}

    def __init__(
        self,
        target: str | None = None,
        *,
        address: str | None = None,
        repeat_action: int | None = None,
        render_mode: str | None = None,
        in_process: bool = False,
        timeout: float = 30.0,
        server_args: Sequence[str] = (),
        render_size: tuple[int, int] | None = None,
        token: str | None = None,
        max_restarts: int = 3,
        inspector: bool = False,
        shared_memory: bool | None = None,
        share_server: bool = True,
        max_episode_steps: int | None = None,
    ) -> None:
        self.metadata = {"render_modes": ["rgb_array"], "render_fps": 15}
        if display_available():
            self.metadata["render_modes"].append("human")
        if render_mode is not None and render_mode not in ("rgb_array", "human"):
            raise ValueError(
                f"render_mode must be 'rgb_array', 'human' or None, got {render_mode!r}"
            )
        if max_episode_steps is not None and max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be at least 1, got {max_episode_steps}")
        if render_mode == "human" and not display_available():
            raise RuntimeError(
                "render_mode='human' needs a display, and none is available "
                "(DISPLAY is not set); use render_mode='rgb_array' instead"
            )
        self.target = target
        self.session = Session(
            target,
            address=address,
            in_process=in_process,
            max_restarts=max_restarts,
            timeout=timeout,
            server_args=server_args,
            token=token,
            shared_memory=shared_memory,
            share_server=share_server and not inspector,
        )
        hello = self.client.hello
        try:
            self._view = TrainerView(hello)
        except ValueError:
            self.session.close()
            raise
        self._in_play = AgentsInPlay(self._view) if hello.possible_agents is not None else None
        self.action_space = self._view.action_space
        self.observation_space = self._view.observation_space
        self.repeat_action = repeat_action
        self.max_episode_steps = max_episode_steps
        self._steps = 0
        ticks = repeat_action or hello.repeat_action
        self.metadata["render_fps"] = hello.physics_ticks_per_second / ticks
        self.render_mode = render_mode
        self.render_size = render_size
        self._display: Display | None = None
        self._last_observation: Any = None
        self.inspector: Inspector | None = None
        if inspector:
            from rlenv_tools.inspector import inspect_sessions

            try:
                self.inspector = inspect_sessions([self.session])
            except BaseException:
                self.session.close()
                raise
        logger.info("connected to %s at %s", hello.environment, self.client.address)

    @property
    def client(self) -> BaseClient:
        """The client of the current server (it changes when a lost server is restarted)."""
        return self.session.client

    @property
    def server(self) -> ServerProcess | None:
        """The server process this environment reaches, if rlenv started it (``None``: not).

        A shared server (``share_server``) serves other environments of this process too.
        """
        return self.session.server

    def configure(self, **settings: Any) -> None:
        """Configure the environment (see ``Client.configure``); replayed after a restart.

        ``agent`` sets every agent, or one agent by its name (or a class by its name):
        ``configure(agent={"Runner1": {"max_force": 6.0}})``.
        """
        self.session.configure(**settings)

    def reset(
        self, *, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Start an episode; ``seed`` makes it reproducible, on any server."""
        super().reset(seed=seed)
        try:
            observation, info = self.client.reset(seed=seed, options=options)
        except LOST as error:  # nothing happened yet: reset the replacement instead
            self.session.restart(error)
            observation, info = self.client.reset(seed=seed, options=options)
        if self._in_play is not None:
            self._in_play.start(observation)
            observation = self._in_play.full_observation(observation)
            info = {**info, "due": self._in_play.due}
        else:
            observation = self._view.observation(observation)
        self._last_observation = observation
        self._steps = 0
        if self.render_mode == "human":
            self.render()
        return observation, info

    def step(self, action: Any) -> StepResult:
        """Run ``action`` for ``repeat_action`` physics ticks; ``info["frames"]`` says how many.

        Agents the server drives (the hello's ``driven``) are left out of the spaces, the
        action, the observation, the reward and the episode's end
        (:mod:`rlenv_client.trainer_view`).

        Raises:
            ValueError: ``action`` has an entry for an agent the server drives.
            ConnectionLost: the server was lost and cannot be restarted (with how it exited).
        """
        action = self._view.action(action)
        if self._in_play is not None and isinstance(action, Mapping):
            action = self._in_play.action(action)
        try:
            result = self.client.step(action, self.repeat_action)
        except LOST as error:
            if self._last_observation is None:
                raise self.session.failure(error) from None
            reason = self.session.restart(error)
            return (
                copy.deepcopy(self._last_observation),
                0.0,
                False,
                True,
                {"frames": 0, "server_restarted": reason},
            )
        result = (
            self._view.result(result) if self._in_play is None else self._in_play_result(result)
        )
        self._last_observation = result[0]
        self._steps += 1
        if self.max_episode_steps is not None and self._steps >= self.max_episode_steps:
            observation, reward, terminated, _, info = result
            result = observation, reward, terminated, True, truncate_agents(info)
        if self.render_mode == "human":
            self.render()
        return result

    def _in_play_result(self, result: StepResult) -> StepResult:
        """A step's result when agents come and go: fixed slots, the trainer's reward, the due."""
        assert self._in_play is not None
        observation, _, terminated, truncated, info = result
        self._in_play.answer(observation, info, ended=terminated or truncated)
        return (
            self._in_play.full_observation(observation),
            answer_reward(info, self._view.agents),
            terminated,
            truncated,
            {**info, "due": self._in_play.due},
        )

    def render(self) -> np.ndarray | None:
        """The current frame (``rgb_array``), or show it in the window (``human``)."""
        if self.render_mode is None:
            gymnasium.logger.warn("render() was called with render_mode=None; nothing to draw")
            return None
        width, height = self.render_size or (None, None)
        try:
            frame = self.client.render(width, height)
        except LOST as error:
            raise self.session.failure(error) from None
        if self.render_mode == "rgb_array":
            return frame
        if self._display is None:
            self._display = Display(f"rlenv: {self.client.hello.environment}")
        self._display.show(frame)
        return None

    def close(self) -> None:
        """Disconnect and stop the server this environment started; safe to repeat."""
        if self._display is not None:
            self._display.close()
            self._display = None
        if self.inspector is not None:
            self.inspector.close()
            self.inspector = None
        self.session.close()

    def __repr__(self) -> str:
        return f"<RemoteEnv {self.client.hello.environment} at {self.client.address}>"
