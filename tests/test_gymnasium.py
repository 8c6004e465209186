"""rlenv environments used as gymnasium users use environments: make, check_env, vector, render."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from conftest import Serve, alive
from gymnasium.utils.env_checker import check_env, check_space_limit
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import rlenv_client
from examples.cartpole import TARGET, CartPoleAgent, controller
from examples.pair import TARGET as PAIR_TARGET
from rlenv_client import ProtocolVersionError, RemoteEnv, RemoteVectorEnv
from rlenv_client.registration import ENVIRONMENTS

CARTPOLE = "rlenv/CartPole-v0"


NATIVE_TWINS = {"rlenv/CartPole-v1": "CartPole-v1"}
"""Ids whose spaces are a gymnasium env's own: check_env may warn about their limits as it
does about that env's (CartPole-v1's velocities are unbounded)."""


def _warnings(check: Callable[[], None]) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check()
    return [str(warning.message) for warning in caught]


@pytest.mark.parametrize("env_id", sorted(ENVIRONMENTS))
def test_check_env_passes_on_every_registered_id(env_id: str) -> None:
    expected: list[str] = []
    if env_id in NATIVE_TWINS:
        native = gym.make(NATIVE_TWINS[env_id])
        expected = _warnings(lambda: check_space_limit(native.observation_space, "observation"))
        assert expected  # the twin's own limits do warn
        native.close()
    env = gym.make(env_id)
    try:
        assert _warnings(lambda: check_env(env.unwrapped)) == expected  # no other warning
    finally:
        env.close()


def test_ids_carry_a_time_limit_and_the_repeat_action() -> None:
    env = gym.make(CARTPOLE, repeat_action=3)
    try:
        assert env.spec is not None and env.spec.max_episode_steps == 500
        assert isinstance(env, gym.wrappers.TimeLimit)
        env.reset(seed=0)
        _, reward, terminated, truncated, info = env.step(np.zeros(1, np.float32))
        assert info["frames"] == 3  # one-argument step uses the constructor's repeat_action
        assert type(reward) is float and type(terminated) is bool and type(truncated) is bool
        assert env.unwrapped.metadata["render_fps"] == 20  # 60 ticks/s over 3 ticks per step
    finally:
        env.close()


def test_register_envs_accepts_the_package() -> None:
    gym.register_envs(rlenv_client)
    assert CARTPOLE in gym.registry


def test_spaces_come_from_the_server() -> None:
    with RemoteEnv(TARGET) as env:
        assert env.action_space == CartPoleAgent.action_space
        assert env.observation_space == CartPoleAgent.observation_space


def test_seeded_resets_reproduce_episodes_across_servers() -> None:
    runs = []
    for _ in range(2):
        with RemoteEnv(TARGET) as env:
            env.action_space.seed(5)
            observation, _ = env.reset(seed=5)
            seen = [observation.tobytes()]
            for _ in range(20):
                observation, _, terminated, *_ = env.step(env.action_space.sample())
                seen.append(observation.tobytes())
                if terminated:
                    break
            seen.append(env.reset()[0].tobytes())  # the seed's stream goes on
            runs.append(seen)
    assert runs[0] == runs[1]


def test_attach_to_a_running_server_by_address(serve: Serve) -> None:
    server = serve()
    env = gym.make(CARTPOLE, address=server.address)
    try:
        observation, _ = env.reset(seed=1)
        assert observation in env.observation_space
    finally:
        env.close()
    assert server.is_alive()  # attaching never owns the server


def test_in_process_mode_is_the_same_environment() -> None:
    actions = [np.array([np.sin(t / 3.0)], np.float32) for t in range(40)]
    trajectories = []
    for in_process in (True, False):
        with RemoteEnv(TARGET, in_process=in_process) as env:
            observation, _ = env.reset(seed=11)
            trajectory = [observation.tobytes()]
            for action in actions:
                observation, reward, terminated, _, info = env.step(action)
                trajectory.append((observation.tobytes(), reward, terminated, info["frames"]))
                if terminated:
                    break
            trajectories.append(trajectory)
    assert trajectories[0] == trajectories[1]


def test_in_process_errors_are_the_servers_errors() -> None:
    with RemoteEnv(TARGET, in_process=True) as env:
        env.reset(seed=0)
        with pytest.raises(rlenv_client.RemoteError, match=r"shape \(2,\), expected \(1,\)"):
            env.step(np.zeros(2, np.float32))
        assert env.step(np.zeros(1, np.float32))[4]["frames"] == 4


def test_vector_env_matches_gymnasium_sync_vector_env() -> None:
    """Same seeds and actions: RemoteVectorEnv and SyncVectorEnv over in-process copies agree
    bit for bit, resets included, in both autoreset modes."""
    for mode in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
        remote = RemoteVectorEnv(3, TARGET, max_episode_steps=12, autoreset_mode=mode)
        reference = SyncVectorEnv(
            [lambda: gym.wrappers.TimeLimit(RemoteEnv(TARGET, in_process=True), 12)] * 3,
            autoreset_mode=mode,
        )
        try:
            remote.action_space.seed(3)
            got, _ = remote.reset(seed=21)
            expected, _ = reference.reset(seed=21)
            assert got.tobytes() == expected.tobytes()
            ended = 0
            for _ in range(60):
                actions = remote.action_space.sample()
                got = remote.step(actions)
                expected = reference.step(actions)
                for part in range(4):
                    assert np.array_equal(got[part], expected[part]), (mode, part)
                if mode is AutoresetMode.SAME_STEP and "final_obs" in expected[4]:
                    mask = expected[4]["_final_obs"]
                    assert np.array_equal(got[4]["_final_obs"], mask)
                    for index in np.flatnonzero(mask):
                        assert np.array_equal(
                            got[4]["final_obs"][index], expected[4]["final_obs"][index]
                        )
                ended += int((got[2] | got[3]).sum())
            assert ended > 3  # resets really happened
        finally:
            remote.close()
            reference.close()


def test_make_vec_builds_a_remote_vector_env_that_runs_long() -> None:
    noise_scale = np.array([[0.0], [0.3], [0.6], [0.9]])  # per copy: balanced to the limit or not
    envs = gym.make_vec(CARTPOLE, num_envs=4, repeat_action=1)
    try:
        assert isinstance(envs.unwrapped, RemoteVectorEnv)
        assert envs.unwrapped.max_episode_steps == 500
        assert envs.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
        observations, _ = envs.reset(seed=0)
        lengths = np.zeros(4, int)  # steps into each copy's episode
        ended = np.zeros(4, bool)
        endings = {"terminated": 0, "truncated": 0}
        for _ in range(2500):  # 10k environment steps
            actions = np.stack([controller(o) for o in observations])
            noise = envs.unwrapped.np_random.uniform(-1, 1, actions.shape) * noise_scale
            observations, rewards, terminated, truncated, _ = envs.step(
                np.clip(actions + noise.astype(np.float32), -1, 1)
            )
            assert observations.shape == (4, 5) and rewards.dtype == np.float64
            # a copy that ended last step was reset instead: its starting state, no reward
            assert not (terminated | truncated)[ended].any()
            assert (rewards[ended] == 0.0).all()
            assert (np.abs(observations[ended][:, [0, 2, 3, 4]]) <= 0.05).all()
            lengths = np.where(ended, 0, lengths + 1)
            running = ~ended
            assert (rewards[running & ~terminated] == 1.0).all()  # +1 per tick while up
            assert (lengths[truncated] == 500).all()  # cut by the time limit exactly there
            assert (lengths[terminated] < 500).all()
            endings["terminated"] += int(terminated.sum())
            endings["truncated"] += int(truncated.sum())
            ended = terminated | truncated
        assert endings["terminated"] > 0 and endings["truncated"] > 0, endings
    finally:
        envs.close()


def test_vector_reset_seeds_each_copy_differently() -> None:
    with RemoteVectorEnv(2, TARGET, in_process=True) as envs:
        observations, _ = envs.reset(seed=7)
        assert observations[0].tobytes() != observations[1].tobytes()
        again, _ = envs.reset(seed=[7, 8])
        assert again.tobytes() == observations.tobytes()


def test_rgb_array_frames_show_the_state() -> None:
    env = gym.make(CARTPOLE, render_mode="rgb_array")
    try:
        env.reset(seed=0)
        first = env.render()
        assert first.shape == (400, 600, 3) and first.dtype == np.uint8
        assert (first != 255).any(axis=2).sum() > 1000  # cart, pole and track are drawn
        assert first.tobytes() == env.render().tobytes()  # same state, same pixels
        env.step(np.ones(1, np.float32))
        env.step(np.ones(1, np.float32))
        assert env.render().tobytes() != first.tobytes()
    finally:
        env.close()
    with RemoteEnv(TARGET, render_mode="rgb_array", render_size=(84, 84)) as small:
        small.reset(seed=0)
        assert small.render().shape == (84, 84, 3)


def test_human_mode_without_a_display_fails_clearly(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(RuntimeError, match="needs a display"):
        RemoteEnv(TARGET, render_mode="human")
    env = RemoteEnv(TARGET, in_process=True)
    assert "human" not in env.metadata["render_modes"]
    env.close()


def test_human_mode_shows_a_window_on_a_virtual_display(tmp_path: Path) -> None:
    xvfb = _which("Xvfb")
    if xvfb is None:
        pytest.skip("Xvfb is not installed (apt-get install xvfb)")
    display = f":{90 + os.getpid() % 100}"
    screen = subprocess.Popen(
        [xvfb, display, "-screen", "0", "800x600x24"], stderr=subprocess.DEVNULL
    )
    try:
        code = (
            "from rlenv_client import RemoteEnv; import numpy as np\n"
            "env = RemoteEnv('examples.cartpole:CartPoleEnvironment', render_mode='human',"
            " in_process=True)\n"
            "env.reset(seed=0)\n"
            "for _ in range(5): env.step(np.zeros(1, np.float32))\n"
            "print(env._display._root.winfo_exists(), env._display._image.width())\n"
            "env.close()\n"
        )
        result = _run_with_display(code, display, deadline=30)
        assert result.stdout.split() == ["1", "600"], result.stderr
    finally:
        screen.terminate()
        screen.wait()


def test_record_video_writes_a_video_that_decodes(tmp_path: Path) -> None:
    pytest.importorskip("moviepy")
    imageio = pytest.importorskip("imageio.v2")
    env = gym.wrappers.RecordVideo(
        gym.make(CARTPOLE, render_mode="rgb_array"),
        str(tmp_path / "videos"),
        episode_trigger=lambda e: True,
        disable_logger=True,
    )
    try:
        observation, _ = env.reset(seed=0)
        for _ in range(30):
            observation, _, terminated, truncated, _ = env.step(controller(observation))
            if terminated or truncated:
                break
    finally:
        env.close()
    videos = sorted((tmp_path / "videos").glob("*.mp4"))
    assert len(videos) == 1
    with imageio.get_reader(videos[0]) as reader:
        frames = [frame for frame in reader]
    assert len(frames) in (30, 31)  # 31 recorded (reset + 30 steps); ffmpeg may drop the last
    assert frames[0].shape == (400, 600, 3)
    assert (frames[-1] < 200).any()  # not blank: the cart is drawn


def test_no_server_outlives_close_or_a_killed_client() -> None:
    with RemoteEnv(TARGET) as env:
        server = env.server
    assert server is not None and not server.is_alive()
    code = (
        "from rlenv_client import RemoteVectorEnv; import time\n"
        "envs = RemoteVectorEnv(2, 'examples.cartpole:CartPoleEnvironment')\n"
        "print(' '.join(str(s.pid) for s in envs.servers), flush=True)\n"
        "time.sleep(60)\n"
    )
    client = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert client.stdout is not None
    pids = [int(pid) for pid in client.stdout.readline().split()]
    assert len(pids) == 2
    client.kill()
    client.wait()
    deadline = time.monotonic() + 20
    while any(alive(pid) for pid in pids):
        assert time.monotonic() < deadline, "a server outlived its killed client"
        time.sleep(0.05)  # polling a condition with a deadline, not waiting for time to pass


def test_a_server_that_dies_mid_episode_is_a_typed_error() -> None:
    env = RemoteEnv(TARGET, max_restarts=0)
    try:
        env.reset(seed=0)
        assert env.server is not None
        os.killpg(env.server.pid, signal.SIGKILL)
        with pytest.raises(rlenv_client.ConnectionLost) as error:
            env.step(np.zeros(1, np.float32))
        assert f"exited with code {-signal.SIGKILL}" in str(error.value)
        assert "listening on" in str(error.value)  # and what it said
    finally:
        env.close()


def _which(program: str) -> str | None:
    from shutil import which

    return which(program)


def _run_with_display(code: str, display: str, deadline: float) -> subprocess.CompletedProcess:
    """Run ``code`` once the X server answers (polled with a deadline)."""
    end = time.monotonic() + deadline
    while True:
        result = subprocess.run(
            [sys.executable, "-c", code],
            capture_output=True,
            text=True,
            env={**os.environ, "DISPLAY": display},
            timeout=deadline,
        )
        if (
            result.returncode == 0
            or "couldn't connect to display" not in result.stderr
            or time.monotonic() > end
        ):
            return result


def test_a_vector_env_names_the_server_that_died() -> None:
    with RemoteVectorEnv(2, TARGET, max_restarts=0) as envs:
        envs.reset(seed=0)
        victim = envs.servers[1]
        os.killpg(victim.pid, signal.SIGKILL)
        with pytest.raises(rlenv_client.ConnectionLost) as error:
            envs.step(np.zeros((2, 1), np.float32))
        assert f"(pid {victim.pid}) exited" in str(error.value)
        with pytest.raises(rlenv_client.ConnectionLost) as error:  # a reset, too
            envs.reset(seed=1)
        assert f"(pid {victim.pid}) exited" in str(error.value)
        assert f"pid {envs.servers[0].pid}" not in str(error.value)


def test_a_lost_server_is_restarted_and_the_episode_truncated() -> None:
    with RemoteEnv(TARGET, max_restarts=1, timeout=30.0) as env:
        observation, _ = env.reset(seed=0)
        observation, *_ = env.step(np.zeros(1, np.float32))
        first = env.server
        assert first is not None
        os.killpg(first.pid, signal.SIGKILL)
        after, reward, terminated, truncated, info = env.step(np.zeros(1, np.float32))
        assert after.tobytes() == observation.tobytes()  # the last real state, nothing invented
        assert (reward, terminated, truncated) == (0.0, False, True)
        assert "restarted (1 of 1)" in info["server_restarted"]
        assert env.server is not first and env.server.is_alive()
        assert not first.is_alive()
        again, _ = env.reset(seed=0)  # the new server gives the same episode
        assert again.tobytes() == env.reset(seed=0)[0].tobytes()
        os.killpg(env.server.pid, signal.SIGSTOP)  # silent: the timeout, then the budget is out
        with pytest.raises(rlenv_client.ConnectionLost, match="did not answer"):
            env.step(np.zeros(1, np.float32))


@pytest.mark.parametrize("per_server", [1, 2])
def test_a_vector_env_restarts_the_lost_server_only(per_server: int) -> None:
    count = 2 * per_server
    lost = [False] * per_server + [True] * per_server
    with RemoteVectorEnv(count, TARGET, max_restarts=1, instances_per_server=per_server) as envs:
        first, _ = envs.reset(seed=0)
        survivor, victim = envs.servers
        os.killpg(victim.pid, signal.SIGKILL)
        still = np.zeros((count, 1), np.float32)
        observations, rewards, terminated, truncated, infos = envs.step(still)
        assert truncated.tolist() == lost and not terminated.any()
        assert (rewards[per_server:] == 0.0).all()
        assert infos["_server_restarted"].tolist() == lost
        assert observations[per_server:].tobytes() == first[per_server:].tobytes()  # the last
        assert envs.servers[0] is survivor and envs.servers[1] is not victim
        observations, rewards, terminated, truncated, _ = envs.step(still)
        # NEXT_STEP: the autoreset on the new server
        assert (rewards[per_server:] == 0.0).all() and not truncated.any()


@pytest.mark.parametrize("target", [TARGET, PAIR_TARGET], ids=["cartpole", "pair-dict-spaces"])
def test_vector_layouts_give_identical_results(target: str) -> None:
    """Four sub-environments in one server (one ``steps`` request per step, in columns), in
    four servers (plain requests) or in this process (in columns, no socket): the same seeds
    and actions give the same observations, rewards and flags, resets included; Dict spaces
    (two agents) too."""
    runs = []
    for servers, layout in [
        (1, {"instances_per_server": 4}),
        (4, {"instances_per_server": 1}),
        (0, {"in_process": True}),
    ]:
        with RemoteVectorEnv(4, target, max_episode_steps=15, **layout) as envs:
            assert len(envs.servers) == servers and len(envs.sessions) == max(servers, 1)
            envs.action_space.seed(8)
            seen = [_bytes(envs.reset(seed=30)[0])]
            for _ in range(40):
                observations, rewards, terminated, truncated, infos = envs.step(
                    envs.action_space.sample()
                )
                seen.append(
                    (
                        _bytes(observations),
                        rewards.tobytes(),
                        terminated.tobytes(),
                        truncated.tobytes(),
                        infos["frames"].tobytes(),
                    )
                )
            runs.append(seen)
    assert runs[0] == runs[1] == runs[2]


def test_a_vector_awaits_first_the_server_that_answers_last(serve: Serve) -> None:
    """A step's answers are awaited last-first, so that the trainer sleeps once per step
    rather than waking for each (on a small machine it shares a core with a server): with a
    slow server (32 CartPoles) and a quick one (1), the slow one comes to be awaited first."""
    slow, quick = serve(TARGET, args=("--instances", "32")), serve(TARGET)
    with RemoteVectorEnv(
        addresses=[f"{slow.host}:{slow.port}", f"{quick.host}:{quick.port}"]
    ) as envs:
        assert envs._servers.gather_order == [1, 0]  # at first the last server is the last rung
        envs.reset(seed=0)
        for _ in range(20):  # the first step shows it, unless the quick server was held up
            envs.step(np.zeros((33, 1), np.float32))
            if envs._servers.gather_order == [0, 1]:
                break
        assert envs._servers.gather_order == [0, 1]


def test_a_refused_vector_step_raises_the_first_servers_refusal() -> None:
    """Whatever order the answers are awaited in, the error raised is the first server's."""
    with RemoteVectorEnv(4, TARGET, instances_per_server=2) as envs:
        envs.reset(seed=0)
        actions = np.zeros((4, 1), np.float32)
        actions[1], actions[2] = 5.0, 7.0  # server 0's second instance, server 1's first
        for order in ([0, 1], [1, 0]):
            envs._servers.gather_order = order
            with pytest.raises(rlenv_client.RemoteError, match=r"action\[1, 0\] is 5.0"):
                envs.step(actions)
        envs.step(np.zeros((4, 1), np.float32))  # nothing moved: the next step is served


def test_max_episode_steps_below_one_is_refused() -> None:
    with pytest.raises(ValueError, match="max_episode_steps must be at least 1, got 0"):
        RemoteVectorEnv(2, TARGET, in_process=True, max_episode_steps=0)


def _bytes(batch: Any) -> bytes:
    """A batch (an array, or a map of arrays) as bytes, to compare runs exactly."""
    if isinstance(batch, dict):
        return b"".join(_bytes(batch[key]) for key in sorted(batch))
    return np.asarray(batch).tobytes()


def test_make_vec_puts_one_server_on_each_core() -> None:
    envs = gym.make_vec(CARTPOLE, num_envs=6)
    try:
        cores = os.cpu_count() or 1
        assert len(envs.unwrapped.servers) == min(6, cores)
        assert sum(client.hello.instances for client in envs.unwrapped.clients) == 6
        observations, _ = envs.reset(seed=0)
        assert observations.shape == (6, 5)
        assert len({row.tobytes() for row in observations}) == 6  # seeded apart
    finally:
        envs.close()


def test_a_server_of_an_older_protocol_is_refused_clearly() -> None:
    """A server speaking protocol 1.x (arrays as ext types, no host of one): a clear error."""
    import socket
    import threading

    from rlenv.protocol import Connection, Hello, Role

    hello = Hello(
        "Old",
        CartPoleAgent.action_space,
        CartPoleAgent.observation_space,
        instances=2,
        protocol=(1, 0),
    )
    listener = socket.create_server(("127.0.0.1", 0))

    def serve_hello() -> None:
        connection, _ = listener.accept()
        with connection:
            connection.sendall(Connection(Role.SERVER).send(hello))
            connection.recv(1)  # until the client hangs up

    thread = threading.Thread(target=serve_hello)
    thread.start()
    try:
        host, port = listener.getsockname()
        with pytest.raises(
            ProtocolVersionError, match=r"server speaks rlenv protocol 1.0, this client speaks 2\.7"
        ):
            RemoteVectorEnv(addresses=[f"{host}:{port}"])
    finally:
        thread.join(timeout=10)
        listener.close()


def test_cartpole_v0_is_not_called_an_outdated_cartpole_v1() -> None:
    """v0 and v1 are two environments: gymnasium's 'out of date' warning would mislead."""
    code = (
        "import gymnasium as gym, rlenv_client\n"
        "gym.make('rlenv/CartPole-v0', in_process=True).close()\n"
    )
    result = subprocess.run(
        [sys.executable, "-W", "error::DeprecationWarning", "-c", code],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr
