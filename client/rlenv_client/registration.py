"""Gymnasium ids for the shipped examples: ``gymnasium.make("rlenv/CartPole-v0")``.

Registered when ``rlenv_client`` is imported (so ``gymnasium.register_envs(rlenv_client)``
works too). The examples ship inside the distribution, as ``rlenv.examples``, and the ids name
them so: they work from any directory. In a checkout, whose examples are the top-level
``examples`` package, the server loads ``rlenv.examples.X`` as ``examples.X``
(:mod:`rlenv.targets`), so one process never holds both.
Every id also has a vector entry point, so ``gymnasium.make_vec`` builds a
:class:`~rlenv_client.vector.RemoteVectorEnv`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import gymnasium

__all__ = ["ENVIRONMENTS", "register_environments"]


@dataclass(frozen=True)
class _Registration:
    target: str
    max_episode_steps: int | None
    several_agents: bool = False


ENVIRONMENTS = {
    "rlenv/CartPole-v0": _Registration("rlenv.examples.cartpole:CartPoleEnvironment", 500),
    "rlenv/CartPole-v1": _Registration(
        "rlenv.examples.classic_cartpole:ClassicCartPoleEnvironment", 500
    ),
    "rlenv/Hunt-v0": _Registration(
        "rlenv.examples.hunt:HuntEnvironment", None, several_agents=True
    ),
    "rlenv/Maze-v0": _Registration("rlenv.examples.maze:MazeEnvironment", 250),
    "rlenv/Pair-v0": _Registration("rlenv.examples.pair:PairEnvironment", 300, several_agents=True),
    "rlenv/Pixels-v0": _Registration("rlenv.examples.pixels:PixelsEnvironment", 1000),
    "rlenv/Plinko-v0": _Registration("rlenv.examples.plinko:PlinkoEnvironment", 100),
    "rlenv/Reacher-v0": _Registration("rlenv.examples.reacher:ReacherEnvironment", 200),
    "rlenv/Swarm-v0": _Registration(
        "rlenv.examples.swarm:SwarmEnvironment", None, several_agents=True
    ),
    "rlenv/Tag-v0": _Registration("rlenv.examples.tag:TagEnvironment", 300, several_agents=True),
    "rlenv/Seeker-v0": _Registration("rlenv.examples.seeker:SeekerEnvironment", 250),
    "rlenv/SeekerPixels-v0": _Registration("rlenv.examples.seeker:SeekerPixelsEnvironment", 250),
}
"""Registered ids and what they serve. CartPole never ends by itself when balanced, so it gets
a time limit (500 steps of 4 ticks: 33 simulated seconds), as gym-kraby's TimeLimit lesson
teaches. ``rlenv/CartPole-v1`` is gymnasium's ``CartPole-v1`` (its spaces, rewards, thresholds
and 500-step limit) on rlenv's physics, for scripts written for gymnasium's. An id of several
agents also gives its limit to :class:`~rlenv_client.env.RemoteEnv`, which truncates every agent
still in the episode in ``info["agents"]`` as well (gymnasium's ``TimeLimit``, which ``make``
still adds, cuts only the joint episode). ``rlenv/Hunt-v0`` and ``rlenv/Swarm-v0`` need none:
the hunt truncates itself after 1,200 ticks, the swarm after 600."""


def register_environments() -> None:
    """Register every id in :data:`ENVIRONMENTS` with gymnasium (once).

    gymnasium takes a lower version of a name for an outdated one and warns on every ``make``;
    ``rlenv/CartPole-v0`` is not an older ``rlenv/CartPole-v1`` but another environment (a
    continuous push, 4 ticks a step), so that one warning is silenced.
    """
    warnings.filterwarnings(
        "ignore",
        message=r".*The environment rlenv/CartPole-v0 is out of "
        r"date",
        category=DeprecationWarning,
    )
    for env_id, registration in ENVIRONMENTS.items():
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=env_id,
            entry_point="rlenv_client.env:RemoteEnv",
            vector_entry_point="rlenv_client.vector:RemoteVectorEnv",
            kwargs={
                "target": registration.target,
                **(
                    {"max_episode_steps": registration.max_episode_steps}
                    if registration.several_agents
                    else {}
                ),
            },
            max_episode_steps=registration.max_episode_steps,
        )
