"""RLlib (new API stack): a multi-agent rlenv environment as an RLlib ``MultiAgentEnv``.

:class:`RemoteMultiAgentEnv` reaches one instance of the environment in a server it starts (or
at an address, or in this process) and speaks RLlib's multi-agent API: observations, rewards
and flags keyed by agent name, an agent leaving the dicts once its episode ended (it is in them
once more, on the step it ended, with its last observation), and ``"__all__"`` for the
episode. Agents its server drives (``others``: ``rlenv serve --policy NAME=heuristic`` or
``NAME=FILE.onnx``) are not RLlib's: they are out of ``possible_agents`` and need no action.

Agents that come and go (an environment with ``possible_agents``, protocol 2.6) follow RLlib's
convention: the observations hold the agents that act now (and, once, those that left, with
their final observation and flags); an agent that joins appears with its first observation
(its reward 0.0); ``agents`` are those in play; ``"__all__"`` ends the episode. An action for
an agent that does not act now is never sent. When the episode ends, or
``max_episode_steps`` cuts it, every agent still in play gets its last observation, truncated
(RLlib needs one to bootstrap from).

Each agent trains the policy (RLModule) that ``policy_mapping_fn`` gives it: one per agent
(:func:`policy_per_agent`) or one per RLAgent class (:func:`policy_per_class`: the tag game's
``Chaser`` and its two runners are two policies). :func:`multi_agent_config_for` sets
it all up::

    import ray
    from ray.rllib.algorithms.ppo import PPOConfig

    from rlenv_client.rllib import multi_agent_config_for

    ray.init(address="local", num_cpus=2, include_dashboard=False)
    config = multi_agent_config_for(PPOConfig(), "examples.tag:TagEnvironment",
                                    per="class", max_episode_steps=300)
    algo = config.build_algo()
    for _ in range(20):
        result = algo.train()   # result["env_runners"]["module_episode_returns_mean"]
    algo.stop()                 # every EnvRunner closes its servers
    ray.shutdown()

RLlib's ``MultiAgentEnvRunner`` builds ``num_envs_per_env_runner`` of these with its own
vector (the creator is called once per environment, so each has a server of its own).

A group of agents (an :class:`~rlenv.agent_group.RLAgentGroup`, protocol 2.7) gives RLlib its
members as agents, ``f"{group}_{i}"``, each with one member's spaces, in and out of the dicts
as agents that come and go are (a member in the dicts from the answer it starts or joins in,
and once more with its final transition). They share one policy: :func:`policy_per_class`
maps every member to the group's class name, :func:`policy_per_agent` to the group's name::

    config = multi_agent_config_for(PPOConfig(), "swarm_envs:MixedEnvironment")  # tests/
    config.policy_mapping_fn("Discs_5")   # "Discs": every disc learns one policy
    config.policy_mapping_fn("Shepherd")  # "Shepherd"

Needs the optional extra ``rllib`` (and a CPU build of torch); only people who use RLlib
import this module, through :mod:`rlenv_client.rllib`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Literal

from ray.rllib.env.multi_agent_env import MultiAgentEnv

from rlenv_client._members_in_play import in_play
from rlenv_client.agent_vector import agent_classes, policy_arguments
from rlenv_client.session import Session
from rlenv_client.trainer_view import TrainerView

if TYPE_CHECKING:
    from ray.rllib.algorithms.algorithm_config import AlgorithmConfig

__all__ = [
    "AgentMapping",
    "RemoteMultiAgentEnv",
    "multi_agent_config_for",
    "policy_per_agent",
    "policy_per_class",
    "register_multi_agent",
]

_ALL = "__all__"


class RemoteMultiAgentEnv(MultiAgentEnv):
    """One instance of a multi-agent rlenv environment, as RLlib's ``MultiAgentEnv``.

    Args:
        target: the environment class as ``MODULE:CLASS`` (a server is started for it).
        address: ``HOST:PORT`` of a running server instead.
        others: what the server drives instead of RLlib, by agent name: ``"heuristic"`` or
            an ONNX file (``rlenv serve --policy NAME=...``).
        repeat_action: physics ticks per step; the server's default if ``None``.
        max_episode_steps: truncate every agent still in the episode after this many steps.
        in_process: run the environment in this process (``others`` is then refused).
        timeout: seconds to wait for each answer.
        server_args: more arguments for ``rlenv serve``.

    Raises:
        ValueError: ``others`` with an address or in process; spaces not keyed by agent.
    """

    def __init__(
        self,
        target: str | None = None,
        *,
        address: str | None = None,
        others: Mapping[str, str] | None = None,
        repeat_action: int | None = None,
        max_episode_steps: int | None = None,
        in_process: bool = False,
        timeout: float = 30.0,
        server_args: Sequence[str] = (),
    ) -> None:
        super().__init__()
        policies = policy_arguments(others or {})
        if policies and (address is not None or in_process):
            raise ValueError(
                "others are driven by the server this environment starts: not "
                "with an address or in_process"
            )
        self.session = Session(
            target,
            address=address,
            in_process=in_process,
            timeout=timeout,
            server_args=[*server_args, *policies],
        )
        hello = self.session.client.hello
        try:
            view = TrainerView(hello)
        except ValueError:
            self.session.close()
            raise
        self._several = view.joint
        self.driven = tuple(hello.driven)
        self._in_play = in_play(view, hello)
        self.possible_agents = list(view.agents if self._in_play is None else self._in_play.names)
        self.agents: list[str] = []
        self.action_spaces, self.observation_spaces = (
            view if self._in_play is None else self._in_play
        ).agent_spaces()
        self.repeat_action = repeat_action
        self.max_episode_steps = max_episode_steps
        self._steps = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Start an episode: every agent's first observation."""
        super().reset(seed=seed, options=options)
        observation, info = self.session.client.reset(seed=seed, options=options)
        self._steps = 0
        if self._in_play is not None:
            turn = self._in_play.start(observation, info)
            self.agents = list(turn.agents)
            return dict(turn.observations), {name: {} for name in self.agents}
        self.agents = list(self.possible_agents)
        observations = self._split(observation)
        return {name: observations[name] for name in self.agents}, {
            name: {} for name in self.agents
        }

    def step(self, action_dict: dict[str, Any]) -> tuple[dict[str, Any], ...]:
        """Act for the agents in the episode; RLlib's five dicts (``"__all__"`` included).

        Raises:
            ValueError: no action for an agent in the episode (named; when agents come and go,
                for an agent that acts now).
        """
        if self._in_play is not None:
            return self._step_in_play(action_dict)
        live = self.agents
        missing = [name for name in live if name not in action_dict]
        if missing:
            raise ValueError(f"no action for agent {missing[0]!r}, which is in the episode")
        joint = (
            {name: action_dict[name] for name in live} if self._several else action_dict[live[0]]
        )
        observation, reward, terminated, truncated, info = self.session.client.step(
            joint, self.repeat_action
        )
        self._steps += 1
        cut = self.max_episode_steps is not None and self._steps >= self.max_episode_steps
        outcomes = info.get("agents") or {
            live[0]: {"reward": reward, "terminated": terminated, "truncated": truncated}
        }
        observations = self._split(observation)
        obs = {name: observations[name] for name in live}
        rewards = {name: float(outcomes[name]["reward"]) for name in live}
        terminateds: dict[str, bool] = {name: bool(outcomes[name]["terminated"]) for name in live}
        truncateds: dict[str, bool] = {
            name: bool(outcomes[name]["truncated"]) or (cut and not terminateds[name])
            for name in live
        }
        if terminated or truncated or cut:  # the episode ended: whoever was left is cut
            for name in live:
                truncateds[name] = truncateds[name] or not terminateds[name]
        self.agents = [name for name in live if not (terminateds[name] or truncateds[name])]
        terminateds[_ALL] = terminated and not self.agents
        truncateds[_ALL] = (truncated or cut) and not terminated
        return obs, rewards, terminateds, truncateds, {name: {} for name in live}

    def _step_in_play(self, action_dict: dict[str, Any]) -> tuple[dict[str, Any], ...]:
        assert self._in_play is not None
        missing = [name for name in self._in_play.due if name not in action_dict]
        if missing:
            raise ValueError(f"no action for agent {missing[0]!r}, which acts now")
        observation, _, terminated, truncated, info = self.session.client.step(
            self._in_play.action(action_dict), self.repeat_action
        )
        self._steps += 1
        cut = self.max_episode_steps is not None and self._steps >= self.max_episode_steps
        turn = self._in_play.answer(observation, info, ended=terminated or truncated or cut)
        self.agents = list(self._in_play.agents)
        deciding = {*turn.due, *turn.left}
        now = [name for name in turn.agents if name in deciding]
        terminateds = {name: turn.terminated[name] for name in now}
        truncateds = {name: turn.truncated[name] for name in now}
        terminateds[_ALL] = terminated
        truncateds[_ALL] = (truncated or cut) and not terminated
        return (
            {name: turn.observations[name] for name in now},
            {name: turn.rewards[name] for name in now},
            terminateds,
            truncateds,
            {name: {} for name in now},
        )

    def close(self) -> None:
        """Disconnect, and stop the server this environment started."""
        self.session.close()

    def _split(self, observation: Any) -> dict[str, Any]:
        return dict(observation) if self._several else {self.possible_agents[0]: observation}


class AgentMapping:
    """A ``policy_mapping_fn``: each agent's policy (module id) from a fixed map.

    Plain data, so Ray pickles it to every EnvRunner.

    Args:
        policies: the policy of each agent, by agent name.
    """

    def __init__(self, policies: Mapping[str, str]) -> None:
        self.policies = dict(policies)

    def __call__(self, agent_id: str, episode: Any = None, **kwargs: Any) -> str:
        """The policy of ``agent_id``.

        Raises:
            KeyError: an agent the map does not name (the environment's agents are).
        """
        try:
            return self.policies[agent_id]
        except KeyError:
            raise KeyError(
                f"no policy for agent {agent_id!r}; mapped: {', '.join(self.policies)}"
            ) from None

    def __repr__(self) -> str:
        return f"AgentMapping({self.policies!r})"


def policy_per_agent(target: str) -> AgentMapping:
    """One policy per agent, named as the agent; a group's members share the group's."""
    agents = agent_classes(target)
    return AgentMapping(
        {  # a member f"{group}_{i}": its group's
            name: name if name in agents else name.rpartition("_")[0]
            for name in agent_classes(target, members=True)
        }
    )


def policy_per_class(target: str) -> AgentMapping:
    """One policy per RLAgent class, named as the class: its agents (and members) share it."""
    return AgentMapping(
        {name: cls.__name__ for name, cls in agent_classes(target, members=True).items()}
    )


def register_multi_agent(target: str, name: str | None = None, **options: Any) -> str:
    """Register ``target`` with RLlib as a :class:`RemoteMultiAgentEnv`; returns the name.

    Args:
        target: the environment class as ``MODULE:CLASS``.
        name: the name to register under; by default ``"rllib-agents/" + target``.
        options: :class:`RemoteMultiAgentEnv` keywords; the env config's override them.
    """
    from ray.tune.registry import register_env

    name = name or f"rllib-agents/{target}"
    register_env(name, MultiAgentCreator(target, **options))
    return name


class MultiAgentCreator:
    """RLlib's env creator for :class:`RemoteMultiAgentEnv` (plain data: Ray pickles it).

    Args:
        target: the environment class as ``MODULE:CLASS``.
        options: :class:`RemoteMultiAgentEnv` keywords.
    """

    def __init__(self, target: str, **options: Any) -> None:
        self.target = target
        self.options = options

    def __call__(self, env_config: Mapping[str, Any]) -> RemoteMultiAgentEnv:
        """A new environment with ``env_config`` over the registered options."""
        return RemoteMultiAgentEnv(self.target, **{**self.options, **dict(env_config)})


def multi_agent_config_for(
    config: AlgorithmConfig,
    target: str,
    *,
    per: Literal["class", "agent"] = "class",
    num_envs_per_env_runner: int = 1,
    num_env_runners: int | None = None,
    name: str | None = None,
    **options: Any,
) -> AlgorithmConfig:
    """``config`` set up to train a policy per agent class (or per agent) of ``target``.

    Registers the environment (:func:`register_multi_agent`) and sets ``environment(name)``,
    ``multi_agent(policies=..., policy_mapping_fn=...)`` and ``env_runners(...)``. Agents that
    ``others`` leaves to the server get no policy.

    Args:
        config: any algorithm's config, e.g. ``PPOConfig()``.
        target: the environment class as ``MODULE:CLASS``.
        per: ``"class"`` (:func:`policy_per_class`) or ``"agent"`` (:func:`policy_per_agent`).
        num_envs_per_env_runner: environments in each EnvRunner.
        num_env_runners: EnvRunner actors (0: sample in the driver); RLlib's default if
            ``None``.
        name: the name to register under.
        options: :class:`RemoteMultiAgentEnv` keywords (``others``, ``max_episode_steps``...).

    Raises:
        ValueError: ``per`` is neither.
    """
    if per not in ("class", "agent"):
        raise ValueError(f"per must be 'class' or 'agent', not {per!r}")
    mapping = (policy_per_class if per == "class" else policy_per_agent)(target)
    driven = set(options.get("others") or {})
    mapping = AgentMapping(
        {agent: policy for agent, policy in mapping.policies.items() if agent not in driven}
    )
    runners: dict[str, Any] = {"num_envs_per_env_runner": num_envs_per_env_runner}
    if num_env_runners is not None:
        runners["num_env_runners"] = num_env_runners
    return (
        config.environment(register_multi_agent(target, name, **options))
        .multi_agent(policies=set(mapping.policies.values()), policy_mapping_fn=mapping)
        .env_runners(**runners)
    )
