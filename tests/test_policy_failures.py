"""Policy files that misbehave: outputs outside the space, huge tensors, NaN, endless graphs.

The graphs are built with the ``onnx`` package directly (no torch). Each misbehaviour must cost
its episode, never the server: the server keeps answering observers and signals, logs each
failure once, and holds its memory.
"""

from __future__ import annotations

import signal
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from rlenv.protocol.errors import RemoteError
from rlenv.protocol.space_json import space_to_json_text
from rlenv_client import Client
from tests.conftest import Serve, wait_until

pytestmark = pytest.mark.onnx
onnx = pytest.importorskip("onnx")
onnxruntime = pytest.importorskip("onnxruntime")

from onnx import TensorProto, helper, numpy_helper  # noqa: E402

from rlenv.serving.onnx_policy import (  # noqa: E402
    ACTION_SPACE_KEY,
    OBSERVATION_SPACE_KEY,
    POLICY_DEADLINE,
    OnnxPolicy,
    PolicyError,
    fit_action,
)
from tests.policy_spaces import (  # noqa: E402
    CARTPOLE,
    CARTPOLE_OBSERVATION,
    PAIR,
    PAIR_OBSERVATION,
    PUSHING,
    STEERING,
)


def _write(
    path: Path,
    nodes: list,
    observation_space: gym.spaces.Box,
    action_space: gym.spaces.Space,
    initializers: tuple = (),
) -> Path:
    """A policy file of these nodes: input ``observation``, output ``action`` (any shape)."""
    graph = helper.make_graph(
        nodes,
        "policy",
        [
            helper.make_tensor_value_info(
                "observation", TensorProto.FLOAT, [None, observation_space.shape[0]]
            )
        ],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, None)],
        initializer=list(initializers),
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    helper.set_model_props(
        model,
        {
            OBSERVATION_SPACE_KEY: space_to_json_text(observation_space),
            ACTION_SPACE_KEY: space_to_json_text(action_space),
        },
    )
    path.write_bytes(model.SerializeToString())
    return path


def _constant(
    path: Path,
    values: list[float],
    observation_space: gym.spaces.Box,
    action_space: gym.spaces.Space,
) -> Path:
    """A policy that answers ``values`` whatever it sees (its batch of one)."""
    value = numpy_helper.from_array(np.array([values], np.float32), "value")
    return _write(
        path,
        [helper.make_node("Constant", [], ["action"], value=value)],
        observation_space,
        action_space,
    )


def _huge(path: Path, observation_space: gym.spaces.Box, action_space: gym.spaces.Space) -> Path:
    """A policy whose output is a 2^14 x (2^12 x width) float tensor: over a GiB.

    Its shape comes from the observation's, so that nothing is folded when the file loads.
    """
    scale = numpy_helper.from_array(np.array([1 << 14, 1 << 12], np.int64), "scale")
    one = numpy_helper.from_array(np.array([1.0], np.float32))
    return _write(
        path,
        [
            helper.make_node("Shape", ["observation"], ["shape"]),
            helper.make_node("Mul", ["shape", "scale"], ["big"]),
            helper.make_node("ConstantOfShape", ["big"], ["action"], value=one),
        ],
        observation_space,
        action_space,
        (scale,),
    )


def _endless(path: Path, observation_space: gym.spaces.Box, action_space: gym.spaces.Space) -> Path:
    """A policy that loops 2^62 times (adding one to its observation each time)."""
    body = helper.make_graph(
        [
            helper.make_node("Identity", ["going"], ["going_on"]),
            helper.make_node("Add", ["x", "one"], ["x_next"]),
        ],
        "body",
        [
            helper.make_tensor_value_info("i", TensorProto.INT64, []),
            helper.make_tensor_value_info("going", TensorProto.BOOL, []),
            helper.make_tensor_value_info("x", TensorProto.FLOAT, None),
        ],
        [
            helper.make_tensor_value_info("going_on", TensorProto.BOOL, []),
            helper.make_tensor_value_info("x_next", TensorProto.FLOAT, None),
        ],
        initializer=[numpy_helper.from_array(np.float32(1.0), "one")],
    )
    return _write(
        path,
        [helper.make_node("Loop", ["trips", "always", "observation"], ["action"], body=body)],
        observation_space,
        action_space,
        (
            numpy_helper.from_array(np.int64(1 << 62), "trips"),
            numpy_helper.from_array(np.bool_(True), "always"),
        ),
    )


def _peak_rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise AssertionError("no VmHWM")


def _failed_episodes(observer: Client, count: int) -> dict:
    """Stats once ``count`` episodes failed (polled; observers are answered meanwhile)."""
    latest: dict = {}

    def failed() -> bool:
        nonlocal latest
        latest = observer.stats()
        return sum(e["end"] == "error" for e in latest["episodes"]) >= count

    wait_until(failed, f"fewer than {count} failed episodes", seconds=60)
    return latest


# --- the output, checked against the space ----------------------------------------------------


def test_box_actions_are_clipped_and_nan_or_a_wrong_shape_refused(tmp_path: Path) -> None:
    forceful = OnnxPolicy(
        _constant(tmp_path / "forceful.onnx", [1e30, -np.inf], PAIR_OBSERVATION, PUSHING)
    )
    assert forceful.act(np.zeros(8, np.float32)).tolist() == [1.0, -1.0]
    three = OnnxPolicy(
        _constant(tmp_path / "three.onnx", [0.1, 0.2, 0.3], PAIR_OBSERVATION, PUSHING)
    )
    with pytest.raises(PolicyError, match=r"three.onnx gave \[0.1 +0.2 +0.3\].*Box"):
        three.act(np.zeros(8, np.float32))
    nan = OnnxPolicy(_constant(tmp_path / "nan.onnx", [np.nan], CARTPOLE_OBSERVATION, STEERING))
    with pytest.raises(PolicyError, match="nan.onnx gave NaN"):
        nan.act(np.zeros(5, np.float32))


def test_other_spaces_take_members_only() -> None:
    assert fit_action(gym.spaces.Discrete(3), np.array([2.0], np.float32)) == 2
    assert fit_action(gym.spaces.Discrete(3, start=-1), np.int64(-1)) == -1
    for wrong in (np.array([2.5]), np.array([3]), np.array([0, 1]), np.array([np.nan])):
        with pytest.raises(PolicyError, match="its action space is Discrete"):
            fit_action(gym.spaces.Discrete(3), wrong)
    multi = gym.spaces.MultiDiscrete([2, 3])
    assert fit_action(multi, np.array([1, 2])).tolist() == [1, 2]
    with pytest.raises(PolicyError, match="not an action of MultiDiscrete"):
        fit_action(multi, np.array([1, 3]))


def test_a_forceful_policy_plays_clipped_episodes(serve: Serve, tmp_path: Path) -> None:
    policy = _constant(tmp_path / "forceful.onnx", [1e30], CARTPOLE_OBSERVATION, STEERING)
    server = serve(CARTPOLE, args=["--policy", f"Agent={policy}", "--max-episode-steps", "50"])
    with Client(server.host, server.port, timeout=30) as observer:
        wait_until(lambda: observer.stats()["next"] >= 3, "no episodes played")
        episodes = observer.stats()["episodes"]
        assert all(e["end"] in ("terminated", "truncated") for e in episodes), episodes


# --- failures cost the episode, not the server ------------------------------------------------


def test_a_nan_policy_fails_its_episodes_and_is_logged_once(serve: Serve, tmp_path: Path) -> None:
    policy = _constant(tmp_path / "nan.onnx", [np.nan], CARTPOLE_OBSERVATION, STEERING)
    server = serve(CARTPOLE, args=["--policy", f"Agent={policy}"])
    with Client(server.host, server.port, timeout=30) as observer:
        stats = _failed_episodes(observer, 3)
        assert stats["steps"] == 0  # nothing it gave was applied
    assert server.output.count("gave NaN") == 1, server.output
    assert len(server.output.splitlines()) < 20, server.output  # a pause between episodes


def test_every_pair_agent_with_a_wrong_or_huge_output_fails_episodes_in_bounded_memory(
    serve: Serve, tmp_path: Path
) -> None:
    huge = _huge(tmp_path / "huge.onnx", PAIR_OBSERVATION, PUSHING)
    three = _constant(tmp_path / "three.onnx", [0.1, 0.2, 0.3], PAIR_OBSERVATION, PUSHING)
    for policies in ([f"Red={huge}", f"Blue={huge}"], [f"Red={three}", f"Blue={huge}"]):
        server = serve(PAIR, args=[arg for policy in policies for arg in ("--policy", policy)])
        with Client(server.host, server.port, timeout=30) as observer:
            _failed_episodes(observer, 2)
            assert server.is_alive()
        assert _peak_rss_mib(server.pid) < 700  # the graph asked for 1,280 MiB
        server.close()
        assert server.output.count("its episodes fail") == 1, server.output  # Red's, once


def test_a_learner_beside_a_failing_policy_gets_an_environment_error(
    serve: Serve, tmp_path: Path
) -> None:
    three = _constant(tmp_path / "three.onnx", [0.1, 0.2, 0.3], PAIR_OBSERVATION, PUSHING)
    server = serve(PAIR, args=["--policy", f"Blue={three}"])
    with Client(server.host, server.port, timeout=30) as learner:
        for _ in range(2):
            learner.reset(seed=0)
            with pytest.raises(RemoteError, match="environment_error.*Blue.*three.onnx gave"):
                learner.step({"Red": np.zeros(2, np.float32)})
            with pytest.raises(RemoteError, match="reset_required.*the episode failed"):
                learner.step({"Red": np.zeros(2, np.float32)})
    assert server.output.count("three.onnx gave") == 1, server.output


def test_an_endless_policy_leaves_observers_and_sigterm_answered(
    serve: Serve, tmp_path: Path
) -> None:
    policy = _endless(tmp_path / "endless.onnx", CARTPOLE_OBSERVATION, STEERING)
    server = serve(CARTPOLE, args=["--policy", f"Agent={policy}"])
    with Client(server.host, server.port, timeout=30) as observer:
        stats = _failed_episodes(observer, 2)
        assert stats["steps"] == 0
        for _ in range(3):  # each answered while the policy runs, within a deadline or so
            started = time.monotonic()
            observer.stats()
            assert time.monotonic() - started < 10 * POLICY_DEADLINE + 20
    assert "ran past its deadline" in server.output, server.output
    server.process.send_signal(signal.SIGTERM)
    wait_until(lambda: not server.is_alive(), "SIGTERM did not end a driven server", seconds=30)
