"""RLlib (new API stack): any rlenv environment as the vector env of every EnvRunner.

:func:`register` registers, with ``ray.tune.registry.register_env``, an env creator that builds
a :class:`~rlenv_client.vector.RemoteVectorEnv`: one vector of ``num_envs_per_env_runner``
sub-environments per EnvRunner, stepped in columns by servers that the EnvRunner starts (on free
ports, in its own process tree) and ends when RLlib closes the env. :func:`config_for` applies
the settings it needs to any algorithm's config::

    import ray
    from ray.rllib.algorithms.ppo import PPOConfig

    from rlenv_client.rllib import config_for

    ray.init(address="local", num_cpus=2, include_dashboard=False)  # "local": a new instance,
    config = config_for(                        # never a cluster another process left behind
        PPOConfig(), "rlenv/CartPole-v0",          # or "mymodule:MyEnvironment"
        num_env_runners=1, num_envs_per_env_runner=8,
        instances_per_server=4,                     # any RemoteVectorEnv option
    )
    algo = config.build_algo()
    for _ in range(20):
        result = algo.train()
        print(result["env_runners"]["episode_return_mean"])
    algo.stop()                                     # every EnvRunner closes its servers
    ray.shutdown()

which is, by hand::

    name = register("rlenv/CartPole-v0", instances_per_server=4)
    config = (
        PPOConfig()
        .environment(name, env_config={"repeat_action": 4})    # options here are checked too
        .env_runners(num_env_runners=1, num_envs_per_env_runner=8,
                     gym_env_vectorize_mode=gymnasium.VectorizeMode.VECTOR_ENTRY_POINT)
        .fault_tolerance(restart_failed_sub_environments=True)
    )

How RLlib 2.60 calls the creator, and why these settings (read in ``ray/rllib/env/``):

- ``SingleAgentEnvRunner.make_env`` registers the creator with gymnasium as
  ``vector_entry_point=lambda num_envs: entry_point(env_ctx | {"num_envs": num_envs})`` and
  calls ``gym.make_vec(..., vectorization_mode=config.gym_env_vectorize_mode)``. Only
  ``VECTOR_ENTRY_POINT`` calls it once for the whole vector; the default (``SYNC``) would call
  it once per sub-environment without ``num_envs``, which the creator refuses, naming the
  setting. ``env_ctx | {...}`` is a plain ``dict``: the creator gets the env config and
  ``num_envs``, never ``worker_index`` or ``vector_index``, so nothing here derives a port or a
  server from them (servers bind port 0). RLlib asserts that the vector holds exactly
  ``num_envs_per_env_runner`` sub-environments; the creator checks it first, with a clearer
  message.
- RLlib's episodes expect gymnasium's ``NEXT_STEP`` autoreset (after a sub-environment ends,
  the next step returns its reset observation, which ``SingleAgentEnvRunner._sample`` records
  with ``add_env_reset``), so ``autoreset_mode`` must stay ``NEXT_STEP``.
- RLlib's new stack does not apply the registered time limit (it registers its own id, with no
  ``max_episode_steps``), so the creator passes the registered id's ``max_episode_steps`` to the
  vector (500 steps for ``rlenv/CartPole-v0``, whose reward is up to 4 per step: episode returns
  go up to 2000).
- Faults. ``EnvRunner._try_env_step`` (``env_runner.py``) wraps ``self.env.step(actions)`` in
  ``except Exception``: with ``restart_failed_sub_environments=True`` it logs the error (unless
  it is a ``StepFailedRecreateEnvError``), counts it in ``num_env_step_failures``, calls
  ``self.make_env()`` (which first calls ``self.env.close()``: this vector ends its servers),
  and returns ``ENV_STEP_FAILURE``; ``SingleAgentEnvRunner._sample`` then drops the ongoing
  episodes, resets the new vector and samples on (episodes that had ended are kept). Without it
  the error is raised again as a ``RuntimeError`` and the EnvRunner fails.
  ``_try_env_reset`` does the same for ``reset`` (recreate, then reset again). Note that RLlib
  recreates the whole vector, not the one sub-environment its docs speak of.

  A lost server (killed, crashed, silent past ``timeout``) is first replaced by the vector
  itself, ``max_restarts`` times per server (``RemoteVectorEnv``'s default, 3; a pool's server
  is found again wherever Ray brought it back): only the episodes on that server end, as
  truncated, with ``info["server_restarted"]``, and no sampled data is dropped. Past that
  budget, with ``max_restarts=0``, or for servers given by ``addresses``, ``step`` raises
  :class:`~rlenv.protocol.errors.ConnectionLost` (an ``Exception``; ``ServerLost`` for a pool),
  which RLlib handles as above: the vector is closed (its servers end, or its lease is
  released) and the creator builds a new one.

Servers from a pool: with ``pool="NAME"`` (in :func:`register` or the env config) each vector
leases ``pool_servers`` (default 1) servers from the named
:class:`rlenv_client.ray.RayServerPool` (``RayServerPool.lease(NAME, servers=k)``) instead of
starting its own, and releases them when RLlib closes it (:class:`LeasedVectorEnv`).
``num_envs_per_env_runner`` must equal ``pool_servers`` times the pool's instances per server,
and the pool must have ``pool_servers`` servers free for every EnvRunner (a vector that RLlib
recreates releases its lease before the new one leases). An EnvRunner that dies without closing
its env (its actor killed) does not give its lease back.

Multi-agent environments (one policy per agent, or per RLAgent class, through
``policy_mapping_fn``) are each a :class:`~rlenv_client.rllib_agents.RemoteMultiAgentEnv`, set
up by :func:`~rlenv_client.rllib_agents.multi_agent_config_for` (in
:mod:`rlenv_client.rllib_agents`, importable from here).

Only people who use RLlib import this module; the rest of ``rlenv_client`` never imports ray,
and here only :func:`register`, :func:`config_for` and a ``pool`` import it.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import gymnasium
from gymnasium.vector import AutoresetMode

import rlenv_client  # noqa: F401  (registers the example ids with gymnasium)
from rlenv_client.vector import RemoteVectorEnv

if TYPE_CHECKING:
    from ray.rllib.algorithms.algorithm_config import AlgorithmConfig

__all__ = ["LeasedVectorEnv", "RLlibEnvCreator", "config_for", "register", "vector_options"]

_MULTI_AGENT = (
    "AgentMapping",
    "RemoteMultiAgentEnv",
    "multi_agent_config_for",
    "policy_per_agent",
    "policy_per_class",
    "register_multi_agent",
)


def __getattr__(name: str) -> Any:
    """The multi-agent names of :mod:`rlenv_client.rllib_agents` (which import ray)."""
    if name in _MULTI_AGENT:
        from rlenv_client import rllib_agents

        return getattr(rllib_agents, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


_VECTOR_ENTRY = "rlenv_client.vector:RemoteVectorEnv"
_NOT_WITH_POOL = ("addresses", "in_process", "instances_per_server", "token")


def vector_options() -> tuple[str, ...]:
    """The :class:`RemoteVectorEnv` options an env config may hold (besides ``num_envs``).

    Read from ``RemoteVectorEnv``'s signature, so new options are accepted as they come.
    """
    parameters = inspect.signature(RemoteVectorEnv.__init__).parameters
    return tuple(name for name in parameters if name not in ("self", "num_envs", "target", "pool"))


def _resolve(env: str) -> tuple[str, int | None]:
    """``(target, max_episode_steps)`` for an rlenv gymnasium id or a ``MODULE:CLASS`` target."""
    if env in gymnasium.registry:
        spec = gymnasium.registry[env]
        target = spec.kwargs.get("target")
        if spec.vector_entry_point != _VECTOR_ENTRY or not isinstance(target, str):
            raise ValueError(
                f"{env!r} is not an rlenv id (its vector entry point is "
                f"{spec.vector_entry_point!r}); give an rlenv id or MODULE:CLASS"
            )
        return target, spec.max_episode_steps
    module, _, name = env.partition(":")
    if not module or not name:
        raise ValueError(
            f"expected an rlenv gymnasium id (e.g. 'rlenv/CartPole-v0') or a "
            f"target 'MODULE:CLASS', got {env!r}"
        )
    return env, None


class RLlibEnvCreator:
    """An RLlib env creator: ``creator(env_config) -> RemoteVectorEnv``.

    RLlib calls it in each EnvRunner with its env config plus ``num_envs`` (see the module
    docstring). Plain data, so Ray pickles it by reference to this module.

    Args:
        target: the environment class as ``MODULE:CLASS``.
        max_episode_steps: truncate episodes after this many steps (``None``: never).
        options: defaults for the vector: :func:`vector_options`, ``pool`` and
            ``pool_servers``; the env config overrides them key by key.

    Raises:
        ValueError: an unknown option, or one RLlib cannot use.
    """

    def __init__(self, target: str, max_episode_steps: int | None = None, **options: Any) -> None:
        self.target = target
        self.options: dict[str, Any] = {"max_episode_steps": max_episode_steps}
        self.options.update(self._checked(options, "register()"))

    def __call__(self, env_config: Mapping[str, Any]) -> RemoteVectorEnv:
        """Build the vector for one EnvRunner from RLlib's ``env_ctx | {"num_envs": n}``.

        Raises:
            ValueError: no ``num_envs`` (RLlib is not in ``VECTOR_ENTRY_POINT`` mode), an
                unknown key, or a vector of another size.
            ServerStartError: a server could not start (its output is in the message).
        """
        if "num_envs" not in env_config:
            raise ValueError(
                "rlenv's RLlib creator builds the whole vector, and RLlib gave no num_envs: "
                "set config.env_runners(gym_env_vectorize_mode=gymnasium.VectorizeMode."
                "VECTOR_ENTRY_POINT, num_envs_per_env_runner=N) (or use rlenv_client.rllib."
                "config_for)"
            )
        config = dict(env_config)
        num_envs = config.pop("num_envs")
        if not isinstance(num_envs, int) or isinstance(num_envs, bool) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive int, got {num_envs!r}")
        options = {**self.options, **self._checked(config, "the env config")}
        pool = options.pop("pool", None)
        pool_servers = options.pop("pool_servers", None)
        if pool is not None:
            return self._leased(
                pool, 1 if pool_servers is None else pool_servers, num_envs, options
            )
        if pool_servers is not None:
            raise ValueError("pool_servers is only for pool='NAME'")
        if options.get("addresses") is None:
            vector = RemoteVectorEnv(num_envs, self.target, **options)
        else:  # running servers: their instances add up (checked below, for RLlib)
            vector = RemoteVectorEnv(None, self.target, **options)
        if vector.num_envs != num_envs:
            vector.close()
            raise ValueError(
                f"the vector holds {vector.num_envs} sub-environments and RLlib expects "
                f"num_envs_per_env_runner={num_envs}; make them equal (the instances of the "
                f"servers at addresses add up)"
            )
        return vector

    def _leased(
        self, pool: str, servers: int, num_envs: int, options: dict[str, Any]
    ) -> RemoteVectorEnv:
        """A vector over ``servers`` servers leased from the named pool (see module docstring).

        Raises:
            RuntimeError: this rlenv has no ``rlenv_client.ray``.
            ValueError: no such pool, not that many servers free, or a lease of another size
                than ``num_envs``.
        """
        clashing = sorted(key for key in _NOT_WITH_POOL if key in options)
        if clashing:
            raise ValueError(
                f"{', '.join(clashing)} cannot be used with pool= (the pool's "
                f"servers fix where and how many sub-environments run)"
            )
        try:
            from rlenv_client.ray import RayServerPool
        except ModuleNotFoundError as error:
            if error.name not in ("rlenv_client.ray", "ray"):
                raise
            raise RuntimeError("pool= needs rlenv_client.ray.RayServerPool and ray") from None
        lease = RayServerPool.lease(pool, servers=servers)
        held = lease.servers * lease.instances_per_server
        if held != num_envs:
            lease.release()
            raise ValueError(
                f"pool {pool!r} hosts {lease.instances_per_server} sub-environments per server: "
                f"pool_servers={servers} gives {held}, and RLlib expects "
                f"num_envs_per_env_runner={num_envs}; make them equal"
            )
        return LeasedVectorEnv(lease, **options)

    @staticmethod
    def _checked(options: Mapping[str, Any], where: str) -> dict[str, Any]:
        """``options`` if every key is one the vector accepts and RLlib can use."""
        valid = (*vector_options(), "pool", "pool_servers")
        unknown = sorted(str(key) for key in options if key not in valid)
        if unknown:
            hint = " (the environment is fixed by register())" if "target" in unknown else ""
            raise ValueError(
                f"unknown key{'s' if len(unknown) > 1 else ''} in {where}: "
                f"{', '.join(unknown)}{hint}; valid keys: num_envs (set by RLlib), "
                f"{', '.join(valid)}"
            )
        mode = options.get("autoreset_mode")
        if mode is not None and AutoresetMode(mode) is not AutoresetMode.NEXT_STEP:
            raise ValueError(f"RLlib needs autoreset_mode NEXT_STEP, got {mode!r}")
        if "pool" in options and not isinstance(options["pool"], str | None):
            raise ValueError(f"pool must be the name of a RayServerPool, got {options['pool']!r}")
        return dict(options)

    def __repr__(self) -> str:
        return f"RLlibEnvCreator({self.target!r}, {self.options!r})"


class LeasedVectorEnv(RemoteVectorEnv):
    """A :class:`RemoteVectorEnv` over a lease of a pool's servers; closing it releases them.

    (``RemoteVectorEnv(pool=lease)`` leaves the lease to its caller; RLlib only closes envs.)

    Args:
        lease: a :class:`rlenv_client.ray.PoolLease`; released if the vector cannot be built.
        options: any other ``RemoteVectorEnv`` option.
    """

    def __init__(self, lease: Any, **options: Any) -> None:
        self.lease = lease
        try:
            super().__init__(pool=lease, **options)
        except BaseException:
            lease.release()
            raise

    def close_extras(self, **kwargs: Any) -> None:
        """Disconnect from the servers, then give them back to the pool."""
        try:
            super().close_extras(**kwargs)
        finally:
            self.lease.release()


def register(env: str = "rlenv/CartPole-v0", name: str | None = None, **options: Any) -> str:
    """Register an rlenv environment with RLlib; returns the name for ``config.environment``.

    Args:
        env: an rlenv gymnasium id (its registered ``max_episode_steps`` applies) or a target
            ``MODULE:CLASS``.
        name: the name to register under; by default ``"rllib/" + env``.
        options: defaults for every vector (any :func:`vector_options`, ``pool``,
            ``pool_servers``); keys of the env config override them.

    Raises:
        ValueError: ``env`` is neither an rlenv id nor a target, or an option is unknown.
    """
    from ray.tune.registry import register_env

    target, max_episode_steps = _resolve(env)
    options = {"max_episode_steps": max_episode_steps, **options}
    creator = RLlibEnvCreator(target, **options)
    name = name or f"rllib/{env}"
    register_env(name, creator)
    return name


def config_for(
    config: AlgorithmConfig,
    env: str = "rlenv/CartPole-v0",
    *,
    num_envs_per_env_runner: int = 8,
    num_env_runners: int | None = None,
    restart_failed_sub_environments: bool = True,
    name: str | None = None,
    **options: Any,
) -> AlgorithmConfig:
    """``config`` set up to sample from rlenv vectors (see the module docstring).

    Registers ``env`` (:func:`register`) and sets ``environment(name)``,
    ``env_runners(gym_env_vectorize_mode=VECTOR_ENTRY_POINT, num_envs_per_env_runner=...)`` and
    ``fault_tolerance(restart_failed_sub_environments=...)``.

    Args:
        config: any algorithm's config, e.g. ``PPOConfig()``.
        env: an rlenv gymnasium id or a target ``MODULE:CLASS``.
        num_envs_per_env_runner: sub-environments in each EnvRunner's vector.
        num_env_runners: EnvRunner actors (0: sample in the driver); RLlib's default if
            ``None``.
        restart_failed_sub_environments: let RLlib recreate a vector whose step or reset
            raised (a lost server the vector could not restart).
        name: the name to register under (see :func:`register`).
        options: RemoteVectorEnv options for every vector (see :func:`register`).

    Returns:
        ``config``, changed in place (RLlib's builder methods return it too).
    """
    runners: dict[str, Any] = {
        "num_envs_per_env_runner": num_envs_per_env_runner,
        "gym_env_vectorize_mode": gymnasium.VectorizeMode.VECTOR_ENTRY_POINT,
    }
    if num_env_runners is not None:
        runners["num_env_runners"] = num_env_runners
    return (
        config.environment(register(env, name, **options))
        .env_runners(**runners)
        .fault_tolerance(restart_failed_sub_environments=restart_failed_sub_environments)
    )
