"""A client process that a test interrupts with a real SIGINT while it waits for an answer.

Run as ``python tests/interrupted.py PATH ADDRESS...`` with PATH one of ``client``, ``env``,
``vector``, ``sb3`` or ``watcher``. It connects to the servers (``CountingEnvironment``: the
observation counts the ticks since the reset, so every answer says which request it answers),
starts an episode, prints ``ready`` and waits for a line on standard input. It then prints
``waiting`` and makes one call whose answer the test holds back (it stops a server with
SIGSTOP) until it has sent SIGINT. The call raises ``KeyboardInterrupt``, caught as a notebook
catches it (``interrupted`` is printed); the process goes on with the calls a user makes next
and prints what they returned as one line of JSON.
"""

from __future__ import annotations

import json
import sys
from typing import Any

import numpy as np

ACTION = 0  # CountingEnvironment's harmless action


def _client(addresses: list[str]) -> dict[str, Any]:
    from rlenv_client import Client

    host, port = addresses[0].rsplit(":", 1)
    client = Client(host, int(port), timeout=30)
    client.reset(seed=1)
    client.step(ACTION, repeat_action=4)
    interrupted = _wait_then(lambda: client.step(ACTION, repeat_action=8))
    observation, info = client.reset(seed=5)
    after = client.step(ACTION, repeat_action=2)
    return {
        "interrupted": interrupted,
        "reset": observation.tolist(),
        "reset_frames": info["frames"],
        "step": after[0].tolist(),
        "step_frames": after[4]["frames"],
    }


def _env(addresses: list[str]) -> dict[str, Any]:
    from rlenv_client import RemoteEnv

    env = RemoteEnv(address=addresses[0], repeat_action=4)
    env.reset(seed=1)
    env.step(ACTION)
    interrupted = _wait_then(lambda: env.step(ACTION))
    observation, _ = env.reset(seed=5)
    after = env.step(ACTION)
    return {
        "interrupted": interrupted,
        "reset": observation.tolist(),
        "step": after[0].tolist(),
        "step_frames": after[4]["frames"],
        "restarted": "server_restarted" in after[4],
    }


def _vector(addresses: list[str]) -> dict[str, Any]:
    from rlenv_client import RemoteVectorEnv

    envs = RemoteVectorEnv(addresses=addresses, repeat_action=4)
    envs.reset(seed=1)
    actions = np.zeros(envs.num_envs, np.int64)
    envs.step(actions)
    interrupted = _wait_then(lambda: envs.step(actions))
    observations, _, _, truncations, infos = envs.step(actions)
    reset, rewards, _, after_truncations, reset_infos = envs.step(actions)
    stepped, *_ = envs.step(actions)
    return {
        "interrupted": interrupted,
        "after": observations.tolist(),
        "truncated": truncations.tolist(),
        "why": list(infos["interrupted"]),
        "reset": reset.tolist(),
        "reset_truncated": after_truncations.tolist(),
        "reset_frames": reset_infos["frames"].tolist(),
        "stepped": stepped.tolist(),
    }


def _sb3(addresses: list[str]) -> dict[str, Any]:
    from rlenv_client.sb3 import SB3VecEnv

    venv = SB3VecEnv(addresses=addresses, repeat_action=4)
    venv.reset()
    actions = np.zeros(venv.num_envs, np.int64)
    venv.step(actions)
    interrupted = _wait_then(lambda: venv.step(actions))
    observations, _, dones, infos = venv.step(actions)
    stepped, *_ = venv.step(actions)
    return {
        "interrupted": interrupted,
        "after": observations.tolist(),
        "dones": dones.tolist(),
        "why": [info.get("interrupted") for info in infos],
        "stepped": stepped.tolist(),
    }


def _watcher(addresses: list[str]) -> dict[str, Any]:
    from rlenv_client import Client
    from rlenv_tools.inspector._watch import Watcher

    host, port = addresses[0].rsplit(":", 1)
    controller = Client(host, int(port), timeout=30)
    controller.reset(seed=1)
    controller.step(ACTION, repeat_action=4)
    watcher = Watcher(addresses)
    watcher.stats(0, 0, 0)
    interrupted = _wait_then(lambda: watcher.snapshot(0, 0))
    stats = watcher.stats(0, 0, 0)
    node = watcher.node(0, 0, "World")
    return {"interrupted": interrupted, "stats_keys": sorted(stats), "node_path": node["path"]}


def _wait_then(call: Any) -> str:
    """Print ``ready``, wait for the test's line, then make ``call``; how it ended."""
    print("ready", flush=True)
    sys.stdin.readline()
    print("waiting", flush=True)
    try:
        call()
    except KeyboardInterrupt:
        print("interrupted", flush=True)
        return "KeyboardInterrupt"
    print("not interrupted", flush=True)
    return "not interrupted"


PATHS = {"client": _client, "env": _env, "vector": _vector, "sb3": _sb3, "watcher": _watcher}

if __name__ == "__main__":
    print(json.dumps(PATHS[sys.argv[1]](sys.argv[2:])), flush=True)
