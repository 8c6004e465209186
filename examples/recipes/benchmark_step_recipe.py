"""Gymnasium's own benchmarks on rlenv: ``benchmark_step`` and ``benchmark_vector_step``.

    pip install rlenv
    python examples/recipes/benchmark_step_recipe.py [--smoke] [--rounds R] [--seconds S]

``gymnasium.utils.performance.benchmark_step(env, target_duration, seed)`` steps random actions
for ``target_duration`` seconds, resetting at each episode's end, and returns steps/s; here on
``gym.make("rlenv/CartPole-v1")`` (a server subprocess) against ``gym.make("CartPole-v1")``,
one call a round, in turns. ``benchmark_vector_step`` does the same for ``gym.make_vec`` of 8:
rlenv's id makes its ``RemoteVectorEnv`` (servers in columns), CartPole-v1's default is
gymnasium's NumPy ``CartPoleVectorEnv``, and ``vectorization_mode="sync"`` a
``SyncVectorEnv`` of 8 (measured too, for the Python loop a user's own environment gets).
A gymnasium without ``benchmark_vector_step`` (before 1.3) measures ``benchmark_step`` alone,
and says so.
"""

from __future__ import annotations

import gymnasium as gym
from _turns import Measure, arguments, print_contest
from gymnasium.utils import performance

import rlenv_client  # noqa: F401  (registers the rlenv/ ids with gymnasium)

VECTOR = 8


def benchmark(env: gym.Env | gym.vector.VectorEnv, seconds: float) -> Measure:
    """One round: gymnasium's benchmark of ``env`` (a vector's if it is one), seeded 0."""
    if isinstance(env, gym.vector.VectorEnv):
        return lambda: performance.benchmark_vector_step(env, target_duration=seconds, seed=0)
    return lambda: performance.benchmark_step(env, target_duration=seconds, seed=0)


def main() -> None:
    """One figure a benchmark."""
    args = arguments(__doc__)

    def measure(env: gym.Env | gym.vector.VectorEnv) -> Measure:
        return benchmark(env, args.seconds)

    print_contest(
        "gymnasium benchmark_step",
        gym.make("rlenv/CartPole-v1"),
        gym.make("CartPole-v1"),
        measure,
        args.rounds,
    )
    if not hasattr(performance, "benchmark_vector_step"):
        print(f"gymnasium benchmark_vector_step: not in gymnasium {gym.__version__}, not run")
        return
    for mode in (None, "sync"):
        ours = gym.make_vec("rlenv/CartPole-v1", num_envs=VECTOR)
        theirs = gym.make_vec("CartPole-v1", num_envs=VECTOR, vectorization_mode=mode)
        print_contest(
            f"gymnasium benchmark_vector_step, make_vec({VECTOR}) against CartPole-v1's "
            f"{type(theirs.unwrapped).__name__}",
            ours,
            theirs,
            measure,
            args.rounds,
        )


if __name__ == "__main__":
    main()
