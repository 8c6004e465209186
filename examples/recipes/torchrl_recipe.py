"""TorchRL on rlenv: ``GymEnv``, ``ParallelEnv``, ``check_env_specs``, ``PettingZooWrapper``.

    pip install torch==2.13.0            # a CPU torch first, or pip pulls a CUDA build
    pip install torchrl 'rlenv[pettingzoo]'
    python examples/recipes/torchrl_recipe.py [--smoke] [--rounds R] [--seconds S]

A registered id is a gymnasium id to TorchRL's ``GymEnv`` (each one starts a server subprocess),
so ``ParallelEnv`` workers each get their own. An environment of several agents goes through
``RemoteParallelEnv`` (PettingZoo's parallel API) into ``PettingZooWrapper``: with
``use_mask=True`` and ``done_on_any=False``, an agent whose episode ended before the others' is
masked out until the joint episode ends. Then the figure: ``rollout`` steps/s on
``rlenv/CartPole-v1`` against ``CartPole-v1``, in ``GymEnv`` and in a ``ParallelEnv`` of 2.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import torch
from _turns import Measure, Stepper, arguments, print_contest, timed
from torchrl.envs import EnvBase, GymEnv, ParallelEnv, check_env_specs
from torchrl.envs.libs.pettingzoo import PettingZooWrapper

import rlenv_client  # noqa: F401  (registers the rlenv/ ids with gymnasium)
from rlenv_client.pettingzoo import RemoteParallelEnv

PAIR = "rlenv.examples.pair:PairEnvironment"


def rlenv_cartpole() -> EnvBase:
    """The id ``rlenv/CartPole-v1`` as TorchRL's ``GymEnv`` (``ParallelEnv`` calls it)."""
    return GymEnv("rlenv/CartPole-v1")


def native_cartpole() -> EnvBase:
    """Gymnasium's own CartPole-v1, the baseline."""
    return GymEnv("CartPole-v1")


def parallel(make: Callable[[], EnvBase]) -> EnvBase:
    """Two ``make`` environments in a ``ParallelEnv``, its workers forked.

    The default start method, spawn, imports torch afresh in every worker (seconds each on a
    small machine); fork starts them at once (on the CPU: the recipe checks it).
    """
    return ParallelEnv(2, make, mp_start_method="fork")


def rollouts(env: EnvBase, steps: int) -> Stepper:
    """A rollout of ``steps`` steps across episodes; how many env-steps it made."""
    return lambda: env.rollout(steps, break_when_any_done=False).numel()


def check_one_agent() -> None:
    """``check_env_specs`` on ``GymEnv`` and ``ParallelEnv``, and rollouts across episodes."""
    env = rlenv_cartpole()
    try:
        check_env_specs(env, seed=0)
        rollout = env.rollout(600, break_when_any_done=False)
        assert rollout.batch_size == torch.Size([600])
        assert rollout["next", "done"].any(), "600 random steps end at least one episode"
        assert (rollout["next", "reward"] == 1.0).all()
    finally:
        env.close()
    envs = parallel(rlenv_cartpole)
    try:
        check_env_specs(envs, seed=0)
        assert envs.rollout(50, break_when_any_done=False).batch_size == torch.Size([2, 50])
    finally:
        envs.close()


def check_masks() -> None:
    """``PettingZooWrapper`` with masks on ``rlenv/Pair-v0``'s two agents.

    An agent that ended is masked while the other plays on; both play again from the joint
    episode's next start.
    """
    torch.manual_seed(0)
    env = PettingZooWrapper(
        RemoteParallelEnv(PAIR, max_cycles=300), use_mask=True, done_on_any=False, seed=0
    )
    try:
        check_env_specs(env, seed=0)
        assert set(env.group_map) == {"Red", "Blue"}
        rollout = env.rollout(600, break_when_any_done=False)
        masks = torch.stack([rollout[agent, "mask"][:, 0] for agent in ("Red", "Blue")], dim=1)
        joint_done = rollout["next", "done"][:, 0]
        assert (~masks).any(), "in 600 random steps one agent ends before the other"
        starts = torch.cat([torch.tensor([True]), joint_done[:-1]])
        assert masks[starts].all(), "every agent plays at an episode's start"
        unmasked_again = masks[1:] & ~masks[:-1] & ~starts[1:, None]
        assert not unmasked_again.any(), "a masked agent stays masked until the episode ends"
    finally:
        env.close()


def seeded_rollouts(env: EnvBase, steps: int, seconds: float) -> Measure:
    """One round: ``env``'s rollouts of ``steps`` steps, seeded 0 (warmed up: :func:`timed`)."""
    env.set_seed(0)
    return timed(rollouts(env, steps), seconds)


def main() -> None:
    """The checks, then the figure."""
    args = arguments(__doc__)
    check_one_agent()
    check_masks()
    print("TorchRL: GymEnv, ParallelEnv, check_env_specs and PettingZooWrapper masks: ok")
    for name, wrap, steps in (
        ("GymEnv rollout", lambda make: make(), 100),
        ("ParallelEnv(2) rollout", parallel, 50),
    ):
        ours, theirs = wrap(rlenv_cartpole), wrap(native_cartpole)
        measure = functools.partial(seeded_rollouts, steps=steps, seconds=args.seconds)
        print_contest(f"TorchRL {name}", ours, theirs, measure, args.rounds)


if __name__ == "__main__":
    main()
