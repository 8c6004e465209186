"""Imitation, end to end: demonstrations -> Minari dataset -> behaviour cloning -> ONNX -> served.

``python benchmarks/imitation.py [--episodes E] [--eval-episodes K] [--epochs N] [--out DIR]
[--only NAME]`` (the onnx and minari extras, torch; ``OMP_NUM_THREADS=1``). For each of two
examples with a scripted expert:

- ``cartpole``: ``rlenv/CartPole-v1`` (``examples.classic_cartpole``, ``Discrete(2)``), the
  expert ``heuristic`` (push towards where the pole falls), 500-step episodes;
- ``plinko``: ``rlenv/Plinko-v0`` (``examples.plinko``, a ``Box(1)`` action, a new level every
  episode), the expert ``follow`` (keep the catcher under the ball), 100-step episodes, return
  1 for a caught ball;

it records ``E`` episodes of the expert as exact recordings
(:func:`rlenv_tools.demonstrations.record`, seeds 10000 and on), turns them into a Minari
dataset (:func:`rlenv_tools.datasets.create_dataset`, which re-simulates and checks every
observation; ``MINARI_DATASETS_PATH`` is ``DIR/minari``), reads it back with
``minari.load_dataset``, trains behaviour cloning on its (observation, action) pairs with plain
torch (an MLP of 2 x 64 tanh units, inputs standardised by the dataset's mean and deviation;
cross-entropy for ``Discrete``, mean squared error for ``Box``; Adam, seeded), exports it with
:func:`rlenv_tools.policies.export_onnx`, serves it with ``rlenv serve TARGET --policy
Agent=FILE --max-episode-steps N`` in a subprocess, and reads the returns of its first ``K``
episodes (seeded 0 to K-1 by the server) from an observer's ``client.stats()``. The expert plays
the same ``K`` seeds through ``gymnasium.make`` for its mean return. A table compares them.

The defaults (40 demonstrations, 100 evaluation episodes, 30 epochs) take about a minute on 2
cores; ``--episodes 5 --eval-episodes 10 --epochs 5`` about 15 seconds. Figures in
``docs/policies-and-data.md`` ("Imitation, end to end").
"""

from __future__ import annotations

import argparse
import os
import shutil
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from torch import nn

import rlenv_client  # noqa: F401  (registers the rlenv/ ids)
from rlenv.examples.classic_cartpole import heuristic
from rlenv.examples.plinko import follow
from rlenv_client import Client, ServerProcess
from rlenv_tools.demonstrations import record
from rlenv_tools.policies import export_onnx

DEMONSTRATION_SEED = 10_000  # demonstrations start here; evaluation uses seeds 0 to K-1


@dataclass(frozen=True)
class Task:
    name: str
    env_id: str
    target: str
    expert: Callable[[np.ndarray], Any]
    max_episode_steps: int


TASKS = (
    Task(
        "cartpole",
        "rlenv/CartPole-v1",
        "examples.classic_cartpole:ClassicCartPoleEnvironment",
        heuristic,
        500,
    ),
    Task("plinko", "rlenv/Plinko-v0", "examples.plinko:PlinkoEnvironment", follow, 100),
)


class Cloned(nn.Module):
    """An MLP on standardised observations: logits for ``Discrete``, the action for ``Box``."""

    def __init__(self, mean: np.ndarray, std: np.ndarray, outputs: int) -> None:
        super().__init__()
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32))
        self.net = nn.Sequential(
            nn.Linear(len(mean), 64),
            nn.Tanh(),
            nn.Linear(64, 64),
            nn.Tanh(),
            nn.Linear(64, outputs),
        )

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return self.net((observation.float() - self.mean) / self.std)


def make_dataset(task: Task, episodes: int, out: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """Record the expert, make the Minari dataset, read it back: (observations, actions, s)."""
    import minari

    from rlenv_tools.datasets import create_dataset

    demos = out / task.name / "demonstrations"
    shutil.rmtree(demos, ignore_errors=True)
    start = time.perf_counter()
    record(task.env_id, task.expert, episodes, demos, seed=DEMONSTRATION_SEED)
    dataset_id = f"rlenv-{task.name}/expert-v0"
    create_dataset(dataset_id, demos, algorithm_name=f"scripted {task.expert.__name__}")
    dataset = minari.load_dataset(dataset_id)
    observations, actions = [], []
    for episode in dataset.iterate_episodes():
        observations.append(episode.observations[:-1])  # T+1 observations, T actions
        actions.append(episode.actions)
    return np.concatenate(observations), np.concatenate(actions), time.perf_counter() - start


def train(
    observations: np.ndarray,
    actions: np.ndarray,
    action_space: spaces.Space,
    epochs: int,
    seed: int = 0,
) -> Cloned:
    """Behaviour cloning: cross-entropy (Discrete) or mean squared error (Box), Adam."""
    torch.manual_seed(seed)
    discrete = isinstance(action_space, spaces.Discrete)
    mean, std = observations.mean(0), observations.std(0) + 1e-6
    outputs = int(action_space.n) if discrete else int(np.prod(action_space.shape))
    model = Cloned(mean, std, outputs)
    x = torch.as_tensor(observations, dtype=torch.float32)
    if discrete:
        y = torch.as_tensor(actions, dtype=torch.int64).reshape(-1) - int(action_space.start)
        loss_fn: Callable[..., torch.Tensor] = nn.functional.cross_entropy
    else:
        y = torch.as_tensor(actions, dtype=torch.float32).reshape(len(x), -1)
        loss_fn = nn.functional.mse_loss
    optimiser = torch.optim.Adam(model.parameters(), lr=1e-3)
    generator = torch.Generator().manual_seed(seed)
    for _ in range(epochs):
        for batch in torch.randperm(len(x), generator=generator).split(64):
            loss = loss_fn(model(x[batch]), y[batch])
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
    return model.eval()


def expert_returns(task: Task, count: int) -> list[float]:
    """The expert's returns on seeds 0 to count-1, as the served policy's episodes are seeded."""
    env = gym.make(task.env_id, max_episode_steps=task.max_episode_steps)
    returns = []
    try:
        for seed in range(count):
            observation, _ = env.reset(seed=seed)
            total, done = 0.0, False
            while not done:
                observation, reward, terminated, truncated, _ = env.step(task.expert(observation))
                total += float(reward)
                done = terminated or truncated
            returns.append(total)
    finally:
        env.close()
    return returns


def served_returns(task: Task, policy: Path, count: int, timeout: float = 600.0) -> list[float]:
    """Serve the policy file for the agent; an observer reads its first ``count`` returns."""
    server = ServerProcess(
        task.target,
        args=["--policy", f"Agent={policy}", "--max-episode-steps", str(task.max_episode_steps)],
    )
    try:
        with Client(server.host, server.port, timeout=10) as observer:
            deadline = time.monotonic() + timeout
            while True:
                stats = observer.stats()
                if stats["next"] >= count:
                    break
                if time.monotonic() > deadline:
                    raise TimeoutError(
                        f"{task.name}: {stats['next']} of {count} episodes after {timeout} s"
                    )
                time.sleep(0.05)
    finally:
        server.close()
    episodes = sorted(stats["episodes"], key=lambda record: record["episode"])[:count]
    return [float(record["return"]) for record in episodes]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=40, help="demonstrations per example")
    parser.add_argument(
        "--eval-episodes",
        type=int,
        default=100,
        help="episodes of the expert and of the served policy",
    )
    parser.add_argument("--epochs", type=int, default=30, help="behaviour cloning epochs")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("imitation-out"),
        help="demonstrations, datasets (DIR/minari) and policy files",
    )
    parser.add_argument(
        "--only",
        choices=[task.name for task in TASKS],
        action="append",
        help="run only this example (repeatable)",
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    warnings.filterwarnings("ignore", module="minari")  # metadata it recommends (author, ...)
    args.out.mkdir(parents=True, exist_ok=True)
    datasets = (args.out / "minari").resolve()
    shutil.rmtree(datasets, ignore_errors=True)  # a rerun makes its datasets afresh
    os.environ["MINARI_DATASETS_PATH"] = str(datasets)
    rows = []
    for task in TASKS:
        if args.only and task.name not in args.only:
            continue
        started = time.perf_counter()
        observations, actions, data_seconds = make_dataset(task, args.episodes, args.out)
        env = gym.make(task.env_id)
        observation_space, action_space = env.observation_space, env.action_space
        env.close()
        clock = time.perf_counter()
        model = train(observations, actions, action_space, args.epochs)
        train_seconds = time.perf_counter() - clock
        policy = export_onnx(
            model, args.out / task.name / "bc.onnx", observation_space, action_space
        )
        clock = time.perf_counter()
        cloned = served_returns(task, policy, args.eval_episodes)
        expert = expert_returns(task, args.eval_episodes)
        eval_seconds = time.perf_counter() - clock
        rows.append(
            (
                task.name,
                len(observations),
                float(np.mean(expert)),
                float(np.mean(cloned)),
                data_seconds,
                train_seconds,
                eval_seconds,
                time.perf_counter() - started,
            )
        )
        print(
            f"{task.name}: {len(observations)} steps in {args.episodes} demonstrations; "
            f"expert {np.mean(expert):.3f}, behaviour cloning {np.mean(cloned):.3f} "
            f"over {args.eval_episodes} episodes",
            flush=True,
        )
    print()
    print(
        "| example | demo steps | expert mean return | BC mean return | BC / expert | "
        "record + dataset s | train s | evaluate s | total s |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, steps, expert, cloned, data_s, train_s, eval_s, total in rows:
        ratio = cloned / expert if expert else float("nan")
        print(
            f"| {name} | {steps} | {expert:.3f} | {cloned:.3f} | {ratio:.2f} | {data_s:.1f} | "
            f"{train_s:.1f} | {eval_s:.1f} | {total:.1f} |"
        )


if __name__ == "__main__":
    main()
