"""Stable-Baselines3 ``VecEnv`` over :class:`~rlenv_client.vector.RemoteVectorEnv`.

SB3 wraps single environments in its ``DummyVecEnv``, which steps them one after the other: one
round trip per environment per step. :class:`SB3VecEnv` instead sends every sub-environment's
request at once and waits once, and uses ``SAME_STEP`` autoreset, which is SB3's convention (the
observation returned for a finished environment is the first of its next episode; the last one
is in ``info["terminal_observation"]``, and ``info["TimeLimit.truncated"]`` tells truncation).
With ``agents=``, the sub-environments are the learning agents of ``num_envs`` instances of a
multi-agent environment (:class:`~rlenv_client.agent_vector.AgentVectorEnv`): one agent, or a
team sharing one policy, trains straight from the game; ``others`` says what drives the other
agents (their heuristics by default). Each finished episode's statistics are in
``info["episode"]`` (``r``: return, ``l``: length, ``t``: seconds since the vector was made),
as SB3's ``Monitor`` gives them, so that ``ep_rew_mean`` is logged without a ``VecMonitor``
(wrapping it in one anyway overwrites them with the same figures); a learner's wait for its
instance to reset counts as no episode.

Agents that come and go (``possible_agents``, protocol 2.6) keep a slot each
(:class:`~rlenv_client.agent_vector.AgentVectorEnv`), and SB3 cannot skip a row: a slot whose
agent does not decide now (``info["is_active"]`` false) carries the agent's last observation
(zeros before it joins), reward 0 and no done, and its action is ignored by the server. An
agent that leaves ends its slot's episode, ``terminated`` or ``truncated``, with
``info["terminal_observation"]``; the slot then waits (``info["waiting"]``) until the agent's
name is next in play, in a later episode of its instance. The steps a slot waits are in no
episode's length.

A group of agents (``agents=GROUP``, an :class:`~rlenv.agent_group.RLAgentGroup`) gives a
sub-environment per member per instance (``num_envs`` instances of ``N`` members: ``num_envs * N``
of SB3's), the same way: a member that ends gives its ``terminal_observation`` and its
``episode`` once, then its slot waits (zeros) until its instance resets; one that joins starts
an episode from its first observation. One policy learns from every member.

:class:`CurriculumCallback` scores the levels of a
:class:`~rlenv_client.curriculum.CurriculumVectorEnv` (given to :class:`SB3VecEnv` as
``vector``) from each rollout's advantages and values (PLR's positive value loss, or
``max_mc``), and with ``sampler.robust`` keeps PPO from learning from new levels.

Needs the optional extra: ``pip install 'rlenv[sb3]'`` (on a machine without CUDA, install a CPU
build of torch first).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from typing import Any, cast

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from rlenv_client.agent_vector import Agents, AgentVectorEnv, OtherPolicy
from rlenv_client.curriculum.vector import CurriculumVectorEnv
from rlenv_client.selfplay import FrozenPolicy
from rlenv_client.vector import RemoteVectorEnv
from rlenv_client.vector_servers import default_layout

__all__ = ["CurriculumCallback", "SB3VecEnv", "SelfPlayCallback"]

logger = logging.getLogger(__name__)


class SB3VecEnv(VecEnv):
    """``num_envs`` rlenv environments as one SB3 vectorised environment.

    Args:
        num_envs: how many sub-environments; with ``agents``, how many instances of the
            environment (each gives one sub-environment per learning agent, or per member of
            a learning group).
        target: the environment class as ``MODULE:CLASS``, or a registered id's target.
        addresses: ``HOST:PORT`` of running servers instead of starting them.
        repeat_action: physics ticks per step (the servers' default if ``None``).
        max_episode_steps: truncate episodes after this many steps.
        in_process: run the environments inside this process.
        render_mode: ``"rgb_array"`` or ``None``.
        instances_per_server: how many environments each started server hosts; by default
            one server per core but one, which is left to the trainer (its policy runs between
            steps, while the servers wait: see ``docs/training-fast.md``).
        vector: a gymnasium vector environment to adapt instead of making one (the other
            arguments but ``render_mode`` are then ignored): a ``RemoteVectorEnv`` with
            ``SAME_STEP`` autoreset, or a wrapper of one such as a
            :class:`~rlenv_client.curriculum.CurriculumVectorEnv`.
        agents: of a multi-agent environment, which agents learn: names, or an RLAgent class
            for all its agents (one policy shared); see
            :class:`~rlenv_client.agent_vector.AgentVectorEnv`.
        others: with ``agents``, what drives each other agent, by name: an ONNX file,
            ``"heuristic"`` or ``policy(observation) -> action``; by default its heuristic.

    Raises:
        ValueError: ``vector`` autoresets otherwise than ``SAME_STEP``; ``others`` without
            ``agents``, or ``agents`` with ``vector``; see
            :class:`~rlenv_client.agent_vector.AgentVectorEnv` for the rest.
    """

    def __init__(
        self,
        num_envs: int = 1,
        target: str | None = None,
        *,
        addresses: Sequence[str] | None = None,
        repeat_action: int | None = None,
        max_episode_steps: int | None = None,
        in_process: bool = False,
        render_mode: str | None = None,
        instances_per_server: int | None = None,
        vector: VectorEnv | None = None,
        agents: Agents | None = None,
        others: Mapping[Any, OtherPolicy] | None = None,
    ) -> None:
        if others is not None and agents is None:
            raise ValueError(
                "others says what drives the agents that do not learn: give agents= too"
            )
        if agents is not None and vector is not None:
            raise ValueError("agents= makes the vector: give agents or vector, not both")
        if agents is not None:
            vector = AgentVectorEnv(
                None if addresses is not None else num_envs,
                target,
                agents=agents,
                others=others,
                addresses=addresses,
                repeat_action=repeat_action,
                max_episode_steps=max_episode_steps,
                in_process=in_process,
                render_mode=render_mode,
                instances_per_server=instances_per_server,
                trainer_cores=1,
            )
        if vector is not None:
            if vector.metadata.get("autoreset_mode") is not AutoresetMode.SAME_STEP:
                raise ValueError(
                    "SB3VecEnv needs a vector with SAME_STEP autoreset (SB3's "
                    f"convention), not {vector.metadata.get('autoreset_mode')}"
                )
            self.venv: VectorEnv = vector
        else:
            if instances_per_server is None and addresses is None and not in_process:
                instances_per_server = default_layout(num_envs, trainer_cores=1)[0]
            self.venv = RemoteVectorEnv(
                None if addresses is not None else num_envs,
                target,
                addresses=addresses,
                repeat_action=repeat_action,
                max_episode_steps=max_episode_steps,
                autoreset_mode=AutoresetMode.SAME_STEP,
                in_process=in_process,
                render_mode=render_mode,
                instances_per_server=instances_per_server,
            )
        super().__init__(
            self.venv.num_envs, self.venv.single_observation_space, self.venv.single_action_space
        )
        self.render_mode = render_mode
        self._actions: np.ndarray | None = None
        self._started = time.time()
        self._episode_returns = np.zeros(self.num_envs, np.float64)
        self._episode_lengths = np.zeros(self.num_envs, np.int64)
        self._waiting = np.zeros(self.num_envs, np.bool_)  # as the last step left them

    def reset(self) -> VecEnvObs:
        """Reset every environment, with the seeds given to SB3's ``VecEnv.seed()`` if any."""
        seeds = self._seeds if any(seed is not None for seed in self._seeds) else None
        observations, infos = self.venv.reset(seed=seeds, options=self._options[0] or None)
        self.reset_infos = _split_infos(infos, self.num_envs)
        self._episode_returns[:] = 0
        self._episode_lengths[:] = 0
        self._waiting = self._waiting_in(infos)
        self._reset_seeds()
        self._reset_options()
        return observations

    def step_async(self, actions: np.ndarray) -> None:
        """Remember the actions; :meth:`step_wait` sends them all at once."""
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        """Step every environment concurrently and translate to SB3's conventions.

        A finished environment's info is that of its episode's last step (with
        ``server_restarted`` or ``interrupted`` when that is how it ended), as SB3's own
        vectors give it, and its statistics in ``info["episode"]``, as SB3's ``Monitor``
        gives them.
        """
        observations, rewards, terminated, truncated, infos = self.venv.step(self._actions)
        dones = terminated | truncated
        self._episode_returns += rewards
        self._episode_lengths += ~self._waiting  # a slot's wait is in no episode
        self._waiting = self._waiting_in(infos)
        per_env = _split_infos(infos, self.num_envs)
        ended = np.flatnonzero(dones)
        final = _split_infos(infos["final_info"], self.num_envs) if ended.size else []
        for index in ended:
            per_env[index] = {**per_env[index], **final[index]}  # the last step's, as SB3 has it
            per_env[index]["terminal_observation"] = infos["final_obs"][index]
            per_env[index]["TimeLimit.truncated"] = bool(truncated[index] and not terminated[index])
            if not final[index].get("waiting"):  # a learner's wait ends: no episode to count
                per_env[index]["episode"] = {
                    "r": round(float(self._episode_returns[index]), 6),
                    "l": int(self._episode_lengths[index]),
                    "t": round(time.time() - self._started, 6),
                }
            self._episode_returns[index] = 0
            self._episode_lengths[index] = 0
        return observations, rewards.astype(np.float32), dones, per_env

    def _waiting_in(self, infos: Mapping[str, Any]) -> np.ndarray:
        """Which slots wait (:class:`~rlenv_client.agent_vector.AgentVectorEnv`'s ``waiting``)."""
        waiting = infos.get("waiting")
        if waiting is None:
            return np.zeros(self.num_envs, np.bool_)
        return np.asarray(waiting, np.bool_) & np.asarray(infos["_waiting"], np.bool_)

    def close(self) -> None:
        """Stop every server this environment started."""
        self.venv.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        """One frame per environment (needs ``render_mode="rgb_array"``)."""
        frames = self.venv.render()
        if frames is None:
            return [None] * self.num_envs
        return list(cast(Sequence[np.ndarray], frames))  # rgb_array: each frame an array

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """An attribute of the vector environment, repeated for each selected index."""
        return [getattr(self.venv, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Not supported: the environments live in other processes."""
        raise AttributeError(f"cannot set {attr_name!r} on remote environments")

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: VecEnvIndices = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        """Not supported: the environments live in other processes."""
        raise AttributeError(f"cannot call {method_name!r} on remote environments")

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """The remote environments are never wrapped on this side."""
        return [False] * len(self._get_indices(indices))


class CurriculumCallback(BaseCallback):
    """Scores a curriculum's levels from each PPO (or A2C) rollout, for a trainer on SB3.

    At the end of every rollout, each episode that ended in it is scored from the rollout
    buffer's advantages and values (:meth:`CurriculumVectorEnv.score_rollout`). With
    ``wrapper.sampler.robust`` (Robust PLR), the transitions of new levels are then taken out
    of learning: their advantages are set to 0 and their returns to their values, so that
    they add nothing to the policy or value loss. SB3 has no per-transition mask: this is
    exact only without advantage normalisation (``PPO(normalize_advantage=False)``; checked),
    and the entropy bonus still sees those states.

    Args:
        wrapper: the :class:`~rlenv_client.curriculum.CurriculumVectorEnv` the model's
            :class:`SB3VecEnv` adapts, made with ``score="external"``.
        score: ``"positive_value_loss"`` or ``"max_mc"``.
        verbose: SB3's verbosity.

    Raises:
        ValueError: the wrapper scores episodes itself, or ``score`` is unknown.
    """

    def __init__(
        self, wrapper: CurriculumVectorEnv, score: str = "positive_value_loss", verbose: int = 0
    ) -> None:
        super().__init__(verbose)
        if wrapper.score != "external":
            raise ValueError(
                "CurriculumCallback scores the episodes: make the wrapper with "
                f"score='external', not {wrapper.score!r}"
            )
        if score not in ("positive_value_loss", "max_mc"):
            raise ValueError(f"score must be 'positive_value_loss' or 'max_mc', not {score!r}")
        self.wrapper = wrapper
        self.score = score
        self.scored = 0
        """How many episodes were scored so far."""
        self._masks: list[np.ndarray] = []

    def _on_training_start(self) -> None:
        if self.wrapper.sampler.robust and getattr(self.model, "normalize_advantage", False):
            raise ValueError(
                "Robust PLR with SB3 needs normalize_advantage=False: normalised "
                "advantages of new levels would not stay 0"
            )

    def _on_rollout_start(self) -> None:
        self._masks = []

    def _on_step(self) -> bool:
        self._masks.append(self.wrapper.train_mask.copy())
        return True

    def _on_rollout_end(self) -> None:
        buffer = self.model.rollout_buffer
        steps = buffer.buffer_size if buffer.full else buffer.pos
        advantages = buffer.advantages[:steps]
        self.scored += len(
            self.wrapper.score_rollout(advantages, buffer.values[:steps], self.score)
        )
        if self.wrapper.sampler.robust and len(self._masks) == steps:
            ignored = ~np.stack(self._masks)
            buffer.advantages[:steps][ignored] = 0.0
            buffer.returns[:steps][ignored] = buffer.values[:steps][ignored]


class SelfPlayCallback(BaseCallback):
    """Refreshes a :class:`~rlenv_client.selfplay.FrozenPolicy` from the model being trained.

    The copy is taken when training starts, then every ``every`` steps (SB3's
    ``num_timesteps``: one per sub-environment step), so that the agents it drives play the
    learner as it was at most ``every`` steps ago.

    Args:
        frozen: the copy that ``others`` gives the opponents.
        every: steps between refreshes (at least 1).
        verbose: SB3's verbosity (1: log each refresh, at INFO, on ``rlenv_client.sb3``).

    Raises:
        ValueError: ``every`` is smaller than 1.
    """

    def __init__(self, frozen: FrozenPolicy, every: int, verbose: int = 0) -> None:
        super().__init__(verbose)
        if every < 1:
            raise ValueError(f"every must be at least 1 step, not {every}")
        self.frozen = frozen
        self.every = every
        self._last = 0

    def _on_training_start(self) -> None:
        self._refresh()

    def _on_step(self) -> bool:
        if self.num_timesteps - self._last >= self.every:
            self._refresh()
        return True

    def _refresh(self) -> None:
        self.frozen.refresh(self.model.policy, self.num_timesteps)
        self._last = self.num_timesteps
        if self.verbose:
            logger.info("self-play: the opponents' copy refreshed at step %d", self.num_timesteps)


def _split_infos(infos: dict[str, Any], num_envs: int) -> list[dict[str, Any]]:
    """Split a batched gymnasium info dict (with ``_key`` masks) into one dict per environment.

    A nested dict (``agents``: each agent's outcome, with several agents) is split likewise.
    Columns of numbers give Python numbers (``tolist``: one call, not one per environment,
    which counts where each member of a group is an environment).
    """
    per_env: list[dict[str, Any]] = [{} for _ in range(num_envs)]
    for key, values in infos.items():
        if key.startswith("_") or key in ("final_obs", "final_info"):
            continue
        mask = infos.get(f"_{key}")
        split = _split_infos(values, num_envs) if isinstance(values, dict) else values
        if isinstance(split, np.ndarray) and split.ndim == 1:
            split = split.tolist()
        if mask is None or mask.all():
            for info, value in zip(per_env, split, strict=True):
                info[key] = value
        else:
            for index in np.flatnonzero(mask).tolist():
                per_env[index][key] = split[index]
    return per_env
