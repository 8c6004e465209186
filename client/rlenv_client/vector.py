"""RemoteVectorEnv: N environments stepped concurrently, as a ``gymnasium.vector.VectorEnv``.

Every step sends all requests first and then gathers the answers, so the servers simulate in
parallel while the trainer waits once. The N sub-environments live in servers this vector starts
(``instances_per_server`` per server: by default as many servers as cores, each hosting its
share), in running servers given by address (each hosting as many instances as its hello
says), in the servers of a Ray pool (:mod:`rlenv_client.ray`), or in this process. Every
server gets one ``steps`` request per step (its instances' actions in, observations, rewards
and flags out, in columns) and one ``batch`` per reset or render, however many instances it
hosts.

Autoreset follows gymnasium 1.x (:class:`gymnasium.vector.AutoresetMode`):

- ``NEXT_STEP`` (default): the step after a sub-environment terminated or was truncated resets
  it instead of stepping it; that step returns the reset observation, reward 0 and both flags
  false, and ignores the sub-environment's action.
- ``SAME_STEP``: a sub-environment that ends is reset within the same step; the returned
  observation is the reset one, and ``info["final_obs"]`` / ``info["final_info"]`` hold the
  last observation and info of the episode that ended.

Agents the servers drive themselves (``rlenv serve --policy``, the hello's ``driven``) are left
out of the spaces, actions, observations, rewards and episode ends, as
:class:`~rlenv_client.env.RemoteEnv` leaves them (:mod:`rlenv_client.trainer_view`).

Agents that come and go (the hello's ``possible_agents``, protocol 2.6) keep a fixed slot
each: the observation has every possible agent's entry, zeros where the agent is not in the
sub-environment's answer (not in play, or not due), as the ``steps`` columns have it;
``infos["due"][name]`` is a column of whether agent ``name`` is in each answer (due, or
leaving with its final transition), and ``infos["agents"]`` masks each agent's outcome to
the rows whose answer holds it (a joined agent's first reward, ``None``, is 0.0). The rows of
the action column of agents not due are ignored by the servers.

A group of agents (an :class:`~rlenv.agent_group.RLAgentGroup`, protocol 2.7) stays one array:
its observation column is ``(num_envs, N, *obs)``, its action column ``(num_envs, N, *act)``
(rows of members not in play are ignored), and ``infos["agents"][group]`` holds its outcome
arrays stacked, ``(num_envs, N)`` each (``reward``, ``terminated``, ``truncated``,
``active``, ``joined``). :class:`~rlenv_client.agent_vector.AgentVectorEnv` makes each member
a sub-environment.

``max_episode_steps`` truncates each sub-environment's episodes, as ``TimeLimit`` does (with
several agents, each agent still in the episode is truncated in ``info["agents"]``). A lost
server that this vector started is restarted (``max_restarts`` each), and one of a pool is
found again wherever the pool brought it back: the interrupted episodes
of its instances end as truncated with their last observation, reward 0 and
``info["server_restarted"]``, and the autoreset that follows starts fresh episodes.

A step or reset interrupted half way (a ``KeyboardInterrupt`` in a notebook) leaves servers
that stepped without the vector seeing it: the next step then sends nothing and ends every
episode as truncated, with the last observations returned, reward 0 and
``info["interrupted"]``; the autoreset that follows starts fresh episodes (the answers the
interrupted step left behind are dropped, never taken for later ones).

:meth:`RemoteVectorEnv.set_next_reset` gives one sub-environment's next reset (its autoreset,
or the next :meth:`~RemoteVectorEnv.reset`) a seed, reset options and settings of its own, as a
curriculum needs (:class:`~rlenv_client.curriculum.CurriculumVectorEnv`): inside a step, they
travel in the ``steps`` request's ``reset_with`` (protocol 2.4), on the socket; steps without
them are sent as before.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, create_empty_array

from rlenv.protocol import ErrorReply, Request, Response
from rlenv_client._agents_in_play import AgentSlots, answer_reward, due_columns, with_column
from rlenv_client._rows import check_shape, empty_like, row
from rlenv_client._server_groups import ServerGroups
from rlenv_client._step_columns import StepColumns
from rlenv_client._vector_infos import BatchedInfos
from rlenv_client._vector_resets import Resets
from rlenv_client.base import BaseClient
from rlenv_client.launcher import ServerProcess
from rlenv_client.session import ServerSource, Session
from rlenv_client.time_limits import truncate_agents
from rlenv_client.trainer_view import TrainerView
from rlenv_client.vector_servers import (
    connect_sessions,
    default_layout,
    exchange,
    server_places,
    sure_reply,
)

if TYPE_CHECKING:
    from rlenv_tools.inspector import Inspector

__all__ = ["RemoteVectorEnv", "default_layout"]

logger = logging.getLogger(__name__)

Reply = Response | ErrorReply


class RemoteVectorEnv(VectorEnv):
    """``num_envs`` copies of one rlenv environment, stepped concurrently.

    Args:
        num_envs: how many sub-environments (1 by default). With ``addresses`` or ``pool``, as
            many as their servers host (checked when given).
        target: the environment class as ``MODULE:CLASS``; servers are started for it.
        addresses: ``HOST:PORT`` of running servers instead (each hosts the instances its hello
            announces).
        pool: the servers of a :class:`~rlenv_client.ray.RayServerPool` (or of a lease of
            one) instead: every one of them, each asked for its address on every connection.
        repeat_action: physics ticks per step; the servers' default if ``None``.
        max_episode_steps: truncate episodes after this many steps (at least 1; ``None``: never).
        autoreset_mode: ``NEXT_STEP`` or ``SAME_STEP``.
        in_process: run the copies inside this process instead of servers (by default all of
            them in one group, stepped in columns as a multi-instance server steps them).
        render_mode: ``"rgb_array"`` to render every copy, or ``None``.
        timeout: seconds to wait for each answer.
        token: the secret of servers that require one (default ``$RLENV_TOKEN``).
        max_restarts: how many times each lost server that this vector started is replaced.
        instances_per_server: how many sub-environments each started server hosts; by default
            one server per core (see :func:`default_layout`).
        inspector: also start the live inspector (:mod:`rlenv_tools.inspector`) on every
            server: its page's address is printed on standard error and kept in
            ``inspector.url``.
        shared_memory: step servers on this machine through shared-memory lanes (see
            :class:`~rlenv_client.client.Client`): by default wherever they can.
        server_args: extra arguments for the servers this vector starts (``rlenv serve``),
            e.g. ``["--policy", "Runner1=heuristic"]``.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": ["rgb_array"]}

    def __init__(
        self,
        num_envs: int | None = None,
        target: str | None = None,
        *,
        addresses: Sequence[str] | None = None,
        pool: ServerSource | None = None,
        repeat_action: int | None = None,
        max_episode_steps: int | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        in_process: bool = False,
        render_mode: str | None = None,
        timeout: float = 30.0,
        token: str | None = None,
        max_restarts: int = 3,
        instances_per_server: int | None = None,
        inspector: bool = False,
        shared_memory: bool | None = None,
        server_args: Sequence[str] = (),
    ) -> None:
        self.sessions: list[Session] = []  # first: closing a half-built vector closes these
        self.inspector: Inspector | None = None
        started = addresses is None and pool is None and not in_process
        mode = _checked_mode(autoreset_mode, max_episode_steps, render_mode, server_args, started)
        places = server_places(
            num_envs, target, addresses, pool, in_process, token, instances_per_server, server_args
        )
        connect_sessions(
            self.sessions,
            places,
            timeout=timeout,
            max_restarts=max_restarts,
            shared_memory=shared_memory,
        )
        self._servers = ServerGroups(self.sessions)
        hello = self.clients[0].hello
        try:
            self._servers.check(num_envs if addresses is not None or pool is not None else None)
            self._view = TrainerView(hello)
        except ValueError:
            self.close()
            raise
        self.num_envs = self._servers.num_envs
        self.single_action_space = self._view.action_space
        self.single_observation_space = self._view.observation_space
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.metadata = {
            **self.metadata,
            "autoreset_mode": mode,
            "render_fps": hello.physics_ticks_per_second / (repeat_action or hello.repeat_action),
        }
        self.render_mode = render_mode
        self.repeat_action = repeat_action
        self.max_episode_steps = max_episode_steps
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)
        self._infos = BatchedInfos(self._add_info, self.num_envs)
        self._observations_template = create_empty_array(
            self.single_observation_space, self.num_envs
        )
        self._steps = np.zeros(self.num_envs, dtype=np.int64)
        self._slots = AgentSlots(self._view) if hello.possible_agents is not None else None
        self._resets = Resets(
            self.sessions,
            self._servers.groups,
            self._servers.client_of,
            None if self._slots is None else self._slots.fill,
        )
        self._last: Any = None  # the last batch of observations returned
        self._interrupted: str | None = None  # what interrupted the last step or reset
        if inspector:
            self._start_inspector()

    @property
    def clients(self) -> list[BaseClient]:
        """One client per server (they change when a server is restarted)."""
        return [session.client for session in self.sessions]

    @property
    def servers(self) -> list[ServerProcess]:
        """The server processes this vector started."""
        return [session.server for session in self.sessions if session.server is not None]

    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: Mapping[str, Any] | None = None,
    ) -> tuple[Any, dict[str, Any]]:
        """Reset every sub-environment; an int ``seed`` seeds them ``seed``, ``seed + 1`` ...

        Raises:
            ValueError: a list of seeds of the wrong length.
            ConnectionLost: a server went away (with how it exited, if it died).
        """
        self._interrupted = None
        try:
            return self._reset(seed, options)
        except BaseException as error:
            self._note_interruption(error)
            raise

    def _reset(
        self, seed: int | Sequence[int | None] | None, options: Mapping[str, Any] | None
    ) -> tuple[Any, dict[str, Any]]:
        if seed is None or isinstance(seed, int):
            seeds: list[int | None] = [
                None if seed is None else seed + i for i in range(self.num_envs)
            ]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"{len(seeds)} seeds for {self.num_envs} environments")
        super().reset(seed=seed if isinstance(seed, int) else None)
        observations = create_empty_array(self.single_observation_space, self.num_envs)
        frames = np.zeros(self.num_envs, np.int64)
        due = due_columns(self._slots, self.num_envs)
        infos = self._resets.reset(range(self.num_envs), observations, frames, seeds, options, due)
        self._autoreset[:] = False
        self._steps[:] = 0
        self._last = observations
        merged = self._infos.merge({}, [infos[i] for i in range(self.num_envs)], frames)
        return observations, with_column(merged, "due", due, self.num_envs)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every sub-environment (resetting those that ended, per the autoreset mode).

        Every server gets one ``steps`` request (actions in, observations, rewards and flags
        out, in columns).

        Raises:
            TypeError: ``actions`` is ``None``.
            ValueError: ``actions`` does not hold one action per sub-environment (its shape
                and the expected one are named); nothing was sent.
            RemoteError: a server refused the step (e.g. ``invalid_action``) or a
                sub-environment failed; every server was answered first.
            ConnectionLost: a server went away and cannot be restarted (with how it exited).
        """
        if actions is None:
            raise TypeError(
                f"step() needs an action for each of the {self.num_envs} sub-environments, got None"
            )
        self._view.action(actions)
        check_shape(self.action_space, actions, "actions")
        try:
            return self._step(actions)
        except BaseException as error:
            self._note_interruption(error)
            raise

    def _step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        resetting = (
            self._autoreset
            if self._mode is AutoresetMode.NEXT_STEP
            else np.zeros(self.num_envs, dtype=np.bool_)
        )
        columns = self._step_everywhere(actions, resetting)
        observations, rewards, terminations, truncations, frames, env_infos = columns
        steps = self._steps
        steps += 1
        steps[resetting] = 0  # these started an episode instead
        if self.max_episode_steps is not None:
            timed_out = steps >= self.max_episode_steps
            truncations |= timed_out
            for index in np.flatnonzero(timed_out):  # with several agents, each of them too
                env_infos[index] = truncate_agents(env_infos[index])
        ended = terminations | truncations
        infos: dict[str, Any] = {}
        if self._mode is AutoresetMode.SAME_STEP and ended.any():
            for index in np.flatnonzero(ended):
                final_info = {**env_infos[index], "frames": int(frames[index])}
                infos = self._add_info(
                    infos,
                    {"final_obs": row(observations, index), "final_info": final_info},
                    int(index),
                )
            restarted = self._resets.reset(
                np.flatnonzero(ended), observations, frames, due=columns.due
            )
            for reset_index, info in restarted.items():
                env_infos[reset_index] = info
                self._steps[reset_index] = 0
        self._autoreset = ended
        self._last = observations
        return (
            observations,
            rewards,
            terminations,
            truncations,
            with_column(
                self._infos.merge(infos, env_infos, frames), "due", columns.due, self.num_envs
            ),
        )

    def _step_everywhere(self, actions: Any, resetting: np.ndarray) -> StepColumns:
        """Send every server its share of the step, then gather the answers into columns.

        A server that is lost and restarted gives its sub-environments their last observation,
        truncated, with ``info["server_restarted"]``; after an interrupted step or reset, every
        sub-environment does so, with ``info["interrupted"]``, and nothing is sent.
        """
        if self._interrupted is not None:
            return self._after_interruption()
        starts = self._resets.take_marked(resetting)
        actions = self._view.full_actions(actions, self.num_envs)
        # every row of the observations is written by the servers' answers
        columns = StepColumns(
            empty_like(self._observations_template),
            self.num_envs,
            None if self._slots is None else self._slots.names,
        )
        self._servers.step(actions, resetting, self.repeat_action, starts, columns, self._last)
        if self._view.driven and self._slots is not None:  # the trainer's agents' rewards
            for index, info in enumerate(columns.env_infos):  # (the episode's end is theirs)
                columns.rewards[index] = answer_reward(info, self._view.agents)
        elif self._view.driven:  # the trainer's agents' rewards and ends, not every agent's
            for index, info in enumerate(columns.env_infos):
                if "agents" in info:  # not in a lost server's
                    (
                        columns.rewards[index],
                        columns.terminations[index],
                        columns.truncations[index],
                    ) = self._view.outcome(info)
        return columns

    def _after_interruption(self) -> StepColumns:
        """The step after an interrupted one: every episode ends, truncated (see the module)."""
        why = f"the previous step or reset was interrupted ({self._interrupted})"
        self._interrupted = None
        if self._last is None:
            raise RuntimeError(f"{why} before any observation: call reset()")
        columns = StepColumns(
            empty_like(self._observations_template),
            self.num_envs,
            None if self._slots is None else self._slots.names,
        )
        columns.cut_short(range(self.num_envs), self._last, {"interrupted": why})
        return columns

    def _note_interruption(self, error: BaseException) -> None:
        """Remember an interruption (not an error) that escaped a step or reset, for the next."""
        if not isinstance(error, Exception):
            self._interrupted = type(error).__name__

    def set_next_reset(
        self,
        index: int,
        *,
        seed: int | None = None,
        options: Mapping[str, Any] | None = None,
        config: Mapping[str, Any] | None = None,
    ) -> None:
        """Give sub-environment ``index``'s next reset a seed, options and settings of its own.

        They apply once, at its next autoreset (inside a step, as the ``steps`` request's
        ``reset_with``) or at the next :meth:`reset` (in place of that call's seed and options
        for this sub-environment); setting them again before then replaces them.

        Args:
            index: the sub-environment, in ``[0, num_envs)``.
            seed: the episode's seed (``None``: its generator continues).
            options: its reset options (``{"level": data}``, say).
            config: settings to configure before the reset, as :meth:`BaseClient.configure`'s
                keywords (``{"world": {"difficulty": 0.3}}``; see
                :func:`~rlenv_client.curriculum.configure_arguments`).

        Raises:
            IndexError: ``index`` is out of range.
        """
        if not 0 <= index < self.num_envs:
            raise IndexError(f"sub-environment {index} of {self.num_envs}")
        self._resets.set_next(index, seed, options, config)

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One frame per sub-environment (``rgb_array``)."""
        if self.render_mode is None:
            return None
        plan: list[Request | None] = [
            self._servers.client_of(i).render_request() for i in range(self.num_envs)
        ]
        replies = exchange(self.sessions, self._servers.groups, plan)
        return tuple(
            self._servers.client_of(index).render_result(sure_reply(index, reply))
            for index, reply in enumerate(replies)
        )

    def __enter__(self) -> RemoteVectorEnv:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close_extras(self, **kwargs: Any) -> None:
        """Disconnect every client and stop every server this environment started."""
        if self.inspector is not None:
            self.inspector.close()
            self.inspector = None
        for session in self.sessions:
            session.close()

    # --- internals --------------------------------------------------------------------------

    def _start_inspector(self) -> None:
        """Start the live inspector on every server; a vector it fails for is closed."""
        from rlenv_tools.inspector import inspect_sessions

        try:
            self.inspector = inspect_sessions(self.sessions)
        except BaseException:
            self.close()
            raise

    @property
    def _mode(self) -> AutoresetMode:
        return self.metadata["autoreset_mode"]


def _checked_mode(
    autoreset_mode: AutoresetMode | str,
    max_episode_steps: int | None,
    render_mode: str | None,
    server_args: Sequence[str],
    started: bool,
) -> AutoresetMode:
    """The autoreset mode, once the vector's arguments are checked.

    ``started`` says whether the vector starts its servers itself (``server_args`` are theirs).

    Raises:
        ValueError: the argument at fault, named.
    """
    mode = AutoresetMode(autoreset_mode)
    if mode is AutoresetMode.DISABLED:
        raise ValueError("RemoteVectorEnv autoresets; use NEXT_STEP or SAME_STEP")
    if max_episode_steps is not None and max_episode_steps < 1:
        raise ValueError(f"max_episode_steps must be at least 1, got {max_episode_steps}")
    if render_mode not in (None, "rgb_array"):
        raise ValueError(f"render_mode must be 'rgb_array' or None, got {render_mode!r}")
    if server_args and not started:
        raise ValueError(
            "server_args are for the servers a vector starts, not for "
            "addresses, a pool or in_process"
        )
    return mode
