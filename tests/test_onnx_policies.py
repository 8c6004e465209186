"""Policies as ONNX: export_onnx checked against torch, and rlenv serve --policy over sockets."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from rlenv.protocol.errors import RemoteError
from rlenv.protocol.space_json import space_from_json
from rlenv_client import Client

pytestmark = pytest.mark.onnx
torch = pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")
onnxruntime = pytest.importorskip("onnxruntime")

from rlenv.serving.onnx_policy import OnnxPolicy  # noqa: E402
from rlenv_tools.policies import ExportMismatch, export_onnx  # noqa: E402
from tests.policy_spaces import (  # noqa: E402
    CARTPOLE,
    CARTPOLE_OBSERVATION,
    PAIR,
    STEERING,
)


def _mlp(inputs: int, outputs: int, seed: int = 0) -> torch.nn.Module:
    torch.manual_seed(seed)
    return torch.nn.Sequential(
        torch.nn.Linear(inputs, 16), torch.nn.Tanh(), torch.nn.Linear(16, outputs)
    )


def _agent_spaces(target: str) -> tuple[gym.spaces.Space, gym.spaces.Space]:
    from rlenv.serving._host import Host

    host = Host(target)
    agent = host.instances[0].agents[-1]
    spaces = agent.observation_space, agent.action_space
    host.close()
    return spaces


@pytest.fixture(scope="module")
def cartpole_policy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    observation_space, action_space = _agent_spaces(CARTPOLE)
    return export_onnx(
        _mlp(5, 1),
        tmp_path_factory.mktemp("onnx") / "cartpole.onnx",
        observation_space,
        action_space,
    )


@pytest.fixture(scope="module")
def pair_policy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    observation_space, action_space = _agent_spaces(PAIR)
    return export_onnx(
        _mlp(8, 2, seed=1),
        tmp_path_factory.mktemp("onnx") / "blue.onnx",
        observation_space,
        action_space,
    )


def _session(path: Path) -> onnxruntime.InferenceSession:
    return onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])


def _metadata(path: Path) -> dict[str, str]:
    return {prop.key: prop.value for prop in onnx.load(str(path)).metadata_props}


# --- export -----------------------------------------------------------------------------------

SB3_CASES = [
    ("PPO", "Pendulum-v1"),
    ("PPO", "CartPole-v1"),
    ("A2C", "Pendulum-v1"),
    ("DQN", "CartPole-v1"),
    ("SAC", "Pendulum-v1"),
]


@pytest.mark.parametrize(("algorithm", "env_id"), SB3_CASES)
def test_sb3_export_gives_predict_deterministic(
    algorithm: str, env_id: str, tmp_path: Path
) -> None:
    sb3 = pytest.importorskip("stable_baselines3")
    model = getattr(sb3, algorithm)("MlpPolicy", env_id, seed=0, device="cpu")
    torch.manual_seed(0)
    with torch.no_grad():  # weights far from a fresh model's: actions vary across observations
        for parameter in model.policy.parameters():
            parameter.normal_(0.0, 0.5)
    path = export_onnx(model, tmp_path / "policy.onnx")
    space = model.observation_space
    space.seed(123)  # other observations than the export's own check, in a batch of 257
    observations = np.stack([space.sample() for _ in range(257)]) * 3.0
    observations = np.clip(observations, space.low, space.high).astype(np.float32)
    got = _session(path).run(["action"], {"observation": observations})[0]
    expected, _ = model.predict(observations, deterministic=True)
    assert got.dtype == model.action_space.dtype
    if isinstance(model.action_space, gym.spaces.Discrete):
        assert got.shape == (257,) and np.array_equal(got, expected)
        assert len(np.unique(got)) == 2  # both actions occur: an argmax, not a constant
    else:
        assert got.shape == (257, 1)
        np.testing.assert_allclose(got, expected, atol=1e-5)
        assert got.min() >= -2.0 and got.max() <= 2.0
    assert space_from_json(_metadata(path)["rlenv.action_space"]) == model.action_space


def test_sac_squashing_reaches_the_bounds(tmp_path: Path) -> None:
    sb3 = pytest.importorskip("stable_baselines3")
    model = sb3.SAC("MlpPolicy", "Pendulum-v1", seed=0, device="cpu")
    with torch.no_grad():  # a huge mean: tanh saturates, unscaled onto [-2, 2]
        model.policy.actor.mu.weight.mul_(1e4)
    path = export_onnx(model, tmp_path / "sac.onnx")
    observations = np.array([[1.0, 0.0, 8.0], [1.0, 0.0, -8.0]], np.float32)
    got = _session(path).run(["action"], {"observation": observations})[0]
    np.testing.assert_allclose(np.abs(got), 2.0, atol=1e-5)
    np.testing.assert_allclose(got, model.predict(observations, deterministic=True)[0], atol=1e-5)


def test_cleanrl_style_discrete_actor_exports_argmax(tmp_path: Path) -> None:
    observation_space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
    action_space = gym.spaces.Discrete(5, start=2)
    actor = _mlp(4, 5)
    path = export_onnx(actor, tmp_path / "actor.onnx", observation_space, action_space)
    observations = np.random.default_rng(7).uniform(-1, 1, (300, 4)).astype(np.float32)
    got = _session(path).run(["action"], {"observation": observations})[0]
    with torch.no_grad():
        logits = actor(torch.as_tensor(observations)).numpy()
    assert got.dtype == np.int64
    assert np.array_equal(got, np.argmax(logits, axis=1) + 2)
    assert set(np.unique(got)) <= set(range(2, 7)) and len(np.unique(got)) > 1


def test_cleanrl_style_box_actor_is_clipped(tmp_path: Path) -> None:
    actor = _mlp(5, 1)
    with torch.no_grad():
        actor[2].weight.mul_(100.0)
    path = export_onnx(actor, tmp_path / "actor.onnx", CARTPOLE_OBSERVATION, STEERING)
    observations = np.random.default_rng(3).uniform(-4, 4, (200, 5)).astype(np.float32)
    got = _session(path).run(["action"], {"observation": observations})[0]
    with torch.no_grad():
        raw = actor(torch.as_tensor(observations)).numpy()
    assert np.abs(raw).max() > 1.0  # clipping matters here
    np.testing.assert_allclose(got, np.clip(raw, -1.0, 1.0), atol=1e-5)


def test_metadata_spaces_round_trip_with_bounds_and_dtype(tmp_path: Path) -> None:
    observation_space = gym.spaces.Box(
        np.array([-np.inf, 0.0, -3.5]), np.array([np.inf, 1.0, 2.25]), dtype=np.float64
    )
    action_space = gym.spaces.Box(
        np.array([-1.0, -0.5], np.float32), np.array([1.0, 0.25], np.float32)
    )
    path = export_onnx(_mlp(3, 2).double(), tmp_path / "a.onnx", observation_space, action_space)
    metadata = _metadata(path)
    policy = OnnxPolicy(path)
    for key, space, loaded in (
        ("rlenv.observation_space", observation_space, policy.observation_space),
        ("rlenv.action_space", action_space, policy.action_space),
    ):
        for read in (space_from_json(metadata[key]), loaded):
            assert read == space and read.dtype == space.dtype
            assert np.array_equal(read.low, space.low) and np.array_equal(read.high, space.high)
    assert policy.act(np.zeros(3)).shape == (2,)


class _TwoFaced(torch.nn.Module):
    """Its ONNX graph adds 0.25 to what it computes in torch."""

    def __init__(self) -> None:
        super().__init__()
        self.net = _mlp(5, 1)

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        action = torch.tanh(self.net(observation)) * 0.5
        return action + 0.25 if torch.onnx.is_in_onnx_export() else action


def test_a_graph_unlike_its_module_is_refused_naming_the_largest_difference(tmp_path: Path) -> None:
    path = tmp_path / "wrong.onnx"
    with pytest.raises(ExportMismatch, match=r"largest difference is 0\.25\b") as caught:
        export_onnx(_TwoFaced(), path, CARTPOLE_OBSERVATION, STEERING)
    assert "on 64 of 64 observations" in str(caught.value) and "\n" not in str(caught.value)
    assert not path.exists()


def test_a_file_that_is_not_onnx_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "model.onnx"
    path.write_bytes(b"this is not a model\n")
    with pytest.raises(ValueError, match=r"model\.onnx is not an ONNX model"):
        OnnxPolicy(path)


# --- rlenv serve --policy ---------------------------------------------------------------------


def _wait_for_episodes(client: Client, count: int, timeout: float = 60.0) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        stats = client.stats()
        if stats["next"] >= count:
            return stats
        assert time.monotonic() < deadline, f"only {stats['next']} episodes in {timeout} s"


def test_a_policy_plays_episodes_an_observer_counts(serve, cartpole_policy: Path) -> None:
    server = serve(CARTPOLE, args=["--policy", f"Agent={cartpole_policy}"])
    with Client(server.host, server.port, timeout=10) as observer:
        stats = _wait_for_episodes(observer, 5)
        episodes = stats["episodes"]
        assert [e["episode"] for e in episodes[:5]] == list(range(5))
        assert all(e["end"] in ("terminated", "truncated") and e["length"] > 0 for e in episodes)
        assert stats["steps"] >= sum(e["length"] for e in episodes)
        later = _wait_for_episodes(observer, stats["next"] + 1)
        assert later["steps"] > stats["steps"]  # it goes on with nobody but an observer
        with pytest.raises(RemoteError, match="driven by policies"):
            observer.reset(seed=1)
        assert observer.stats()["errors"] == 0


def test_max_episode_steps_truncates(serve, cartpole_policy: Path) -> None:
    server = serve(
        CARTPOLE, args=["--policy", f"Agent={cartpole_policy}", "--max-episode-steps", "3"]
    )
    with Client(server.host, server.port, timeout=10) as observer:
        episodes = _wait_for_episodes(observer, 6)["episodes"]
    assert all(e["length"] <= 3 for e in episodes)
    assert any(e["end"] == "truncated" and e["length"] == 3 for e in episodes)


def test_episodes_are_seeded_by_their_number(serve, cartpole_policy: Path) -> None:
    first = serve(CARTPOLE, args=["--policy", f"Agent={cartpole_policy}"])
    second = serve(CARTPOLE, args=["--policy", f"Agent={cartpole_policy}"])
    runs = []
    for server in (first, second):
        with Client(server.host, server.port, timeout=10) as observer:
            runs.append(
                [
                    (e["length"], e["return"])
                    for e in _wait_for_episodes(observer, 4)["episodes"][:4]
                ]
            )
    assert runs[0] == runs[1]


def _serve_refused(*args: str) -> str:
    result = subprocess.run(
        [sys.executable, "-m", "rlenv", "serve", *args],
        timeout=120,
        capture_output=True,
        text=True,
        stdin=subprocess.DEVNULL,
    )
    assert result.returncode == 2, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    return lines[0]


def test_mismatched_spaces_are_refused_at_start_naming_both(pair_policy: Path) -> None:
    line = _serve_refused(CARTPOLE, "--policy", f"Agent={pair_policy}")
    assert line.startswith(
        f"rlenv serve: --policy Agent={pair_policy}: the file's observation space is Box("
    )
    assert "(8,), float32" in line and "agent 'Agent''s is Box(" in line and "(5,)" in line


def test_a_bound_differing_is_a_mismatch(tmp_path: Path) -> None:
    other = gym.spaces.Box(-1.0, 0.5, (1,), np.float32)  # the cart's action space is [-1, 1]
    path = export_onnx(_mlp(5, 1), tmp_path / "p.onnx", _agent_spaces(CARTPOLE)[0], other)
    line = _serve_refused(CARTPOLE, "--policy", f"Agent={path}")
    assert "the file's action space is Box(-1.0, 0.5, (1,), float32)" in line
    assert "agent 'Agent''s is Box(-1.0, 1.0, (1,), float32)" in line


def test_a_non_onnx_file_is_refused_at_start(tmp_path: Path) -> None:
    path = tmp_path / "weights.pt"
    path.write_bytes(b"\x80\x04not onnx")
    line = _serve_refused(CARTPOLE, "--policy", f"Agent={path}")
    assert line.startswith(f"rlenv serve: {path} is not an ONNX model")


def test_an_unknown_agent_is_refused_at_start(cartpole_policy: Path) -> None:
    line = _serve_refused(PAIR, "--policy", f"Green={cartpole_policy}")
    assert "the environment has no agent 'Green'; its agents: Red, Blue" in line


def test_a_learner_plays_against_a_policy_opponent(serve, pair_policy: Path) -> None:
    """The learner sends Red's actions; Blue's are its policy's, exactly as if sent."""
    policy = OnnxPolicy(pair_policy)
    rng = np.random.default_rng(0)
    reds = [rng.uniform(-1, 1, 2).astype(np.float32) for _ in range(40)]
    driven = serve(PAIR, args=["--policy", f"Blue={pair_policy}"])
    plain = serve(PAIR)
    with (
        Client(driven.host, driven.port, timeout=10) as learner,
        Client(plain.host, plain.port, timeout=10) as both,
    ):
        observation, _ = learner.reset(seed=5)
        mirrored, _ = both.reset(seed=5)
        moved = 0.0
        for red in reds:
            blue = policy.act(mirrored["Blue"])
            observation, *_ = learner.step({"Red": red})
            mirrored, *_ = both.step({"Red": red, "Blue": blue})
            for name in ("Red", "Blue"):
                np.testing.assert_array_equal(observation[name], mirrored[name])
            moved += float(np.abs(blue).sum())
        assert moved > 0.0
        # an action sent for Blue is ignored: the policy's stands
        blue = policy.act(mirrored["Blue"])
        observation, *_ = learner.step({"Red": reds[0], "Blue": -blue})
        mirrored, *_ = both.step({"Red": reds[0], "Blue": blue})
        np.testing.assert_array_equal(observation["Blue"], mirrored["Blue"])


def test_a_timeline_branches_with_a_policy_file(tmp_path: Path, cartpole_policy: Path) -> None:
    from rlenv_tools.timeline import Timeline
    from tests.test_timeline import record

    path = record(tmp_path, CARTPOLE)
    policy = OnnxPolicy(cartpole_policy)
    with Timeline.open(path) as timeline:
        branch = timeline.branch(3, policy=cartpole_policy, max_steps=6)
        by_hand = timeline.branch(3, policy=policy.act, max_steps=6)
        assert 3 < len(branch) <= 9 and timeline.diff(branch).first_difference is not None
        assert branch.diff(by_hand).first_difference is None
        chosen = [event[1] for event in branch.episode.snapshot["events"] if event[0] == "action"]
        for step in range(3, len(branch)):
            assert np.array_equal(chosen[step], policy.act(branch.at(step).observation))
        with pytest.raises(ValueError, match="not an ONNX model"):
            timeline.branch(3, policy=path, max_steps=2)  # a recording, not a policy


def test_an_onnx_file_in_others_drives_that_agent_in_the_server(pair_policy: Path) -> None:
    """``others={"Blue": FILE}`` runs the file beside the physics; the same file called in the
    trainer gives Red the same episode, bit for bit."""
    from rlenv.serving.onnx_policy import OnnxPolicy
    from rlenv_client.agent_vector import AgentVectorEnv

    served = AgentVectorEnv(
        1, PAIR, agents="Red", others={"Blue": pair_policy}, max_episode_steps=40
    )
    called = AgentVectorEnv(
        1, PAIR, agents="Red", others={"Blue": OnnxPolicy(pair_policy).act}, max_episode_steps=40
    )
    try:
        assert served.driven_by_server == {"Blue": str(pair_policy)}
        assert served.vector.clients[0].hello.driven == ("Blue",)
        first, second = served.reset(seed=4)[0], called.reset(seed=4)[0]
        for _ in range(40):
            assert np.array_equal(first, second)
            actions = np.full((1, 2), 0.25, np.float32)
            first, *ours, _ = served.step(actions)
            second, *theirs, _ = called.step(actions)
            for mine, other in zip(ours, theirs, strict=True):
                assert np.array_equal(mine, other)
        assert ours[2][0]  # the time limit ended the episode
    finally:
        served.close()
        called.close()
