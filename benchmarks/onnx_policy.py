"""What a policy file costs per step: onnxruntime against the torch policy, and served episodes.

``python benchmarks/onnx_policy.py [--rounds R] [--steps N] [--seconds S]`` (the onnx extra,
torch and stable-baselines3; ``OMP_NUM_THREADS=1`` as the server's session uses one thread).
A fresh SB3 PPO on rlenv's CartPole (its default MLP: 64x64, tanh) is exported with
``export_onnx``; in turns, each round times ``N`` single-observation calls of onnxruntime (as
``rlenv serve --policy`` makes them: ``OnnxPolicy.act``) and of the torch policy's
``predict(deterministic=True)``. Then ``rlenv serve ... --policy Agent=FILE`` plays episodes
for ``S`` seconds per round and an observer reads the steps it counted (``stats()``): the
served policy-driven steps/s. It prints the median of each and the ratio.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import PPO

from rlenv.serving._host import Host
from rlenv.serving.onnx_policy import OnnxPolicy
from rlenv_client import Client, ServerProcess
from rlenv_tools.policies import export_onnx

TARGET = "examples.cartpole:CartPoleEnvironment"


def _per_call(act, observations: np.ndarray) -> float:
    start = time.perf_counter()
    for observation in observations:
        act(observation)
    return (time.perf_counter() - start) / len(observations)


def _served_rate(path: Path, seconds: float) -> float:
    server = ServerProcess(TARGET, args=["--policy", f"Agent={path}"])
    try:
        with Client(server.host, server.port, timeout=10) as observer:
            first, start = observer.stats()["steps"], time.perf_counter()
            deadline = start + seconds
            while time.perf_counter() < deadline:
                stats = observer.stats()  # one observer request at a time, as the inspector
            elapsed = time.perf_counter() - start
            return (stats["steps"] - first) / elapsed
    finally:
        server.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    torch.set_num_threads(1)
    host = Host(TARGET)
    agent = host.instances[0].agents[0]
    observation_space, action_space = agent.observation_space, agent.action_space
    host.close()

    class _Spaces(gym.Env):
        def __init__(self) -> None:
            self.observation_space, self.action_space = observation_space, action_space

    model = PPO("MlpPolicy", _Spaces(), seed=0, device="cpu", n_steps=64)
    with tempfile.TemporaryDirectory() as directory:
        path = export_onnx(model, Path(directory) / "ppo.onnx")
        policy = OnnxPolicy(path)
        rng = np.random.default_rng(0)
        observations = rng.uniform(-1, 1, (args.steps, 5)).astype(np.float32)
        onnx_times, torch_times, served = [], [], []

        def predict(observation: np.ndarray) -> None:
            model.policy.predict(observation, deterministic=True)

        for round_ in range(args.rounds):
            pair = [(onnx_times, policy.act), (torch_times, predict)]
            for times, act in pair if round_ % 2 == 0 else pair[::-1]:
                times.append(_per_call(act, observations))
            served.append(_served_rate(path, args.seconds))
        onnx_us, torch_us = (statistics.median(t) * 1e6 for t in (onnx_times, torch_times))
        print(f"onnxruntime OnnxPolicy.act:          {onnx_us:8.1f} us per step")
        print(
            f"torch policy.predict(deterministic): {torch_us:8.1f} us per step "
            f"({torch_us / onnx_us:.1f}x onnxruntime)"
        )
        print(
            f"served policy-driven CartPole:       {statistics.median(served):8.0f} steps/s "
            f"(min {min(served):.0f}, {args.rounds} rounds of {args.seconds} s)"
        )


if __name__ == "__main__":
    main()
