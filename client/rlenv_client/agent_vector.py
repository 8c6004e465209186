"""AgentVectorEnv: the chosen agents of N multi-agent instances, each one sub-environment.

A trainer of one agent (or of a team sharing one policy) sees a plain gymnasium
``VectorEnv``: as Godot RL Agents makes every AIController an environment, each learning agent
of each of the ``instances`` is one sub-environment, sub-environment ``i * k + j`` being the
``j``-th of the ``k`` learners of instance ``i``. The other agents are driven:

- by default each by its class's ``RLAgent.heuristic``, run by the servers beside the physics
  (``rlenv serve --policy NAME=heuristic``); an agent with no heuristic and no entry in
  ``others`` is refused, naming it;
- ``others={"Runner1": "runner.onnx"}``: by an ONNX policy file, in the server likewise
  (``--policy NAME=FILE``);
- ``others={"Runner1": callable}``: by ``callable(observation) -> action``, called here on
  the agent's own observation before each step (a frozen copy of the learner's policy, for
  self-play: :mod:`rlenv_client.selfplay`);
- agents the server was started to drive (its hello's ``driven``) need nothing.

Episodes follow the agents, not the instances. A learner's episode ends when it terminates or
is truncated, or when its instance's episode ends (every agent done: then it is truncated unless
it terminated). ``max_episode_steps`` truncates every learner still in the episode, as
gymnasium's ``TimeLimit`` does (a learner that terminated on that step is both). Autoreset is
``SAME_STEP`` (``info["final_obs"]``, ``info["final_info"]``). A learner that ends while its
instance plays on (a runner caught while the other still runs) **waits** until the instance
resets: each step returns its last observation again, reward 0, both flags false and
``info["waiting"]``; the step that resets its instance ends that wait as truncated, its final
info holding ``waiting`` too, so that no episode statistics are counted for it. Its actions
while waiting are ignored (the slots and their waits: :mod:`rlenv_client._learner_slots`).

Agents that come and go (the hello's ``possible_agents``, protocol 2.6) keep a fixed slot per
possible learner: sub-environment ``i * k + j`` is always agent ``j`` of instance ``i``, in
play or not. The mask is ``infos["is_active"]`` (Sample Factory's name; TorchRL's ``mask``,
PufferLib's ``masks``): true where the slot's agent is in its instance's answer, that is, it
decides now, or it leaves with its final transition (``terminated`` or ``truncated``, with
``final_obs``). An inactive slot carries its agent's last observation (zeros before it
joins), reward 0 and both flags false; its action is ignored by the server. A slot whose agent
is not in play (not joined yet, or gone) waits, with ``info["waiting"]``, as above: it becomes
active when the agent joins (no episode boundary: the join's observation comes with reward 0),
and a name is never in play twice in one episode, so a slot whose agent left waits until its
instance's next episode. Callables in ``others`` are called only where their agent decides.

A group of agents (an :class:`~rlenv.agent_group.RLAgentGroup`, the hello's ``groups``,
protocol 2.7) learns alone: with ``agents=GROUP`` each member of each instance is one
sub-environment, sub-environment ``i * N + m`` being member ``m`` of instance ``i``
(``num_envs = instances * N``, the member's spaces), and the group's arrays are reshaped, with no
loop over members (:mod:`rlenv_client._group_slots`). ``is_active`` is the group's ``active``
row: a member in play, or ending with its final transition (``terminated`` or ``truncated``,
``final_obs``), once; then its slot is out of play until its instance resets (zeros, reward 0,
``waiting``), and a member that joins turns its slot active with its first observation and
reward 0. The group's other agents are driven as above; a callable driving a group gets its
``(N, *obs)`` array and returns ``(N, *act)``.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any, cast

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, create_empty_array

from rlenv.agent import RLAgent
from rlenv.serving.policy_driver import HEURISTIC
from rlenv_client._agents_in_play import as_one, with_column
from rlenv_client._group_slots import GroupSlots
from rlenv_client._learner_slots import LearnerSlots
from rlenv_client._rows import check_shape, repeat_rows, row, set_row
from rlenv_client.vector import RemoteVectorEnv
from rlenv_client.vector_servers import default_layout

__all__ = [
    "AgentVectorEnv",
    "Agents",
    "OtherPolicy",
    "agent_classes",
    "learner_names",
    "policy_arguments",
]

Agents = str | type[RLAgent] | Sequence[str | type[RLAgent]]
"""Which agents learn: names, an RLAgent class (its every agent), or a list of both."""

OtherPolicy = str | os.PathLike[str] | Callable[[Any], Any]
"""What drives another agent: ``"heuristic"``, an ONNX file, or ``policy(observation)``."""


def agent_classes(target: str, *, members: bool = False) -> dict[str, type[RLAgent]]:
    """Each agent's class, by name, read from one instance of ``target`` built in this process.

    An environment whose agents come and go gives its declaration: every possible agent's.

    Args:
        target: the environment class as ``MODULE:CLASS``.
        members: name each group's members in its place (``f"{group}_{i}"``, each of the
            group's class), as PettingZoo and RLlib see them.

    Raises:
        ImportError, ValueError, TypeError: ``target`` does not load (see
            :func:`rlenv.serving._instance.load_environment`).
    """
    from rlenv_client._members_in_play import member_names
    from rlenv_client.local import LocalClient

    with LocalClient(target) as probe:
        assert probe.host is not None
        instance = probe.host.instances[0]
        declared = instance.environment.possible_agents
        if declared is not None:
            classes = dict(declared)
        else:
            classes = {agent.name: type(agent) for agent in instance.agents}
        groups = probe.hello.groups if members else {}
    return {
        each: cls
        for name, cls in classes.items()
        for each in (member_names(name, groups[name].instance_count) if name in groups else (name,))
    }


def policy_arguments(policies: Mapping[str, str]) -> list[str]:
    """``rlenv serve``'s ``--policy NAME=POLICY`` arguments, one pair per driven agent.

    ``POLICY`` is an ONNX file or ``"heuristic"``.
    """
    return [
        argument
        for name, policy in policies.items()
        for argument in ("--policy", f"{name}={policy}")
    ]


def learner_names(
    agents: Agents, names: Sequence[str], classes: Mapping[str, type[RLAgent]] | None
) -> list[str]:
    """The learning agents ``agents`` selects, in the environment's order.

    Raises:
        ValueError: a name the environment lacks, a class none of its agents has, or no agent.
    """
    wanted = [agents] if isinstance(agents, str | type) else list(agents)
    chosen: set[str] = set()
    for item in wanted:
        if isinstance(item, str):
            if item not in names:
                raise ValueError(
                    f"agents: the environment has no agent {item!r}; its agents: {', '.join(names)}"
                )
            chosen.add(item)
        elif isinstance(item, type) and issubclass(item, RLAgent):
            if classes is None:
                raise ValueError(
                    f"agents: cannot tell which agents are {item.__name__}s "
                    "without the environment's target; name them instead"
                )
            found = [name for name, cls in classes.items() if issubclass(cls, item)]
            if not found:
                raise ValueError(
                    f"agents: no agent is a {item.__name__}; its agents: {_roster(names, classes)}"
                )
            chosen.update(found)
        else:
            raise TypeError(f"agents holds agent names or RLAgent classes, not {item!r}")
    if not chosen:
        raise ValueError("agents selects no agent")
    return [name for name in names if name in chosen]


class AgentVectorEnv(VectorEnv):
    """The learning agents of ``instances`` copies of a multi-agent environment, as one vector.

    Args:
        instances: how many copies of the environment (``None``: as many as ``addresses``
            host). The vector has ``instances * len(learners)`` sub-environments
            (``instances * N`` for a group of ``N`` members).
        target: the environment class as ``MODULE:CLASS``.
        agents: which agents learn (:data:`Agents`); they must share their spaces. A group
            learns alone: its members are the sub-environments (see the module).
        others: what drives each other agent, by name or by RLAgent class
            (:data:`OtherPolicy`); by default its heuristic.
        addresses: ``HOST:PORT`` of running servers instead; they can only be given callables
            in ``others`` (or drive agents themselves, started with ``--policy``).
        repeat_action: physics ticks per step; the servers' default if ``None``.
        max_episode_steps: truncate each instance's episodes after this many steps.
        in_process: run the copies inside this process (``others`` must then be callables).
        instances_per_server: how many copies each started server hosts: by default one
            server per core but ``trainer_cores``.
        render_mode: ``"rgb_array"`` or ``None``.
        timeout: seconds to wait for each answer.
        token: the secret of servers that require one.
        max_restarts: how many times each lost server that this vector started is replaced.
        trainer_cores: cores the default layout leaves to the trainer (see
            :func:`~rlenv_client.vector_servers.default_layout`;
            :class:`~rlenv_client.sb3.SB3VecEnv` leaves 1).

    Attributes:
        learners: the learning agents' names, in the environment's order.
        driven_here: the agents a callable drives, by name.
        driven_by_server: what the servers drive each other agent with, by name.
        vector: the :class:`~rlenv_client.vector.RemoteVectorEnv` of the joint instances.

    Raises:
        ValueError: an unknown agent in ``agents`` or ``others``, a learner in ``others``,
            learners with different spaces, a group among several learners, another agent with
            neither a heuristic nor an entry in ``others`` (named), or a server-side policy
            where no server is started.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": ["rgb_array"]}

    def __init__(
        self,
        instances: int | None = None,
        target: str | None = None,
        *,
        agents: Agents,
        others: Mapping[str | type[RLAgent], OtherPolicy] | None = None,
        addresses: Sequence[str] | None = None,
        repeat_action: int | None = None,
        max_episode_steps: int | None = None,
        in_process: bool = False,
        instances_per_server: int | None = None,
        render_mode: str | None = None,
        timeout: float = 30.0,
        token: str | None = None,
        max_restarts: int = 3,
        trainer_cores: int = 0,
    ) -> None:
        vector: RemoteVectorEnv | None = None  # self.vector once built
        options: dict[str, Any] = {
            "repeat_action": repeat_action,
            "max_episode_steps": max_episode_steps,
            "autoreset_mode": AutoresetMode.SAME_STEP,
            "render_mode": render_mode,
            "timeout": timeout,
            "token": token,
            "max_restarts": max_restarts,
        }
        try:
            if addresses is not None:  # running servers: their hello says who they are
                vector = RemoteVectorEnv(instances, target, addresses=addresses, **options)
                hello = vector.clients[0].hello
                classes = _classes_or_none(target or hello.target)
                names, already = list(hello.agents), set(hello.driven)
            else:
                if target is None:
                    raise ValueError("AgentVectorEnv needs a target or addresses")
                classes = agent_classes(target)
                names, already = list(classes), set()
            self.learners = learner_names(agents, names, classes)
            self.driven_here, self.driven_by_server = _plan_others(
                names, self.learners, classes, _others_map(others), already
            )
            if self.driven_by_server and (addresses is not None or in_process):
                where = "servers given by address" if addresses is not None else "in_process"
                name, policy = next(iter(self.driven_by_server.items()))
                raise ValueError(
                    f"agent {name!r} is to be driven by {policy!r} in its server, and {where} "
                    f"start no server here: give others={{{name!r}: callable}}, or serve it "
                    f"with rlenv serve --policy {name}={policy}"
                )
            if vector is None:
                server_args = policy_arguments(self.driven_by_server)
                if instances_per_server is None and not in_process:
                    instances_per_server = default_layout(
                        instances or 1, trainer_cores=trainer_cores
                    )[0]
                vector = RemoteVectorEnv(
                    instances,
                    target,
                    in_process=in_process,
                    instances_per_server=instances_per_server,
                    server_args=server_args,
                    **options,
                )
            self.vector: RemoteVectorEnv = vector
            self._set_spaces()
        except BaseException:
            if vector is not None:
                vector.close()
            raise
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": self.vector.metadata["render_fps"]}

    def _set_spaces(self) -> None:
        vector = self.vector
        self.instances = vector.num_envs
        joint_actions, joint_observations = (
            vector.single_action_space,
            vector.single_observation_space,
        )
        hello = vector.clients[0].hello
        self._come_and_go = hello.possible_agents is not None
        self._several = isinstance(joint_actions, spaces.Dict) and (
            len(hello.agents) > 1 or self._come_and_go or bool(hello.groups)
        )
        first = self.learners[0]
        self._group: GroupSlots | None = None
        self._slots: LearnerSlots | None = None
        if first in hello.groups:  # its members are the sub-environments
            group = hello.groups[first]
            action_space, observation_space = group.action_space, group.observation_space
            self._per_instance = group.instance_count
            self._group = GroupSlots(first, self.instances, group.instance_count, observation_space)
        else:
            action_space, observation_space = (
                self._agent_space(joint_actions, first),
                self._agent_space(joint_observations, first),
            )
            self._per_instance = len(self.learners)
            self._slots = LearnerSlots(
                self.learners,
                self.instances,
                observation_space,
                come_and_go=self._come_and_go,
                share=self._of,
                add_info=self._add_info,
            )
        for name in self.learners[1:]:
            if name in hello.groups or self._group is not None:
                grouped = first if self._group is not None else name
                raise ValueError(
                    f"agents: group {grouped!r} learns alone (each of its members is a "
                    f"sub-environment): give agents={grouped!r}, and train the others apart"
                )
            if (
                self._agent_space(joint_actions, name),
                self._agent_space(joint_observations, name),
            ) != (action_space, observation_space):
                raise ValueError(
                    f"agents {first!r} and {name!r} learn one policy but have "
                    "different spaces; train them apart"
                )
        self.num_envs = self.instances * self._per_instance
        self.single_action_space, self.single_observation_space = action_space, observation_space
        self.action_space = batch_space(action_space, self.num_envs)
        self.observation_space = batch_space(observation_space, self.num_envs)
        self._joint_action = create_empty_array(joint_actions, self.instances)
        self._joint_observation: Any = None
        self._others_done = {name: np.zeros(self.instances, np.bool_) for name in self.driven_here}
        self._steps = np.zeros(self.instances, np.int64)  # of each instance's episode
        self._due: dict[str, np.ndarray] = {}  # by agent, over the instances (come and go)

    def _agent_space(self, joint: spaces.Space, name: str) -> spaces.Space:
        # Several agents: the joint spaces are Dicts by agent (see _set_spaces).
        return cast(spaces.Dict, joint)[name] if self._several else joint

    def _of(self, joint_batch: Any, name: str) -> Any:
        """Agent ``name``'s share of a joint batch (or of one joint value)."""
        return joint_batch[name] if self._several else joint_batch

    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: Mapping[str, Any] | None = None,
    ) -> tuple[Any, dict[str, Any]]:
        """Reset every instance (an int ``seed`` seeds instance ``i`` with ``seed + i``).

        A list of seeds holds one per instance, or one per sub-environment (as SB3 gives
        them), of which each instance takes its first learner's.

        Raises:
            ValueError: a list of seeds of another length.
        """
        if seed is not None and not isinstance(seed, int) and len(seed) == self.num_envs:
            seed = list(seed)[:: self._per_instance]
        joint, infos = self.vector.reset(seed=seed, options=options)
        self._joint_observation = joint
        for done in self._others_done.values():
            done[:] = False
        self._steps[:] = 0
        out = self._spread(infos)
        if self._come_and_go:
            self._due = dict(infos["due"])  # kept for the callables of the next step
        if self._group is not None:
            observations, active = self._group.start(joint, infos)
            return observations, self._group_infos(out, active)
        assert self._slots is not None
        return self._slots.start(joint, self._due, out)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every instance with the learners' ``actions`` and the others' policies.

        Raises:
            ValueError: ``actions`` does not hold one action per sub-environment.
            RuntimeError: step before reset.
        """
        if self._joint_observation is None:
            raise RuntimeError("call reset() before step()")
        check_shape(self.action_space, actions, "actions")
        k, joint = len(self.learners), self._joint_action
        if self._group is not None:  # the joint action is a map: the group is keyed
            columns = cast(dict[str, Any], joint)
            columns[self._group.name] = self._group.action(actions, columns[self._group.name])
        else:
            for j, name in enumerate(self.learners):
                column = self._of(joint, name)
                for i in range(self.instances):
                    set_row(column, i, row(actions, i * k + j))
        for name, policy in self.driven_here.items():
            column, seen = self._of(joint, name), self._of(self._joint_observation, name)
            acting = ~self._others_done[name]
            if self._come_and_go:  # only where it decides
                acting &= self._due.get(name, acting)
            for live in np.flatnonzero(acting):
                set_row(column, live, policy(row(seen, live)))
        joint_obs, *flags, infos = self.vector.step(joint)
        self._joint_observation = joint_obs
        return self._outcomes(joint_obs, tuple(flags), infos)

    def _agent_outcome(
        self, name: str, joint: tuple[np.ndarray, ...], ended: np.ndarray, infos: Mapping[str, Any]
    ) -> tuple[np.ndarray, ...]:
        """``(reward, terminated, truncated)`` columns of agent ``name`` over the instances.

        Those of the last step of an instance that ended (its ``final_info``), not its reset.
        """
        if not self._several:
            return joint
        step = _columns(infos["agents"].get(name), self.instances)
        if not ended.any():
            return step
        final = _columns(infos["final_info"].get("agents", {}).get(name), self.instances)
        return tuple(np.where(ended, last, now) for last, now in zip(final, step, strict=True))

    def _outcomes(
        self, joint_obs: Any, joint: tuple[np.ndarray, ...], infos: dict[str, Any]
    ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        ended = joint[1] | joint[2]
        self._steps += 1
        limit = self.vector.max_episode_steps
        timed_out = self._steps >= limit if limit is not None else np.zeros_like(ended)
        self._steps[ended] = 0
        if self._come_and_go:
            self._due = dict(infos["due"])
        for name in self.driven_here:
            _, done_t, done_c = self._agent_outcome(name, joint, ended, infos)
            self._others_done[name] |= done_t | done_c
            self._others_done[name][ended] = False
        out = self._spread(infos)
        if self._group is not None:
            (observations, rewards, terminated, truncated, finals), mask = self._group.outcomes(
                joint_obs, ended, infos
            )
            out = self._group_infos({**out, **finals}, mask)
            return observations, rewards, terminated, truncated, out
        assert self._slots is not None
        columns = [self._agent_outcome(name, joint, ended, infos) for name in self.learners]
        return self._slots.outcomes(joint_obs, columns, ended, timed_out, infos, self._due, out)

    def _group_infos(self, out: dict[str, Any], active: np.ndarray) -> dict[str, Any]:
        """A group's infos: ``is_active`` per member slot, and ``waiting`` where any waits."""
        assert self._group is not None
        waiting = self._group.waiting
        if waiting.any():
            out = {**out, "waiting": waiting, "_waiting": waiting.copy()}
        return with_column(out, "is_active", active, self.num_envs)

    def _spread(self, infos: Mapping[str, Any]) -> dict[str, Any]:
        """The instances' infos, each repeated for its slots (``agents`` and finals left)."""
        k = self._per_instance
        return {
            key: repeat_rows(value, k)
            for key, value in infos.items()
            if key
            not in (
                "agents",
                "_agents",
                "due",
                "_due",
                "final_obs",
                "_final_obs",
                "final_info",
                "_final_info",
            )
        }

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One frame per sub-environment: its instance's (``rgb_array``)."""
        frames = self.vector.render()
        if frames is None:
            return None
        return tuple(frame for frame in frames for _ in range(self._per_instance))

    def close_extras(self, **kwargs: Any) -> None:
        """Stop the servers this vector started."""
        self.vector.close()

    def __enter__(self) -> AgentVectorEnv:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def _classes_or_none(target: str | None) -> dict[str, type[RLAgent]] | None:
    """:func:`agent_classes` of ``target``, or ``None`` where it cannot be built here."""
    if target is None:
        return None
    try:
        return agent_classes(target)
    except ImportError:
        return None


def _roster(names: Sequence[str], classes: Mapping[str, type[RLAgent]] | None) -> str:
    if classes is None:
        return ", ".join(names)
    return ", ".join(f"{name} ({classes[name].__name__})" for name in names)


def _others_map(others: Any) -> dict[Any, Any]:
    """``others`` as a dict; refused unless it is a map (``others="heuristic"``, say)."""
    if others is not None and not isinstance(others, Mapping):
        raise TypeError(
            "others must map agent names (or RLAgent classes) to what drives them, "
            f'e.g. {{"Runner1": "heuristic"}}; got {others!r:.60}'
        )
    return dict(others or {})


def _plan_others(
    names: Sequence[str],
    learners: Sequence[str],
    classes: Mapping[str, type[RLAgent]] | None,
    others: dict[Any, OtherPolicy],
    already: set[str],
) -> tuple[dict[str, Callable[[Any], Any]], dict[str, str]]:
    """Who drives each non-learning agent: callables here, and policies for the servers.

    Raises:
        ValueError: see :class:`AgentVectorEnv`.
    """
    by_name: dict[str, OtherPolicy] = {}
    for key, policy in others.items():
        if isinstance(key, str):
            if key not in names:
                raise ValueError(
                    f"others: the environment has no agent {key!r}; its agents: "
                    f"{_roster(names, classes)}"
                )
            by_name[key] = policy
        else:
            found = learner_names(key, names, classes)
            for name in found:
                by_name.setdefault(name, policy)
    learning = sorted(set(by_name) & set(learners))
    if learning:
        raise ValueError(f"others: agent {learning[0]!r} is a learner (agents selects it)")
    here: dict[str, Callable[[Any], Any]] = {}
    served: dict[str, str] = {}
    for name in names:
        if name in learners or name in already:
            continue
        policy = by_name.get(name, HEURISTIC)
        if callable(policy):
            here[name] = policy
        elif policy == HEURISTIC:
            if classes is None or not classes[name].has_heuristic():
                what = (
                    "its class has no heuristic"
                    if classes is not None
                    else "its heuristic cannot be checked without the environment's target"
                )
                raise ValueError(
                    f"agent {name!r} neither learns nor has a policy in others, and {what}: "
                    f"give others={{{name!r}: 'policy.onnx'}} or a callable, or define "
                    f"{classes[name].__name__ if classes else 'its class'}.heuristic"
                )
            served[name] = HEURISTIC
        elif isinstance(policy, str | os.PathLike):
            path = os.fspath(policy)
            if not os.path.isfile(path):
                raise ValueError(f"others[{name!r}]: no such policy file: {path}")
            served[name] = os.path.abspath(path)
        else:
            raise TypeError(
                f"others[{name!r}] must be 'heuristic', an ONNX file or a callable, not {policy!r}"
            )
    return here, served


def _columns(
    outcome: Mapping[str, Any] | None, instances: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(reward, terminated, truncated)`` of one agent's batched outcome map.

    ``None`` (no instance's answer holds the agent: agents that come and go): 0 and false; a
    joined agent's first reward (``None``) is 0. A group's (arrays over its members) is the
    group's as one agent: its members' rewards summed, and ended where no member is left in
    play (terminated if one of those that ended now terminated).
    """
    if outcome is None:
        return np.zeros(instances), np.zeros(instances, np.bool_), np.zeros(instances, np.bool_)
    if "joined" in outcome:  # rows whose answer lacks the group: 0 and false
        reward, terminated, truncated = as_one(outcome)
        present = outcome["_active"]
        return reward, terminated & present, truncated & present
    reward = outcome["reward"]
    if isinstance(reward, np.ndarray) and reward.dtype == object:
        reward = np.where(reward == None, 0.0, reward)  # noqa: E711 (elementwise)
    return (
        np.asarray(reward, np.float64),
        np.asarray(outcome["terminated"], np.bool_),
        np.asarray(outcome["truncated"], np.bool_),
    )
