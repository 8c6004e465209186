"""rlenv's reach below pymunk's public API: taken on the tested versions only, and the public
fallback runs the same simulation bit for bit."""

from __future__ import annotations

import json
import subprocess
import sys

import pymunk

from rlenv.scene2d import _chipmunk as chipmunk

_EPISODES = """
import hashlib, json, logging, sys
logging.basicConfig(level=logging.WARNING, stream=sys.stderr)
import pymunk
if sys.argv[1] != "installed":
    pymunk.version = sys.argv[1]  # as if another pymunk were installed
from rlenv.scene2d import _chipmunk as chipmunk
from rlenv_client import LocalClient
digests = {}
for target in ("examples.plinko:PlinkoEnvironment", "examples.pair:PairEnvironment",
               "examples.cartpole:CartPoleEnvironment"):
    client = LocalClient(target)
    digest = hashlib.sha256()
    for seed in (3, 4):  # the second reset restarts the world that saw the first episode
        observation, _ = client.reset(seed=seed)
        client.action_space.seed(seed)
        for _ in range(150):
            observation, reward, terminated, truncated, _ = client.step(
                client.action_space.sample())
            digest.update(repr((observation, reward)).encode())
            if terminated or truncated:
                break
    digests[target] = digest.hexdigest()
    client.close()
print(json.dumps({"fast": chipmunk.FAST, "digests": digests}))
"""


def _episodes(version: str) -> tuple[dict, str]:
    run = subprocess.run(
        [sys.executable, "-c", _EPISODES, version],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    return json.loads(run.stdout), run.stderr


def test_the_installed_pymunk_is_a_tested_one() -> None:
    low, high = chipmunk.TESTED
    assert low <= chipmunk._version(pymunk.version) <= high and chipmunk.FAST


def test_another_pymunk_takes_the_public_api_and_simulates_the_same() -> None:
    fast, quiet = _episodes("installed")
    public, warned = _episodes("7.9.0")
    assert fast["fast"] and not public["fast"]
    assert public["digests"] == fast["digests"]  # bit for bit: the same simulation
    assert "warning" not in quiet.lower()
    assert "pymunk 7.9.0 is not a version rlenv was tested with (7.0.1 to 7.3.1)" in warned
