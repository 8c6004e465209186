"""A new user's first hour, replayed against real servers (and a stranger's strict client).

What they ran into: a map key that is not a str, settings that are not finite, ``_get_info``
before the first reset, a configuration half applied, ``step(None)``, a wrong-sized vector
batch, and the command line's tracebacks. (Ctrl-C during a request: ``test_interruptions``.)
"""

from __future__ import annotations

import math
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import Serve

from rlenv.protocol.codec import pack, unpack
from rlenv.protocol.errors import ErrorCode
from rlenv.testing import frame, read_body, read_frame
from rlenv_client import Client, RemoteEnv, RemoteError, RemoteVectorEnv

TESTS = Path(__file__).resolve().parent
LANDER = "first_hour_envs:LanderEnvironment"
RLENV = Path(sys.executable).with_name("rlenv")


@pytest.fixture
def lander(serve: Serve) -> Client:
    server = serve(LANDER, env={"PYTHONPATH": str(TESTS)})
    with Client(server.host, server.port, timeout=10) as client:
        yield client


def _raw(client: Client) -> socket.socket:
    host, port = client.address.rsplit(":", 1)
    sock = socket.create_connection((host, int(port)), timeout=10)
    read_frame(sock)  # the hello
    return sock


# --- map keys are str, both ways ------------------------------------------------------------


@pytest.mark.parametrize(
    "request_map",
    [
        {"id": 3, b"reset": {}},
        {b"id": 1},
        {"id": 4, "reset": {"seed": 0, "options": {b"k": 1}}},
        {"id": 5, "inspect": {"get": {b"path": "World", "property": "gravity"}}},
    ],
    ids=["top", "id", "reset options", "inspect"],
)
def test_a_bin_map_key_at_any_depth_is_a_bad_frame(lander: Client, request_map: dict) -> None:
    with _raw(lander) as sock:
        sock.sendall(frame(pack(request_map)))
        reply = read_frame(sock)
        assert reply["id"] is None and reply["error"]["code"] == ErrorCode.BAD_FRAME
        assert "is bin, not a str" in reply["error"]["message"]
        sock.sendall(frame(pack({"id": 9})))
        assert read_frame(sock)["id"] == 9  # the connection goes on


def test_the_server_sends_no_map_key_that_is_not_a_str(lander: Client) -> None:
    lander.reset(seed=0)
    with pytest.raises(RemoteError) as error:
        lander.step(1)  # the environment's info holds b"raw"
    assert error.value.code == ErrorCode.ENVIRONMENT_ERROR
    assert (
        "_get_info() returned data that cannot travel: map key b'raw' is bin" in error.value.message
    )
    lander.reset(seed=0)
    with _raw(lander) as sock:  # what a strict client reads: only str keys, at every depth
        sock.sendall(frame(pack({"id": 1, "snapshot": {}})))
        unpack(read_body(sock), strict=True)


# --- settings that are not finite are refused -----------------------------------------------


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_a_setting_that_is_not_finite_is_refused_and_later_episodes_run(
    lander: Client, value: float
) -> None:
    with pytest.raises(RemoteError) as error:
        lander.configure(world={"gravity": value})
    assert error.value.code == ErrorCode.INVALID_CONFIG
    assert error.value.message.startswith("LanderWorld.gravity must be finite")
    for seed in range(2):  # the refused setting poisons no episode
        lander.reset(seed=seed)
        observation, *_ = lander.step(0)
        assert np.isfinite(observation).all()
    assert lander.get_property("World", "gravity") == -1.0


def test_an_inspect_set_that_is_not_finite_is_refused(serve: Serve) -> None:
    server = serve()  # CartPole: a body's angular velocity
    with Client(server.host, server.port, timeout=10) as client:
        client.reset(seed=0)
        before = client.get_property("World/Physics/Pole", "angular_velocity")
        for value in (math.nan, math.inf):
            with pytest.raises(RemoteError) as error:
                client.set_property("World/Physics/Pole", "angular_velocity", value)
            assert error.value.code == ErrorCode.BAD_REQUEST
            assert "angular_velocity must be finite" in error.value.message
        assert client.get_property("World/Physics/Pole", "angular_velocity") == before
        observation, *_ = client.step(np.zeros(1, np.float32))
        assert np.isfinite(observation).all()


# --- _get_info needs an episode; a failed request changes no setting -------------------------


def test_configure_before_the_first_reset_does_not_call_get_info(lander: Client) -> None:
    lander.configure(world={"gravity": -2.0})  # _get_info would fail: no episode yet
    assert lander.get_property("World", "gravity") == -2.0
    _, info = lander.reset(seed=0)
    assert info["height"] == 10.0  # once an episode exists, _get_info runs


def test_a_configuration_that_fails_half_way_leaves_nothing_applied(lander: Client) -> None:
    lander.reset(seed=0)
    with pytest.raises(RemoteError) as error:
        lander.configure(world={"gravity": -5.0, "wind": 13.0})  # gravity set, then it raised
    assert error.value.code == ErrorCode.ENVIRONMENT_ERROR and "unlucky wind" in error.value.message
    assert lander.get_property("World", "gravity") == -1.0
    lander.reset(seed=0)
    snapshot = lander.snapshot()
    assert snapshot["config"]["world"] == {"gravity": -1.0, "wind": 0.0}


# --- actions --------------------------------------------------------------------------------


def test_step_none_is_refused_and_poll_reads_the_state(lander: Client) -> None:
    lander.reset(seed=0)
    with pytest.raises(TypeError, match="call poll"):
        lander.step(None)
    observation, reward, terminated, truncated, info = lander.poll()
    assert observation.tolist() == [10.0, 0.0] and info["frames"] == 0
    assert (reward, terminated, truncated) == (0.0, False, False)
    observation, *_ = lander.step(2)  # the client is still in step
    assert observation[1] > 0


def test_gymnasium_step_none_is_refused(serve: Serve) -> None:
    server = serve(LANDER, env={"PYTHONPATH": str(TESTS)})
    env = RemoteEnv(address=server.address)
    try:
        env.reset(seed=0)
        with pytest.raises(TypeError, match="needs an action"):
            env.step(None)
    finally:
        env.close()


def test_a_vector_names_the_users_batch_when_its_shape_is_wrong(serve: Serve) -> None:
    servers = [serve(args=["--instances", "2"]) for _ in range(2)]
    envs = RemoteVectorEnv(addresses=[server.address for server in servers])
    try:
        envs.reset(seed=0)
        with pytest.raises(ValueError, match=r"actions has shape \(3, 1\), expected \(4, 1\)"):
            envs.step(np.zeros((3, 1), np.float32))
        with pytest.raises(TypeError, match="needs an action for each of the 4"):
            envs.step(None)
        observations, *_ = envs.step(np.zeros((4, 1), np.float32))  # nothing was sent before
        assert observations.shape == (4, 5)  # CartPole observes 5 values
    finally:
        envs.close()


# --- the command line -----------------------------------------------------------------------


def _rlenv(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(RLENV), *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=cwd,
        stdin=subprocess.DEVNULL,
    )


def test_the_console_script_serves_a_module_from_the_current_folder(tmp_path: Path) -> None:
    (tmp_path / "mymodule.py").write_text(
        "from rlenv.examples.cartpole import CartPoleEnvironment as PushEnvironment\n"
    )
    process = subprocess.Popen(
        [str(RLENV), "serve", "mymodule:PushEnvironment", "--port", "0"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        stdin=subprocess.DEVNULL,
    )
    try:
        line = process.stdout.readline()
        assert line.startswith("listening on "), process.stderr.read()
    finally:
        process.terminate()
        process.wait(timeout=10)


@pytest.mark.parametrize(
    ("args", "first_line"),
    [
        (
            ["serve", "examples.cartpole:Nope"],
            "rlenv serve: module 'examples.cartpole' has no attribute 'Nope'",
        ),
        (
            ["serve", "nomodule:Env"],
            "rlenv serve: No module named 'nomodule': run rlenv from the "
            "folder that holds the module",
        ),
        (
            ["serve", "examples.cartpole:CartPoleEnvironment", "--port", "99999"],
            "rlenv serve: error: argument --port: 99999 is not a port",
        ),
    ],
    ids=["attribute", "module", "port out of range"],
)
def test_the_command_line_says_in_one_line_why_it_failed(args: list[str], first_line: str) -> None:
    result = _rlenv(*args)
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if not line.startswith(("usage:", " "))]
    assert lines[0].startswith(first_line), result.stderr
    assert "Traceback" not in result.stderr


def test_a_port_in_use_is_said_in_one_line_and_the_traceback_needs_debug() -> None:
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = str(taken.getsockname()[1])
        result = _rlenv("serve", "examples.cartpole:CartPoleEnvironment", "--port", port)
        assert result.returncode == 2
        assert result.stderr.splitlines() == [
            f"rlenv serve: port {port} is in use on 127.0.0.1 (by another server?): choose "
            "another port, or 0 for a free one"
        ]
        debug = _rlenv(
            "--log-level", "DEBUG", "serve", "examples.cartpole:CartPoleEnvironment", "--port", port
        )
        assert "Traceback" in debug.stderr and debug.returncode == 2


def test_a_server_that_cannot_start_says_why_first(tmp_path: Path) -> None:
    from rlenv_client import ServerProcess, ServerStartError

    with pytest.raises(ServerStartError) as error:
        ServerProcess("examples.cartpole:Nope")
    first = str(error.value).splitlines()[0]
    assert first == (
        "server examples.cartpole:Nope could not start: module "
        "'examples.cartpole' has no attribute 'Nope'"
    )
