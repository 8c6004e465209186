"""An observer claims one agent of several while a trainer controls the episode (protocol 2.6).

Over real sockets, against ``rlenv serve`` subprocesses of ``examples.tag``: the claimed agent
moves as the observer holds (bit for bit as if the trainer had sent that action itself), the
trainer's ``info["claimed"]`` says so, a release or a disconnect gives the agent back, the
episode's snapshot replays exactly, and the refusals name what is wrong.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import wait_until
from inspector_http import fetch

from rlenv.protocol import Request, Response
from rlenv.protocol.errors import RemoteError
from rlenv_client import Client
from rlenv_client.launcher import ServerProcess
from rlenv_client.replay import EpisodeFile
from rlenv_tools.inspector import Demonstrator, InspectorServer, Watcher

TAG = "examples.tag:TagEnvironment"
HELD = np.array([1.0, -0.5], np.float32)  # what the person holds for Runner1


def trainer_action(step: int) -> dict[str, np.ndarray]:
    """The trainer's own actions: every agent, Runner1 included, changing with the step."""
    phase = np.float32(step % 7 / 7.0)
    return {
        "Chaser": np.array([phase, 1.0 - phase], np.float32),
        "Runner1": np.array([-1.0, phase], np.float32),
        "Runner2": np.array([0.0, -phase], np.float32),
    }


def same(a: Any, b: Any) -> bool:
    """Whether two observations are identical, bit for bit."""
    if isinstance(a, Mapping):
        return a.keys() == b.keys() and all(same(a[key], b[key]) for key in a)
    return (
        np.asarray(a).tobytes() == np.asarray(b).tobytes()
        and np.asarray(a).dtype == np.asarray(b).dtype
    )


@pytest.fixture
def tag(serve) -> ServerProcess:
    return serve(TAG)


def test_a_claimed_agent_moves_as_the_observer_holds_bit_for_bit(tag: ServerProcess) -> None:
    claimed_steps, free_steps = 12, 6
    with Client(tag.host, tag.port) as trainer, Client(tag.host, tag.port) as person:
        trainer.reset(seed=5)
        assert person.claim("Runner1", HELD) == ["Runner1"]
        seen = []
        for step in range(claimed_steps):
            observation, _, _, _, info = trainer.step(trainer_action(step))
            assert info["claimed"] == ["Runner1"]
            seen.append(observation)
        person.release_claim()
        for step in range(claimed_steps, claimed_steps + free_steps):
            observation, _, _, _, info = trainer.step(trainer_action(step))
            assert "claimed" not in info  # Runner1 is the trainer's again
            seen.append(observation)
        snapshot = trainer.snapshot()
        logged = [event[1] for event in snapshot["events"] if event[0] == "action"]
        assert all(np.array_equal(action["Runner1"], HELD) for action in logged[:claimed_steps])
        assert np.array_equal(
            logged[claimed_steps]["Runner1"], trainer_action(claimed_steps)["Runner1"]
        )
        # the same episode, the trainer sending the person's action itself
        trainer.reset(seed=5)
        for step, expected in enumerate(seen):
            action = trainer_action(step)
            if step < claimed_steps:
                action["Runner1"] = HELD
            observation, *_ = trainer.step(action)
            assert same(observation, expected), f"step {step} differs"
        # and the claimed episode's snapshot replays to where it ended, bit for bit
        restored, _ = trainer.restore(snapshot)
        assert same(restored, seen[-1])


def test_a_trainer_thread_plays_on_while_a_person_claims_and_disconnects(
    tag: ServerProcess,
) -> None:
    stop = threading.Event()
    infos: list[dict[str, Any]] = []
    failures: list[BaseException] = []

    def train() -> None:
        try:
            with Client(tag.host, tag.port) as trainer:
                trainer.reset(seed=1)
                step = 0
                while not stop.is_set():
                    _, _, terminated, truncated, info = trainer.step(trainer_action(step))
                    infos.append(info)
                    step += 1
                    if terminated or truncated:
                        trainer.reset()
        except BaseException as error:  # the test's thread reports it
            failures.append(error)

    thread = threading.Thread(target=train, daemon=True)
    thread.start()
    try:
        wait_until(lambda: len(infos) > 3 or failures, "the trainer never stepped", seconds=60)
        person = Client(tag.host, tag.port)
        assert person.claim("Runner2", HELD) == ["Runner2"]
        wait_until(
            lambda: infos[-1].get("claimed") == ["Runner2"] or failures,
            "the trainer's info never said Runner2 was claimed",
            seconds=60,
        )
        person.close()  # a disconnect releases the claim
        wait_until(
            lambda: "claimed" not in infos[-1] or failures,
            "the claim outlived its client's connection",
            seconds=60,
        )
        with Client(tag.host, tag.port) as other:  # and Runner2 may be claimed again
            assert other.claim("Runner2", HELD) == ["Runner2"]
    finally:
        stop.set()
        thread.join(timeout=60)
    assert not failures, failures


def test_claims_are_refused_precisely(serve, tag: ServerProcess) -> None:
    with (
        Client(tag.host, tag.port) as trainer,
        Client(tag.host, tag.port) as person,
        Client(tag.host, tag.port) as other,
    ):
        trainer.reset(seed=0)
        with pytest.raises(RemoteError) as refused:
            person.claim("Runner3", HELD)
        assert refused.value.code == "bad_request" and str(refused.value).endswith(
            "claim.agent: no agent 'Runner3'; the agents: Chaser, Runner1, Runner2"
        )
        with pytest.raises(RemoteError) as refused:
            person.claim("Runner1", np.array([3.0, 0.0], np.float32))
        assert refused.value.code == "invalid_action" and "claim." in str(refused.value)
        person.claim("Runner1", HELD)
        with pytest.raises(RemoteError) as refused:  # one claim per client
            person.claim("Runner2", HELD)
        assert refused.value.code == "bad_request" and "this client plays 'Runner1' already" in str(
            refused.value
        )
        with pytest.raises(RemoteError) as refused:  # one claim per agent
            other.claim("Runner1", HELD)
        assert (
            refused.value.code == "busy"
            and "agent 'Runner1' is claimed by another client" in str(refused.value)
        )
        with pytest.raises(RemoteError) as refused:  # the controller acts for all already
            trainer.claim("Runner2", HELD)
        assert (
            refused.value.code == "bad_request"
            and "this client controls the environment" in str(refused.value)
        )
        person.claim("Runner1", -HELD)  # changing the held action is no second claim
        assert trainer.step(trainer_action(0))[4]["claimed"] == ["Runner1"]
    driven = serve(TAG, args=["--policy", "Chaser=heuristic"])
    with Client(driven.host, driven.port) as person:
        with pytest.raises(RemoteError) as refused:
            person.claim("Chaser", HELD)
        assert refused.value.code == "bad_request" and str(refused.value).endswith(
            "claim: agent 'Chaser' is driven by the server (rlenv serve --policy); claim another"
        )
    single = serve()  # CartPole: one agent
    with Client(single.host, single.port) as person:
        with pytest.raises(RemoteError) as refused:
            person.claim("CartPole", 0)
        assert (
            refused.value.code == "bad_request"
            and "the client that controls the environment owns it" in str(refused.value)
        )


def test_the_inspectors_take_control_claims_an_agent_beside_a_trainer_and_records_it(
    tag: ServerProcess, tmp_path: Path
) -> None:
    stop = threading.Event()
    infos: list[dict[str, Any]] = []
    failures: list[BaseException] = []

    def train() -> None:  # a trainer of every agent, its episodes cut at 25 steps
        try:
            with Client(tag.host, tag.port) as trainer:
                while not stop.is_set():
                    trainer.reset()
                    for step in range(25):
                        _, _, terminated, truncated, info = trainer.step(trainer_action(step))
                        infos.append(info)
                        if terminated or truncated or stop.wait(0.002):
                            break
        except BaseException as error:  # the test's thread reports it
            failures.append(error)

    thread = threading.Thread(target=train, daemon=True)
    thread.start()
    watcher = Watcher([f"{tag.host}:{tag.port}"])
    demonstrator = Demonstrator(watcher, tmp_path, target=TAG, rate=200.0)
    inspector = InspectorServer(watcher, demonstrator=demonstrator)
    inspector.start()
    try:
        wait_until(lambda: infos or failures, "the trainer never stepped", seconds=60)
        page = inspector.url
        take = {"server": 0, "instance": 0, "agent": "Runner1"}
        with Client(tag.host, tag.port) as other:  # another person plays Runner1 already
            other.claim("Runner1", HELD)
            status, _, answer = fetch(page, "api/control", method="POST", body=take)
            assert (
                status == 409 and "agent 'Runner1' is claimed by another client" in answer["error"]
            ), answer
        status, _, state = fetch(page, "api/control", method="POST", body=take)
        assert status == 200 and state["controlling"] and state["claim"], state
        assert state["agent"] == "Runner1" and "ArrowRight" in state["keys"]
        fetch(page, "api/keys", method="POST", body={"held": ["ArrowRight"]})
        wait_until(
            lambda: infos[-1].get("claimed") == ["Runner1"] or failures,
            "the trainer's info never said Runner1 was claimed",
            seconds=60,
        )
        wait_until(
            lambda: demonstrator.episodes >= 2 or failures,
            "no episode of the trainer's was recorded",
            seconds=60,
        )
        status, _, state = fetch(page, "api/release", method="POST", body={})
        assert status == 200 and not state["controlling"] and state["error"] == ""
        count = len(infos)
        wait_until(lambda: len(infos) > count + 2 or failures, "the trainer stopped", seconds=60)
        assert "claimed" not in infos[-1]  # released: Runner1 is the trainer's again
        last = EpisodeFile.load(sorted(tmp_path.glob("episode-*.rlenv"))[-1])
        assert last.agent == "Runner1" and last.target == TAG and last.observations == []
        runner1 = {
            tuple(map(float, event[1]["Runner1"]))
            for event in last.snapshot["events"]
            if event[0] == "action" and "Runner1" in event[1]
        }
        assert runner1 == {(1.0, 0.0)}, runner1  # the person's, not the trainer's (-1, phase)
        chaser = {
            tuple(map(float, event[1]["Chaser"]))
            for event in last.snapshot["events"]
            if event[0] == "action"
        }
        assert len(chaser) > 1  # the trainer's own actions for the others
    finally:
        inspector.close()
        stop.set()
        thread.join(timeout=60)
    assert not failures, failures


def test_a_claim_in_a_batch_plays_an_agent_of_that_instance_alone(serve) -> None:
    server = serve(TAG, args=["--instances", "2"])
    with Client(server.host, server.port) as trainer, Client(server.host, server.port) as person:
        trainer.send_batch([trainer.reset_request(seed=2), trainer.reset_request(seed=2)])
        trainer.receive_batch()
        person.send_batch(
            [None, Request(0, {"claim": {"agent": "Runner1", "action": HELD.tolist()}})]
        )
        _, claimed = person.receive_batch()
        assert isinstance(claimed, Response) and claimed.info["claimed"] == ["Runner1"]
        for step in range(5):
            trainer.send_batch([trainer.step_request(trainer_action(step))] * 2)
            first, second = trainer.receive_batch()
            assert "claimed" not in first.info and second.info["claimed"] == ["Runner1"]
        assert not same(first.observation, second.observation)  # same seed, Runner1 differs
        logged = [
            event[1]["Runner1"] for event in trainer.snapshot()["events"] if event[0] == "action"
        ]
        assert len(logged) == 5 and all(  # instance 0's log: the trainer's own actions
            np.array_equal(action, trainer_action(step)["Runner1"])
            for step, action in enumerate(logged)
        )


def test_pettingzoo_says_which_agent_a_person_played(tag: ServerProcess) -> None:
    pytest.importorskip("pettingzoo")
    from rlenv_client.pettingzoo import RemoteParallelEnv

    env = RemoteParallelEnv(address=f"{tag.host}:{tag.port}")
    try:
        env.reset(seed=0)
        with Client(tag.host, tag.port) as person:
            person.claim("Runner2", HELD)
            infos = env.step({agent: np.zeros(2, np.float32) for agent in env.agents})[4]
            assert infos["Runner2"]["claimed"] is True
            assert "claimed" not in infos["Chaser"] and "claimed" not in infos["Runner1"]
            person.release_claim()
            infos = env.step({agent: np.zeros(2, np.float32) for agent in env.agents})[4]
            assert all("claimed" not in info for info in infos.values())
    finally:
        env.close()
