"""Cameras and recordings, keyed to physics frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import Serve

from examples.seeker import PIXELS_TARGET
from rlenv.scene2d.camera import Camera
from rlenv_client import Client, ErrorCode, LocalClient, RemoteError

imageio = pytest.importorskip("imageio.v2")
pytest.importorskip("imageio_ffmpeg")


def frames_in(path: Path) -> list[np.ndarray]:
    with imageio.get_reader(path) as reader:
        return [frame for frame in reader]


def test_a_camera_sees_the_scene_and_films_every_nth_tick(tmp_path: Path) -> None:
    with LocalClient(PIXELS_TARGET) as client:
        observation, _ = client.reset(seed=1)
        camera = client.environment.get_node("World/Eye")
        assert isinstance(camera, Camera)
        assert observation.shape == (64, 64, 3) and observation.dtype == np.uint8
        assert observation.tobytes() == camera.capture().tobytes()
        red = (observation[..., 0] > 150) & (observation[..., 1] < 100)
        assert red.sum() > 0  # the apple
        assert not camera.is_physics_processing()  # an idle camera costs no tick
        camera.start_recording(tmp_path / "eye.mp4", every=2)
        assert camera.is_physics_processing()
        with pytest.raises(RuntimeError, match="already recording"):
            camera.start_recording(tmp_path / "again.mp4")
        for _ in range(5):
            client.step(np.array([0.3, 0.0], np.float32))  # 5 steps x 4 ticks
        assert camera.stop_recording() == 10  # one frame every 2 ticks
        assert not camera.is_physics_processing()
    frames = frames_in(tmp_path / "eye.mp4")
    assert len(frames) in (9, 10) and frames[0].shape == (64, 64, 3)


def test_a_client_records_an_episode_on_the_server(serve: Serve, tmp_path: Path) -> None:
    server = serve(args=["--record-dir", str(tmp_path)])
    with Client(server.host, server.port, timeout=10) as client:
        client.reset(seed=0)
        client.configure(record="episode.mp4")
        for _ in range(10):
            client.step(np.zeros(1, np.float32), repeat_action=3)
        client.configure(record="")  # stop: the file is complete
        for name in ("../escape.mp4", ".hidden.mp4", "clip.exe", "a/b.mp4"):
            with pytest.raises(RemoteError) as error:
                client.configure(record=name)
            assert error.value.code == ErrorCode.INVALID_CONFIG
    frames = frames_in(tmp_path / "episode.mp4")
    assert len(frames) in (29, 30)  # one per physics tick: 10 steps x 3 ticks
    assert frames[0].shape == (400, 600, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["episode.mp4"]


def test_recording_is_refused_without_a_record_dir(client: Client) -> None:
    with pytest.raises(RemoteError, match="recording is disabled on this server"):
        client.configure(record="episode.mp4")
    client.reset(seed=0)  # and nothing else changed
