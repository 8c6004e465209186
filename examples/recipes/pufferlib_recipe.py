"""PufferLib on rlenv: emulation, and its Serial and Multiprocessing vectorisation.

    pip install torch==2.13.0                # a CPU torch first, or pip pulls a CUDA build
    pip install --no-deps pufferlib-core     # it pins torch==2.9.0: --no-deps keeps yours
    pip install psutil 'rlenv[pettingzoo]'   # pufferlib.vector imports psutil
    python examples/recipes/pufferlib_recipe.py [--smoke] [--rounds R] [--seconds S]

``GymnasiumPufferEnv`` takes ``gymnasium.make`` of a registered id (a server subprocess each),
``PettingZooPufferEnv`` a ``RemoteParallelEnv`` of several agents; ``pufferlib.vector.make``
runs them in this process (``Serial``) or in worker processes (``Multiprocessing``). Checked:
both backends give the observations, rewards and ends of ``gymnasium.make`` stepped directly
with the same seeds and actions, bit for bit, across autoresets; on ``rlenv/Pair-v0`` an agent
that ended is masked. Then the figure: steps/s on ``rlenv/CartPole-v1`` against ``CartPole-v1``.
"""

from __future__ import annotations

import functools
import itertools
from typing import Any

import gymnasium as gym
import numpy as np
import pufferlib.emulation
import pufferlib.vector
from _turns import Measure, Stepper, arguments, print_contest, timed

import rlenv_client  # noqa: F401  (registers the rlenv/ ids with gymnasium)
from rlenv_client.pettingzoo import RemoteParallelEnv

WORKERS = 2
BACKENDS = {
    "Serial": (pufferlib.vector.Serial, {}),
    # overwork: allowed beyond one worker a physical core (a 1-core machine still runs it).
    "Multiprocessing": (
        pufferlib.vector.Multiprocessing,
        {"num_workers": WORKERS, "overwork": True},
    ),
}
ENVS = 4


def seeds(backend: str, seed: int) -> list[int]:
    """The seeds that ``reset(seed=seed)`` gives the envs, in order.

    ``seed + i`` on ``Serial``; on ``Multiprocessing`` worker ``w``'s ``j``-th env gets
    ``seed + w + j``, so seeds repeat across workers (PufferLib's doing, on any environment).
    """
    if backend == "Serial":
        return [seed + i for i in range(ENVS)]
    per_worker = ENVS // WORKERS
    return [seed + i // per_worker + i % per_worker for i in range(ENVS)]


def cartpole(env_id: str, buf: Any = None, seed: int = 0) -> pufferlib.emulation.GymnasiumPufferEnv:
    """``env_id`` emulated for PufferLib (``buf`` and ``seed`` are the vector's)."""
    return pufferlib.emulation.GymnasiumPufferEnv(env=gym.make(env_id), buf=buf, seed=seed)


def pair(buf: Any = None, seed: int = 0) -> pufferlib.emulation.PettingZooPufferEnv:
    """``rlenv/Pair-v0``'s two agents, through PettingZoo's parallel API."""
    env = RemoteParallelEnv("rlenv.examples.pair:PairEnvironment", max_cycles=300)
    return pufferlib.emulation.PettingZooPufferEnv(env=env, buf=buf, seed=seed)


def vector(backend: str, creator: Any, envs: int = ENVS) -> Any:
    """``envs`` environments of ``creator`` on one of :data:`BACKENDS`."""
    kind, options = BACKENDS[backend]
    return pufferlib.vector.make(creator, backend=kind, num_envs=envs, **options)


def check_against_gymnasium(backend: str, steps: int = 300) -> None:
    """The vector's transitions are ``gymnasium.make``'s, bit for bit, across autoresets.

    PufferLib seeds the envs as :func:`seeds` says, and resets an env that ended on its next
    step (that step's action unused, its rewards and ends zero), unseeded.
    """
    envs = vector(backend, functools.partial(cartpole, "rlenv/CartPole-v1"))
    references = [gym.make("rlenv/CartPole-v1") for _ in range(ENVS)]
    try:
        observations, _ = envs.reset(seed=7)
        expected = [
            env.reset(seed=s)[0] for env, s in zip(references, seeds(backend, 7), strict=True)
        ]
        assert np.array_equal(observations, np.stack(expected))
        ended, episodes = [False] * ENVS, 0
        actions = np.random.default_rng(0).integers(0, 2, (steps, ENVS))
        for action in actions:
            observations, rewards, terminals, truncations, _ = envs.step(action)
            for i, env in enumerate(references):
                if ended[i]:
                    want, reward, terminal, truncation = env.reset()[0], 0.0, False, False
                else:
                    want, reward, terminal, truncation, _ = env.step(int(action[i]))
                ended[i] = terminal or truncation
                episodes += ended[i]
                assert np.array_equal(observations[i], want), (backend, i)
                assert (rewards[i], terminals[i], truncations[i]) == (reward, terminal, truncation)
        assert episodes >= ENVS, f"{steps} random steps end episodes in every env"
    finally:
        envs.close()
        for env in references:
            env.close()


def check_masks(backend: str, steps: int = 600) -> None:
    """On ``rlenv/Pair-v0`` an agent whose episode ended is masked while the other plays on."""
    envs = vector(backend, pair, envs=WORKERS)
    try:
        assert envs.num_agents == 2 * WORKERS
        envs.async_reset(seed=0)
        envs.recv()
        masked = 0
        rng = np.random.default_rng(0)
        for _ in range(steps):
            envs.send(rng.uniform(-1, 1, (2 * WORKERS, 2)).astype(np.float32))
            observations, _, _, _, _, _, _, masks = envs.recv()
            masked += int((masks.reshape(WORKERS, 2).sum(axis=1) == 1).sum())
            assert not observations[~masks].any(), "a masked agent's observation is zeros"
        assert masked, f"in {steps} random steps one agent ends before the other"
    finally:
        envs.close()


def random_steps(envs: Any) -> Stepper:
    """A vector's step of random actions (drawn beforehand), counting its env-steps."""
    envs.action_space.seed(0)
    actions = itertools.cycle([envs.action_space.sample() for _ in range(64)])

    def step() -> int:
        for _ in range(10):
            envs.step(next(actions))
        return 10 * envs.num_agents

    return step


def main() -> None:
    """The checks, then the figure."""
    args = arguments(__doc__)
    for backend in BACKENDS:
        check_against_gymnasium(backend)
        check_masks(backend)
    print("PufferLib: emulation, Serial and Multiprocessing, Pair's masks: ok")

    def measure(envs: Any) -> Measure:
        envs.reset(seed=0)
        return timed(random_steps(envs), args.seconds)

    for backend in BACKENDS:
        ours = vector(backend, functools.partial(cartpole, "rlenv/CartPole-v1"))
        theirs = vector(backend, functools.partial(cartpole, "CartPole-v1"))
        print_contest(f"PufferLib {backend}({ENVS})", ours, theirs, measure, args.rounds)


if __name__ == "__main__":
    main()
