"""``rlenv bench --train``: what serving costs a real trainer, beside the environment in process.

Random actions flatter a serving layer: a trainer computes a policy between steps, and the
everyday trainers step their environments one at a time. This module measures the patterns
trainers use, each against the same environment run in the trainer's own process
(``in_process=True``), their rounds taken in turns so that both see the same machine:

- **PPO** from Stable-Baselines3 (if installed) with 8 environments, in two configurations:
  rl-zoo's CartPole-v1 hyperparameters (``n_steps`` 32, ``batch_size`` 256, 20 epochs) and a
  rollout-heavy one (``n_steps`` 128, ``batch_size`` 256, 1 epoch). The environments are reached
  as SB3 users write it, ``make_vec_env`` (SB3's ``DummyVecEnv``, stepping one environment after
  the other), and through rlenv's :class:`~rlenv_client.sb3.SB3VecEnv` (every environment at
  once); the baseline is ``make_vec_env`` of in-process environments.
- **gymnasium's SyncVectorEnv** of k environments on random actions, for k up to 16: what a
  sequential trainer (CleanRL's ``ppo.py``) pays per environment as environments are added,
  against one environment (k = 1) and against k in process.

Each figure is a rate (environment steps per second) with its ratio to the baseline of the same
round; the table gives the median of the rates and the median and minimum of the per-round
ratios. A CPU-bound process of something else (``busy=True``) and torch's thread count
(``torch_threads``) show how the figures hold on a loaded machine.
"""

from __future__ import annotations

import functools
import json
import logging
import statistics
import subprocess
import sys
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import gymnasium

from rlenv_client.launcher import end_process
from rlenv_tools._bench import Rate, interleaved

__all__ = [
    "PPO_CONFIGS",
    "Measure",
    "Row",
    "busy_process",
    "format_rows",
    "measure_training",
    "ppo_rows",
    "resolve_target",
    "rows_to_json",
    "sync_vector_rows",
]

PPO_CONFIGS: dict[str, dict[str, Any]] = {
    "rl-zoo": {
        "n_steps": 32,
        "batch_size": 256,
        "n_epochs": 20,
        "gae_lambda": 0.8,
        "gamma": 0.98,
        "ent_coef": 0.0,
        "learning_rate": 1e-3,
        "clip_range": 0.2,
    },
    "rollout-heavy": {"n_steps": 128, "batch_size": 256, "n_epochs": 1},
}
"""PPO's hyperparameters for each configuration: rl-zoo's for CartPole-v1 (constant rates
instead of its linear schedules), and one that spends most of its time collecting rollouts."""


class Measure(Rate):
    """One way of running a trainer: ``run(steps)`` trains or steps ``steps`` environment steps.

    A :class:`~rlenv_tools._bench.Rate` (its rounds taken in turns by
    :func:`~rlenv_tools._bench.interleaved`) that knows how to free what it holds.

    Args:
        name: what the row says.
        run: does the work, counting environment steps.
        steps: environment steps per round.
        warmup: environment steps of the warm-up round.
        close: frees what it holds.
    """

    def __init__(
        self,
        name: str,
        run: Callable[[int], None],
        steps: int,
        warmup: int,
        close: Callable[[], None],
    ) -> None:
        super().__init__(run, steps, name=name, warmup=warmup)
        self.close = close


@dataclass(frozen=True)
class Row:
    """A figure of the table: a rate, and its ratios to the baseline of each round."""

    group: str
    name: str
    rate: float
    baseline: str
    ratio: float
    ratio_min: float


def resolve_target(target: str) -> tuple[str, int | None]:
    """``MODULE:CLASS`` and its time limit, for a registered id or a ``MODULE:CLASS``.

    A registered id (``rlenv/CartPole-v1``) has its registered limit; a ``MODULE:CLASS`` none.
    """
    from rlenv_client.registration import ENVIRONMENTS

    if target in ENVIRONMENTS:
        registration = ENVIRONMENTS[target]
        return registration.target, registration.max_episode_steps
    if ":" not in target:
        raise ValueError(
            f"expected MODULE:CLASS or a registered id ({', '.join(ENVIRONMENTS)}), got {target!r}"
        )
    return target, None


def _env_factory(target: str, limit: int | None, **kwargs: Any) -> Callable[[], gymnasium.Env]:
    """Makes one environment as ``gymnasium.make`` of a registered id would."""
    from rlenv_client.env import RemoteEnv

    def make() -> gymnasium.Env:
        env: gymnasium.Env = RemoteEnv(target, **kwargs)
        if limit is not None:
            env = gymnasium.wrappers.TimeLimit(env, limit)
        return env

    return make


def _rows(group: str, measures: Sequence[Measure], baseline: Measure) -> list[Row]:
    rows = []
    for measure in measures:
        ratios = [rate / base for rate, base in zip(measure.rates, baseline.rates, strict=True)]
        rows.append(
            Row(
                group,
                measure.name,
                statistics.median(measure.rates),
                baseline.name,
                statistics.median(ratios),
                min(ratios),
            )
        )
    return rows


def ppo_rows(
    target: str,
    configs: Sequence[str] = tuple(PPO_CONFIGS),
    envs: int = 8,
    rounds: int = 3,
    updates: int = 12,
    native: str | None = None,
    progress: Callable[[str], None] = lambda message: None,
) -> list[Row]:
    """PPO's training speed by how it reaches ``envs`` environments (see the module docstring).

    Args:
        target: ``MODULE:CLASS`` or a registered id.
        configs: names in :data:`PPO_CONFIGS`.
        envs: environments per trainer.
        rounds: rounds of each, in turns, after a warm-up.
        updates: PPO updates (rollouts of ``n_steps`` per environment) per round.
        native: a gymnasium id to train on too, as a reference (``"CartPole-v1"``).
        progress: told each round's rates.
    """
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    from rlenv_client.sb3 import SB3VecEnv

    module_class, limit = resolve_target(target)
    ways: list[tuple[str, Callable[[], Any]]] = [
        (
            "in process: make_vec_env(in_process=True)",
            lambda: make_vec_env(_env_factory(module_class, limit, in_process=True), n_envs=envs),
        ),
        (f"SB3VecEnv({envs})", lambda: SB3VecEnv(envs, module_class, max_episode_steps=limit)),
        (
            "make_vec_env (DummyVecEnv, gym.make each)",
            lambda: make_vec_env(_env_factory(module_class, limit), n_envs=envs),
        ),
    ]
    if native is not None:
        ways.append((f"native {native}", lambda: make_vec_env(native, n_envs=envs)))
    rows: list[Row] = []
    for config in configs:
        hyperparameters = PPO_CONFIGS[config]
        batch = envs * hyperparameters["n_steps"]
        measures = []
        try:
            for name, make in ways:
                model = PPO("MlpPolicy", make(), seed=0, verbose=0, **hyperparameters)
                measures.append(
                    Measure(
                        name,
                        functools.partial(model.learn, reset_num_timesteps=False),
                        updates * batch,
                        2 * batch,
                        model.get_env().close,
                    )
                )
            progress(f"PPO, {config}: {len(measures)} trainers, {rounds} rounds in turns")
            interleaved(rounds, *measures, progress=progress)
        finally:
            for measure in measures:
                measure.close()
        rows += _rows(f"PPO ({config}), {envs} envs", measures, measures[0])
    return rows


def _random_steps(envs: gymnasium.vector.VectorEnv, seed: int = 0) -> Callable[[int], None]:
    envs.reset(seed=seed)
    envs.action_space.seed(seed)
    actions = [envs.action_space.sample() for _ in range(64)]

    def run(steps: int) -> None:
        for turn in range(max(1, steps // envs.num_envs)):
            envs.step(actions[turn % 64])

    return run


def sync_vector_rows(
    target: str,
    counts: Sequence[int] = (1, 2, 4, 8, 16),
    rounds: int = 3,
    steps: int = 8000,
    progress: Callable[[str], None] = lambda message: None,
) -> list[Row]:
    """Gymnasium's ``SyncVectorEnv`` of k served environments on random actions, by k.

    Each k is measured against k = 1 (adding environments should never cost throughput) and
    against k environments in process.
    """
    module_class, limit = resolve_target(target)
    measures: dict[tuple[int, bool], Measure] = {}
    try:
        for count in counts:
            for in_process in (False, True):
                factory = _env_factory(module_class, limit, in_process=in_process)
                vector = gymnasium.vector.SyncVectorEnv([factory] * count)
                name = f"SyncVectorEnv({count})" + (" in process" if in_process else "")
                measures[count, in_process] = Measure(
                    name, _random_steps(vector), steps, steps // 4, vector.close
                )
        progress(f"SyncVectorEnv: {len(measures)} vectors, {rounds} rounds in turns")
        interleaved(rounds, *measures.values(), progress=progress)
    finally:
        for measure in measures.values():
            measure.close()
    first = measures[counts[0], False]
    rows = _rows(
        "SyncVectorEnv, random actions: against one env",
        [measures[count, False] for count in counts],
        first,
    )
    for count in counts:
        rows += _rows(
            "SyncVectorEnv, random actions: against in process",
            [measures[count, False]],
            measures[count, True],
        )
    return rows


def busy_process() -> subprocess.Popen[bytes]:
    """A CPU-bound process of something else (stop it with ``terminate()``)."""
    return subprocess.Popen([sys.executable, "-c", "while True: pass"])


def measure_training(
    target: str,
    envs: int = 8,
    rounds: int = 3,
    busy: bool = False,
    torch_threads: int | None = None,
    native: str | None = None,
    steps: int = 8000,
    ppo: bool = True,
    progress: Callable[[str], None] = lambda message: None,
) -> list[Row]:
    """Every figure of the module docstring for ``target`` (``rlenv bench --train``).

    PPO's figures need stable-baselines3 (and torch); without them only the SyncVectorEnv
    figures are measured, and ``progress`` says why.

    Args:
        target: ``MODULE:CLASS`` or a registered id.
        envs: environments per PPO trainer.
        rounds: rounds of each figure, in turns.
        busy: keep a CPU-bound process of something else running meanwhile.
        torch_threads: ``torch.set_num_threads`` (``None``: torch's default).
        native: a gymnasium id PPO also trains on, as a reference.
        steps: env-steps per round of each SyncVectorEnv figure.
        ppo: measure PPO too (when stable-baselines3 is installed).
        progress: told what is measured, and each round's rates.
    """
    hog = busy_process() if busy else None
    try:
        rows = sync_vector_rows(target, rounds=rounds, steps=steps, progress=progress)
        if not ppo:
            return rows
        try:
            import torch
            from stable_baselines3 import PPO  # noqa: F401  (only: is it there?)
        except ImportError as error:
            progress(f"PPO skipped: {error.name} is not installed (pip install 'rlenv[sb3]')")
            return rows
        if torch_threads is not None:
            torch.set_num_threads(torch_threads)
        logging.getLogger("rlenv_client").setLevel(logging.WARNING)
        return rows + ppo_rows(target, envs=envs, rounds=rounds, native=native, progress=progress)
    finally:
        if hog is not None:
            end_process(hog, 0.0, first=None)


def rows_to_json(rows: Sequence[Row]) -> str:
    """The rows as JSON (a list of objects)."""
    return json.dumps([asdict(row) for row in rows], indent=2)


def format_rows(rows: Sequence[Row]) -> str:
    """The rows as a Markdown table, grouped."""
    lines = []
    group = None
    for row in rows:
        if row.group != group:
            group = row.group
            lines += [
                "",
                f"{group} (env-steps/s; ratio to the baseline of each round)",
                "",
                "| how the trainer reaches the envs | env-steps/s | baseline | ratio "
                "(median) | ratio (min) |",
                "|---|---:|---|---:|---:|",
            ]
        lines.append(
            f"| {row.name} | {row.rate:,.0f} | {row.baseline} | {row.ratio:.2f} | "
            f"{row.ratio_min:.2f} |"
        )
    return "\n".join(lines).lstrip("\n")
