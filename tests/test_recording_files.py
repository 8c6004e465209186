"""What a recording file may do to the machine that opens it: be read within bounds, and run
only code that is installed or that the user named or trusted."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import rlenv_client  # noqa: F401  (registers the ids)
from examples.cartpole import controller
from rlenv.protocol.messages import MAX_REPEAT_ACTION
from rlenv_client.recordings import MAX_RECORDING_BYTES
from rlenv_client.replay import EpisodeFile, digest
from rlenv_client.trusted_targets import UntrustedTargetError
from rlenv_tools.inspector import Timelines
from rlenv_tools.inspector._watch import InspectorError
from rlenv_tools.timeline import Timeline

CHECKOUT = Path(__file__).resolve().parent.parent
PLANTED = """\
from pathlib import Path
Path(__file__).with_name("ran").write_text("planted code ran")
from rlenv.examples.cartpole import CartPoleEnvironment as Planted
NotAnEnvironment = dict
"""


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Twelve steps of a CartPole episode, recorded."""
    path = tmp_path_factory.mktemp("recorded") / "episode-0001.rlenv"
    env = gym.make("rlenv/CartPole-v0", share_server=False)
    try:
        observation, _ = env.reset(seed=5)
        digests = [digest(observation)]
        for t in range(12):
            action = np.clip(controller(observation) + 0.1 * np.sin(t), -1, 1).astype(np.float32)
            observation, _, terminated, truncated, _ = env.step(action)
            digests.append(digest(observation))
            assert not (terminated or truncated)
        remote = env.unwrapped
        EpisodeFile(remote.target, remote.client.snapshot(), digests, False, False).save(path)
    finally:
        env.close()
    return path


def rlenv(
    *args: str, cwd: Path | None = None, timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    path = os.pathsep.join([str(CHECKOUT), str(CHECKOUT / "client")])
    return subprocess.run(
        [sys.executable, "-m", "rlenv", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
        env={**os.environ, "PYTHONPATH": path},
    )


def planted(folder: Path, recording: Path, target: str = "planted:Planted") -> Path:
    """A folder as a download might be: a recording naming a module planted beside it."""
    folder.mkdir(exist_ok=True)
    (folder / "planted.py").write_text(PLANTED)
    episode = EpisodeFile.load(recording)
    episode.target = target
    episode.save(folder / "episode-0001.rlenv")
    return folder / "episode-0001.rlenv"


# --- files that are no recordings --------------------------------------------------------------


def test_a_fifo_a_device_and_a_folder_are_refused_at_once(tmp_path: Path) -> None:
    fifo = tmp_path / "episode-0001.rlenv"
    os.mkfifo(fifo)  # nobody writes: reading it would wait for ever
    for path, kind in ((fifo, "a FIFO"), (Path("/dev/zero"), "a device"), (tmp_path, "a folder")):
        began = time.monotonic()
        with pytest.raises(ValueError, match=f"is {kind}: a recording is a regular file"):
            EpisodeFile.load(path)
        with pytest.raises(ValueError, match=f"is {kind}"):
            Timeline.open(path)
        assert time.monotonic() - began < 30  # at once: a hang never returns
    for args in (
        ["replay", str(fifo)],
        ["replay", "/dev/zero"],
        ["replay", str(fifo), "--inspect"],
    ):
        result = rlenv(*args, timeout=60)  # a hang would be a TimeoutExpired
        assert result.returncode == 2 and "a recording is a regular file" in result.stderr
    with pytest.raises(ValueError, match="is a FIFO"):
        Timelines([fifo])


def test_a_sparse_file_is_refused_from_its_size_without_reading_it(tmp_path: Path) -> None:
    sparse = tmp_path / "episode-0001.rlenv"
    with open(sparse, "wb") as file:
        file.truncate(2 << 30)  # 2 GiB of nothing, none of it on disk
    script = (
        "import resource, sys\nfrom rlenv_client.replay import EpisodeFile\n"
        "try:\n    EpisodeFile.load(sys.argv[1])\nexcept ValueError as error:\n"
        "    print(error)\n"
        "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
    )
    path = os.pathsep.join([str(CHECKOUT), str(CHECKOUT / "client")])
    result = subprocess.run(
        [sys.executable, "-c", script, str(sparse)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": path},
    )
    said, peak = result.stdout.splitlines()
    assert (
        said == f"{sparse} holds 2,147,483,648 bytes: a recording holds at most "
        f"{MAX_RECORDING_BYTES:,}"
    )
    assert int(peak) < 400 * 1024  # KiB: the interpreter and its imports, not the file


def test_an_action_asking_for_too_many_ticks_is_refused(tmp_path: Path, recording: Path) -> None:
    episode = EpisodeFile.load(recording)
    action = next(event for event in episode.snapshot["events"] if event[0] == "action")
    action[2] = 2**40
    episode.save(tmp_path / "episode-0001.rlenv")
    expected = f"asks for {2**40:,} ticks; a recorded action runs at most {MAX_REPEAT_ACTION:,}"
    with pytest.raises(ValueError, match=expected):
        EpisodeFile.load(tmp_path / "episode-0001.rlenv")
    result = rlenv("replay", str(tmp_path / "episode-0001.rlenv"))  # 2**40 ticks: a timeout
    assert result.returncode == 2 and expected in result.stderr
    action[2] = MAX_REPEAT_ACTION  # the bound itself is a recording
    episode.save(tmp_path / "at-the-bound.rlenv")
    assert (
        EpisodeFile.load(tmp_path / "at-the-bound.rlenv").snapshot["events"]
        == episode.snapshot["events"]
    )


def test_a_malformed_snapshot_is_not_an_episode(tmp_path: Path, recording: Path) -> None:
    episode = EpisodeFile.load(recording)
    episode.snapshot["events"].append(["action", [0.0]])  # no frames
    episode.save(tmp_path / "bad.rlenv")
    with pytest.raises(ValueError, match="is not an rlenv episode: restore: events"):
        EpisodeFile.load(tmp_path / "bad.rlenv")


# --- targets that run code -----------------------------------------------------------------------


def test_a_planted_target_runs_in_none_of_the_tools(
    tmp_path: Path, recording: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    download = tmp_path / "download"
    path = planted(download, recording)
    ran = download / "ran"
    advice = "--target MODULE:CLASS (target= in Python), or trust the file with --trust-target"
    for cwd in (tmp_path, download):  # also run in the recording's own folder
        for args in (
            ["replay", str(path)],
            ["replay", str(path), "--inspect"],
            ["dataset", "create", "planted/one-v0", str(download)],
        ):
            result = rlenv(*args, cwd=cwd)
            assert result.returncode == 2, (args, result.stdout, result.stderr)
            assert not ran.exists(), args
            if args[0] == "replay":  # dataset create says so only where minari is installed
                assert (
                    f"names the target 'planted:Planted': {download / 'planted.py'} holds "
                    "it, not an installed package" in result.stderr
                )
                assert advice in result.stderr
        monkeypatch.chdir(cwd)
        with pytest.raises(UntrustedTargetError, match="trust_target=True"):
            Timeline.open(path)
        # the inspector's recent episodes carry what a served hello named (rlenv inspect)
        served = EpisodeFile.load(path)
        served.path = None
        timelines = Timelines()
        number = timelines.add_episode(served, "recent", {"server": 0, "instance": 0})
        with pytest.raises(InspectorError, match="--trust-target") as refused:
            timelines.describe(number)
        assert refused.value.status == 422
        timelines.close()
        assert not ran.exists()


def test_a_target_the_user_names_or_trusts_runs(
    tmp_path: Path, recording: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    download = tmp_path / "download"
    path = planted(download, recording)
    result = rlenv("replay", str(path), "--trust-target", cwd=download)
    assert result.returncode == 0 and "every observation identical" in result.stdout, result.stderr
    assert (download / "ran").read_text() == "planted code ran"
    (download / "ran").unlink()
    result = rlenv("replay", str(path), "--target", "planted:Planted", cwd=download)
    assert result.returncode == 0, result.stderr
    monkeypatch.chdir(download)
    with Timeline.open(path, trust_target=True) as timeline:
        assert len(timeline) == 12
    with Timeline.open(path, target="planted:Planted") as timeline:
        assert len(timeline) == 12
    # an installed package's target needs neither (examples are rlenv's own)
    with Timeline.open(recording) as timeline:
        assert timeline.episode.target == "rlenv.examples.cartpole:CartPoleEnvironment"


def test_a_trusted_target_that_is_no_environment_is_refused(
    tmp_path: Path, recording: Path
) -> None:
    download = tmp_path / "download"
    path = planted(download, recording, "planted:NotAnEnvironment")
    result = rlenv("replay", str(path), "--trust-target", cwd=download)
    assert result.returncode == 2
    assert (
        "planted:NotAnEnvironment is not an RLEnvironment subclass" in result.stderr + result.stdout
    )


def test_a_planted_target_makes_no_dataset(
    tmp_path: Path, recording: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("minari")
    from rlenv_tools.datasets import create_dataset

    download = tmp_path / "download"
    planted(download, recording)
    monkeypatch.chdir(download)
    with pytest.raises(UntrustedTargetError, match="a recording in .* names the target"):
        create_dataset("planted/one-v0", download)
    assert not (download / "ran").exists()
