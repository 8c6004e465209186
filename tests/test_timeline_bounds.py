"""What timelines may take of the machine: their processes and memory are bounded, every process
dies with its owner, and a tick view comes a page at a time."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import Serve, wait_until

from examples.cartpole import controller
from rlenv_client import Client
from rlenv_client.replay import EpisodeFile, digest
from rlenv_tools.inspector import Timelines
from rlenv_tools.inspector._watch import InspectorError
from rlenv_tools.timeline import Timeline

CHECKOUT = Path(__file__).resolve().parent.parent
CARTPOLE = "examples.cartpole:CartPoleEnvironment"


def recorded(
    serve: Serve, target: str, actions: list[object], path: Path, frames: int | None = None
) -> Path:
    """An episode of ``target`` taking ``actions`` (``frames`` ticks each) over a real server,
    written to ``path``."""
    server = serve(target)
    with Client(server.host, server.port, timeout=30) as client:
        observation, _ = client.reset(seed=3)
        digests = [digest(observation)]
        for action in actions:
            digests.append(digest(client.step(action, frames)[0]))
        EpisodeFile(target, client.snapshot(), digests, False, False).save(path)
    return path


def processes() -> dict[int, tuple[int, int]]:
    """Every running process: its parent and its process group."""
    found = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rpartition(")")[2].split()
            except OSError:
                continue
            if fields[0] != "Z":
                found[int(entry.name)] = (int(fields[1]), int(fields[2]))
    return found


def group(pgid: int) -> list[int]:
    """The running processes of the process group ``pgid``."""
    return [pid for pid, (_, of) in processes().items() if of == pgid]


def timelines_here() -> list[int]:
    """The first process of each timeline this process opened (each leads a group)."""
    return [
        pid
        for pid, (parent, of) in processes().items()
        if parent == os.getpid() and of == pid and b"rlenv_tools.forking" in _command(pid)
    ]


def _command(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


def cpu_seconds(pid: int) -> float:
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@pytest.fixture
def cartpole(serve: Serve, tmp_path: Path) -> Path:
    return recorded(serve, CARTPOLE, [[0.0]] * 40, tmp_path / "episode-0001.rlenv", 1)


def test_a_timeline_keeps_to_its_processes_however_long_its_branches(cartpole: Path) -> None:
    with Timeline.open(cartpole, checkpoint_every=1, max_processes=12) as timeline:
        assert len(timeline.processes) <= 12
        branches = [
            timeline.branch(step, policy=controller, max_steps=300) for step in (5, 10, 20, 30)
        ]
        assert len(timeline.processes) <= 12  # unbounded: one a step, over a thousand
        assert len(group(timeline.processes[0])) <= 12
        for branch in branches:  # fewer checkpoints: every step still re-simulates exactly
            for step in (len(branch), len(branch) // 2, 1):
                assert digest(branch.at(step).observation) == branch.episode.observations[step]
        assert len(timeline.processes) <= 12


def test_a_timeline_stops_parking_past_its_memory(cartpole: Path) -> None:
    with Timeline.open(cartpole, checkpoint_every=1, max_memory=1) as timeline:
        assert 0 < len(timeline.processes) <= 1 + 8 + 1  # the first, one measure's parks, cursor
        assert timeline.memory > 1
        branch = timeline.branch(3, policy=controller, max_steps=100)
        assert len(timeline.processes) <= 10
        assert digest(branch.at(50).observation) == branch.episode.observations[50]


def test_the_pages_timelines_share_its_bound_and_close_the_oldest(
    cartpole: Path, tmp_path: Path
) -> None:
    other = tmp_path / "other"
    other.mkdir()
    second = other / "episode-0001.rlenv"
    second.write_bytes(cartpole.read_bytes())
    timelines = Timelines(
        [cartpole, second], checkpoint_every=1, max_recent=1, max_files=1, max_processes=24
    )  # 12 a timeline
    try:
        names = [entry["name"] for entry in timelines.list()["timelines"]]
        assert names == [
            f"{cartpole.parent.name}/episode-0001.rlenv",
            "other/episode-0001.rlenv",
        ]  # the same file name, told apart
        timelines.policies["controller"] = controller
        for step in (2, 8, 16):
            timelines.branch_policy(0, 0, step, "controller", 300)
        (first,) = timelines_here()
        assert len(group(first)) <= 12
        timelines.describe(1)  # the second file opens: the first closes (max_files=1)
        wait_until(lambda: not group(first), "the oldest file's processes live on")
        assert len(timelines_here()) == 1
        listed = {entry["timeline"]: entry["open"] for entry in timelines.list()["timelines"]}
        assert listed == {0: False, 1: True}
        assert timelines.describe(0)["branches"][0]["length"] == 40  # opened again on asking
    finally:
        timelines.close()


OWNER = """\
import sys, threading
from rlenv_tools.timeline import Timeline
timeline = Timeline.open(sys.argv[1], checkpoint_every=2, timeout=3600)
print(timeline.processes[0], flush=True)
threading.Thread(target=timeline.branch, args=(2, [1])).start()  # loops for ever, in C
threading.Event().wait()
"""


def test_every_process_dies_with_an_owner_killed_while_its_environment_spins(
    serve: Serve, tmp_path: Path
) -> None:
    path = recorded(
        serve, "examples.faulty:StuckEnvironment", [0] * 4, tmp_path / "episode-0001.rlenv"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(CHECKOUT), str(CHECKOUT / "client")])}
    owner = subprocess.Popen(
        [sys.executable, "-c", OWNER, str(path)], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        assert owner.stdout is not None
        pgid = int(owner.stdout.readline())
        wait_until(
            lambda: any(cpu_seconds(pid) > 0.5 for pid in group(pgid)),
            "no process of the timeline spins",
            seconds=60,
        )
        assert len(group(pgid)) >= 3  # the first, checkpoints, the spinning cursor
        owner.send_signal(signal.SIGKILL)
        owner.wait(30)
        wait_until(lambda: not group(pgid), "processes outlived their owner")
    finally:
        owner.kill()
        owner.wait()


def test_a_long_steps_ticks_come_a_page_at_a_time(serve: Serve, tmp_path: Path) -> None:
    path = recorded(
        serve, "examples.faulty:CountingEnvironment", [0, 0], tmp_path / "episode-0001.rlenv", 250
    )  # it observes the ticks it counted
    timelines = Timelines([path])
    try:
        page = timelines.ticks(0, 0, 1)
        assert (page["frames"], page["first"], page["next"], len(page["ticks"])) == (
            250,
            1,
            101,
            100,
        )
        assert [tick["tick"] for tick in page["ticks"]] == list(range(1, 101))
        assert [tick["observation"]["Agent"]["numbers"] for tick in page["ticks"]] == [
            [k] for k in range(1, 101)
        ]
        middle = timelines.ticks(0, 0, 1, first=101, count=100)
        assert middle["next"] == 201 and middle["ticks"][0]["tick"] == 101
        assert middle["ticks"][0]["observation"]["Agent"]["numbers"] == [101]
        last = timelines.ticks(0, 0, 1, first=201, count=100)
        assert (last["next"], len(last["ticks"])) == (None, 50)
        with Timeline.open(path) as timeline:  # pages are slices of the whole, bit for bit
            every = timeline.ticks(1)
            assert [tick.tick for tick in every] == list(range(1, 251))
            assert digest(every[150].observation) == digest(
                timeline.ticks(1, first=151, count=1)[0].observation
            )
            assert digest(every[-1].observation) == timeline.episode.observations[1]
        with pytest.raises(InspectorError, match="count must be 1 to 100"):
            timelines.ticks(0, 0, 1, count=101)
        with pytest.raises(InspectorError, match="step 1 has ticks 1 to 250, not 251"):
            timelines.ticks(0, 0, 1, first=251)
    finally:
        timelines.close()


def test_two_agents_ticks_page_by_agent_under_a_bounded_timeline(
    serve: Serve, tmp_path: Path
) -> None:
    from examples.pair import TARGET as PAIR

    server = serve(PAIR)
    path = tmp_path / "episode-0001.rlenv"
    with Client(server.host, server.port, timeout=30) as client:
        observation, _ = client.reset(seed=4)
        agents = list(client.hello.agents)
        digests = [digest(observation)]
        for k in range(30):
            action = {
                name: np.array([np.sin(k + i), np.cos(k)], np.float32)
                for i, name in enumerate(agents)
            }
            digests.append(digest(client.step(action, 6)[0]))
        EpisodeFile(PAIR, client.snapshot(), digests, False, False).save(path)
    timelines = Timelines([path], checkpoint_every=1, max_processes=60)  # 10 a timeline
    try:
        page = timelines.ticks(0, 0, 30, first=4, count=2)
        assert (page["frames"], page["next"]) == (6, 6)
        assert [sorted(tick["observation"]) for tick in page["ticks"]] == [sorted(agents)] * 2
        (first,) = timelines_here()
        assert len(group(first)) <= 10
        with Timeline.open(path) as timeline:
            whole = timeline.ticks(30)
            assert digest(whole[-1].observation) == timeline.episode.observations[30]
            assert [digest(tick.observation) for tick in whole[3:5]] == [
                digest(tick.observation) for tick in timeline.ticks(30, first=4, count=2)
            ]
    finally:
        timelines.close()
