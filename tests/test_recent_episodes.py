"""Recent episodes: the last N finished episodes of a live server, fetched as recordings.

Each kept snapshot is a real recording: restored on a fresh server, it replays to the
observations the live episode had (their digests compared), whoever fetched it (the trainer, an
observer beside it, the inspector's Watcher).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import Serve

from examples.cartpole import TARGET, CartPoleEnvironment
from examples.pair import NAMES, chase
from examples.pair import TARGET as PAIR
from rlenv.protocol import ErrorReply, Request
from rlenv.serving import _snapshots as snapshots
from rlenv.serving._host import Host, target_of
from rlenv.testing import ManualClock
from rlenv_client import Client, ErrorCode, LocalClient, RemoteError
from rlenv_client.replay import EpisodeFile, digest, replay
from rlenv_tools.inspector._watch import InspectorError, Watcher

FAULTY = "examples.faulty:FaultyEnvironment"
LEFT, RIGHT = np.array([-1.0], np.float32), np.array([1.0], np.float32)


def play(
    client: Client | LocalClient,
    seed: int,
    actions: list[np.ndarray],
) -> tuple[list[str], bool, bool]:
    """One episode: the digests of what it saw, and how its last step ended."""
    observation, _ = client.reset(seed=seed)
    seen = [digest(observation)]
    terminated = truncated = False
    for action in actions:
        observation, _, terminated, truncated, _ = client.step(action)
        seen.append(digest(observation))
        if terminated or truncated:
            break
    return seen, bool(terminated), bool(truncated)


def replays_as_lived(episode: EpisodeFile, seen: list[str], fresh: Client) -> None:
    """``episode`` restored on ``fresh`` replays to the digests the live episode had."""
    result = replay(EpisodeFile(episode.target, episode.snapshot, seen), fresh)
    assert result.divergence is None
    assert result.steps == len(seen) - 1


def test_the_last_n_episodes_replay_to_what_the_live_episodes_saw(serve: Serve) -> None:
    live = serve(args=["--keep-episodes", "3"])
    lived = []
    with Client(live.address, timeout=10) as trainer:
        assert trainer.hello.protocol == (2, 7) and trainer.hello.target == TARGET
        assert trainer.episodes() == []  # none finished yet
        for seed in range(5):  # cut short by the next reset, except the pushed one (seed 3)
            actions = [RIGHT] * 60 if seed == 3 else [LEFT, RIGHT] * (2 + seed)
            lived.append(play(trainer, seed, actions))
        assert lived[3][1]  # the pole fell
        assert trainer.episodes()[-1].terminated  # seed 3's: the fifth is under way
        trainer.reset(seed=9)
        episodes = trainer.episodes()
        last = trainer.episodes(last=2)
    assert len(episodes) == 3  # the oldest two were dropped
    assert [e.snapshot for e in last] == [e.snapshot for e in episodes[1:]]
    with serve() as scratch, Client(scratch.address, timeout=10) as fresh:
        for episode, (seen, terminated, truncated) in zip(episodes, lived[2:], strict=True):
            assert episode.target == TARGET and episode.observations == []
            assert (episode.terminated, episode.truncated) == (terminated, truncated)
            replays_as_lived(episode, seen, fresh)


def test_an_observer_fetches_them_while_a_trainer_steps(serve: Serve) -> None:
    live = serve(args=["--instances", "2"])
    address = f"{live.host}:{live.port}"
    watcher = Watcher([address])
    lived: dict[int, list[list[str]]] = {0: [], 1: []}
    with Client(live.address, timeout=10) as trainer, Client(live.address, timeout=10) as observer:
        for seed in range(3):
            trainer.send_batch(
                [
                    Request(0, {"reset": {"seed": seed + 10 * i}, "observation": {"agent": {}}})
                    for i in (0, 1)
                ]
            )
            answers = trainer.receive_batch()
            seen = {i: [digest(trainer.observation_result(answers[i]))] for i in (0, 1)}
            for step in range(3 + seed):
                trainer.send_batch(
                    [
                        Request(
                            0,
                            {
                                "action": [0.3 * (i + 1)] if step % 2 else [-0.2],
                                "observation": {"agent": {}},
                            },
                        )
                        for i in (0, 1)
                    ]
                )
                for i, answer in enumerate(trainer.receive_batch()):
                    seen[i].append(digest(trainer.observation_result(answer)))
                # between two of the trainer's steps: no control taken, no reward taken
                assert len(observer.episodes()) == seed
                assert len(watcher.recent_episodes(0, 1)) == seed
            for i in (0, 1):
                lived[i].append(seen[i])
        trainer.send_batch([Request(0, {"reset": {}})] * 2)
        trainer.receive_batch()
        ours = observer.episodes()  # a plain request: instance 0
        stats = trainer.stats()
    assert stats["steps"] == 3 + 4 + 5  # the trainer's steps went on
    assert ours == watcher.recent_episodes(0, 0)
    second = watcher.recent_episodes(0, 1)
    with serve() as scratch, Client(scratch.address, timeout=10) as fresh:
        for instance, episodes in ((0, ours), (1, second)):
            assert [e.target for e in episodes] == [TARGET] * 3
            for episode, seen in zip(episodes, lived[instance], strict=True):
                replays_as_lived(episode, seen, fresh)
    for server, instance in ((0, 2), (1, 0)):
        with pytest.raises(InspectorError) as missing:
            watcher.recent_episodes(server, instance)
        assert missing.value.status == 404
    watcher.close()


def test_keep_episodes_0_keeps_none(serve: Serve) -> None:
    live = serve(args=["--keep-episodes", "0"])
    with Client(live.address, timeout=10) as client:
        for seed in range(3):
            play(client, seed, [LEFT] * 3)
        client.reset()
        assert client.episodes() == []


def test_refusals_name_what_is_wrong(serve: Serve) -> None:
    live = serve()
    watcher = Watcher([f"{live.host}:{live.port}"])
    with Client(live.address, timeout=10) as client:
        for last in (0, -1, 1.5, True):
            with pytest.raises(RemoteError, match="episodes.last must be an integer >= 1") as bad:
                client.episodes(last=last)  # type: ignore[arg-type]
            assert bad.value.code == ErrorCode.BAD_REQUEST
        for parts, message in (
            ({"episodes": {"since": 1}}, "unknown key 'since' in episodes"),
            ({"episodes": []}, "'episodes' must be a map"),
            ({"episodes": {}, "reset": {}}, "episodes goes alone"),
            ({"episodes": {}, "snapshot": {}}, "not both"),
        ):
            client.send_request(Request(1, parts))
            reply = client.receive_reply()
            assert isinstance(reply, ErrorReply) and reply.code == ErrorCode.BAD_REQUEST
            assert message in reply.message
        client.hello.protocol = (2, 4)  # what an older server says
        with pytest.raises(
            RemoteError, match="the server speaks protocol 2.4; recent episodes need 2.5"
        ):
            client.episodes()
    watcher.servers()  # connects
    watcher._servers[0].client.hello.protocol = (2, 4)  # type: ignore[union-attr]
    with pytest.raises(
        InspectorError, match="server 0 speaks protocol 2.4; recent episodes need 2.5"
    ) as old:
        watcher.recent_episodes(0, 0)
    assert old.value.status == 422
    watcher.close()


# --- in process: which episodes are kept --------------------------------------------------------


def test_only_replayable_episodes_with_actions_are_kept() -> None:
    with LocalClient(FAULTY) as local:
        assert local.episodes() == []  # asked: kept from now on
        local.reset(seed=1)  # no action: nothing to replay
        local.reset(seed=2)
        local.step(0)
        with pytest.raises(RemoteError) as failed:
            local.step(1)  # user code raises: the episode stops
        assert failed.value.code == ErrorCode.ENVIRONMENT_ERROR
        local.reset(seed=3)
        for _ in range(4):
            local.step(0)  # ends at tick 10: terminated
        local.reset(seed=4)
        assert [
            (len(e.snapshot["events"]), e.terminated, e.truncated) for e in local.episodes()
        ] == [(4, True, False)]
        assert local.episodes()[0].target == FAULTY


def test_overflowed_and_real_time_episodes_are_not_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(snapshots, "MAX_EVENTS", 5)
    with LocalClient(TARGET, clock=ManualClock()) as local:
        local.episodes()  # asked: kept from now on
        local.reset(seed=1)
        for _ in range(6):
            local.step(np.zeros(1, np.float32))  # past MAX_EVENTS: the log stopped
        local.configure(real_time=True)
        local.reset(seed=2)  # in real time throughout
        local.step(np.zeros(1, np.float32))
        local.configure(real_time=False)
        local.reset(seed=3)  # in lockstep, in real time for a while
        local.step(np.zeros(1, np.float32))
        local.configure(real_time=True)
        local.step(np.zeros(1, np.float32))
        local.configure(real_time=False)
        local.step(np.zeros(1, np.float32))
        local.reset(seed=4)
        assert local.episodes() == []
        local.step(np.zeros(1, np.float32))
        local.reset(seed=5)
        assert len(local.episodes()) == 1  # in lockstep throughout


def test_changes_after_the_last_action_belong_to_the_next_episode() -> None:
    """A configuration (or a restore's) before the next reset is left out of the recording."""
    with LocalClient(TARGET) as local:
        local.episodes()  # asked: kept from now on
        seen, _, _ = play(local, 5, [LEFT, RIGHT, LEFT])
        local.configure(agent={"angle_limit": 0.5})
        local.reset(seed=6)
        (episode,) = local.episodes()
        assert [event[0] for event in episode.snapshot["events"]] == ["action"] * 3
        replays_as_lived(episode, seen, local)  # the restore finished seed 6's: not kept
        assert len(local.episodes()) == 1


def test_memory_is_bounded_by_n() -> None:
    """The host keeps the very logs its episodes built, the last N of them."""
    host = Host(CartPoleEnvironment, keep_episodes=2)
    instance = host.instances[0]
    logs = []
    for seed in range(6):
        host.answer(Request(1, {"reset": {"seed": seed}}))
        host.answer(Request(2, {"action": LEFT}))
        logs.append(instance.log)
    host.answer(Request(3, {"reset": {}}))
    assert len({id(log) for log in logs}) == 6 and len(instance.recent) == 2
    answer = host.answer(Request(4, {"episodes": {}}))
    assert (
        [entry["snapshot"] for entry in answer.info["episodes"]]
        == [  # type: ignore[union-attr]
            log.snapshot() for log in logs[-2:]
        ]
    )
    host.close()
    with pytest.raises(ValueError, match="keep_episodes must be >= 0"):
        Host(CartPoleEnvironment, keep_episodes=-1)


def test_the_hello_names_the_target_when_it_can() -> None:
    assert target_of(TARGET) == TARGET
    assert target_of(CartPoleEnvironment) == TARGET
    assert target_of(CartPoleEnvironment()) is None  # built by code of its own

    class Local(CartPoleEnvironment):
        pass

    assert target_of(Local) is None  # load_environment cannot find it by name
    with LocalClient(CartPoleEnvironment) as local:
        assert local.hello.target == TARGET
        local.episodes()  # asked: kept from now on
        play(local, 0, [LEFT])
        local.reset()
        assert [e.target for e in local.episodes()] == [TARGET]


def test_several_agents_episodes_end_as_their_answers_said() -> None:
    """With several agents, the end is the answers' (every agent done; terminated if any did)."""
    with LocalClient(PAIR) as local:
        local.episodes()  # asked: kept from now on
        ends = []
        for seed in (2, 3):
            observation, _ = local.reset(seed=seed)
            seen = [digest(observation)]
            terminated = truncated = False
            for _ in range(300):
                observation, _, terminated, truncated, _ = local.step(
                    {name: chase(observation[name]) for name in NAMES}
                )
                seen.append(digest(observation))
                if terminated or truncated:
                    break
            ends.append((seen, bool(terminated), bool(truncated)))
        local.reset(seed=4)
        episodes = local.episodes()
        assert [(e.terminated, e.truncated) for e in episodes] == [end[1:] for end in ends]
        assert any(terminated or truncated for _, terminated, truncated in ends)
        for episode, (seen, _, _) in zip(episodes, ends, strict=True):
            replays_as_lived(episode, seen, local)


def test_a_vectors_autoresets_finish_episodes_too() -> None:
    """Column steps (the lean path a vector's steps take) keep them as plain resets do."""
    with LocalClient(TARGET, instances=2) as local:
        assert local.host is not None and local.host.lean is not None
        local.send_batch([Request(0, {"episodes": {"index": True}})] * 2)  # asked: kept now
        local.receive_batch()
        local.send_batch([local.reset_request(seed=i) for i in (0, 1)])
        local.receive_batch()
        actions = np.full((2, 1), 0.5, np.float32)
        for flags in ((False, False), (True, False), (False, True)):
            local.send_steps(actions, np.array(flags), 4)
            local.receive_steps()
        local.send_batch([Request(0, {"episodes": {}})] * 2)
        kept = [reply.info["episodes"] for reply in local.receive_batch()]  # type: ignore[union-attr]
        assert [[entry["steps"] for entry in entries] for entries in kept] == [[1], [2]]


# --- bounds: what is kept, what one answer holds ------------------------------------------------


def test_nothing_is_kept_until_a_client_asks() -> None:
    """A server no inspector asked keeps nothing (gym.make's shared servers, say)."""
    host = Host(CartPoleEnvironment, count=2)
    for seed in range(3):
        host.answer(Request(1, {"batch": [{"reset": {"seed": seed}}] * 2}))
        host.answer(Request(2, {"batch": [{"action": LEFT}] * 2}))
    assert [len(instance.recent) for instance in host.instances] == [0, 0]
    answer = host.answer(Request(3, {"batch": [None, {"episodes": {"index": True}}]}))
    assert answer.replies[1].info["episodes"] == []  # type: ignore[union-attr]
    for seed in range(3):
        host.answer(Request(4, {"batch": [{"reset": {"seed": seed}}] * 2}))
        host.answer(Request(5, {"batch": [{"action": LEFT}] * 2}))
    host.answer(Request(6, {"batch": [{"reset": {}}] * 2}))
    # the one asked: the episode under way when it was asked, and the three after it
    assert [len(instance.recent) for instance in host.instances] == [0, 4]
    host.close()


def test_what_a_server_keeps_is_bounded_in_events_shared_by_its_instances(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from rlenv.serving import _host as hosting

    monkeypatch.setattr(hosting, "KEEP_EVENTS", 10)  # 5 events for each of two instances
    host = Host(CartPoleEnvironment, count=2, keep_episodes=8)
    for steps in (2, 2, 2, 6, 2):
        host.answer(Request(1, {"batch": [{"reset": {"seed": steps}}] * 2}))
        for _ in range(steps):
            host.answer(Request(2, {"batch": [{"action": np.zeros(1, np.float32)}] * 2}))
    host.answer(Request(3, {"batch": [{"reset": {}}] * 2}))
    for instance in host.instances:
        index = instance.recent.index()
        # The 6-step one is beyond the bound: not kept; the oldest went to make room
        assert [entry["events"] for entry in index] == [2, 2]
        assert [entry["id"] for entry in index] == [2, 3]
    host.close()


def test_a_90000_step_episode_is_served_in_pages_no_answer_over_a_frame() -> None:
    """Its whole snapshot is refused as one answer, clearly; its pages rebuild it exactly."""
    from rlenv.protocol.codec import MAX_FRAME_OBJECTS, count_objects, pack
    from rlenv.serving._recent import PAGE_EVENTS, WHOLE_EVENTS

    host = Host(CartPoleEnvironment, keep_episodes=1)
    instance = host.instances[0]
    host.answer(Request(1, {"reset": {"seed": 0}}))
    host.answer(Request(2, {"action": LEFT}))
    log = instance.log
    log.events.extend(["action", np.array([0.25], np.float32), 1] for _ in range(89_999))
    whole = log.snapshot()
    host.answer(Request(3, {"reset": {}}))
    refused = host.answer(Request(4, {"episodes": {}}))
    assert isinstance(refused, ErrorReply) and refused.code == ErrorCode.BAD_REQUEST
    assert f"90,000 events, more than one answer carries ({WHOLE_EVENTS:,})" in refused.message
    (entry,) = host.answer(Request(5, {"episodes": {"index": True}})).info["episodes"]  # type: ignore[union-attr]
    assert (entry["steps"], entry["events"]) == (90_000, 90_000)
    events, pages = [], 0
    while len(events) < entry["events"]:
        answer = host.answer(
            Request(6, {"episodes": {"episode": entry["id"], "from": len(events)}})
        )
        body = pack(answer.to_wire())
        assert count_objects(body) <= MAX_FRAME_OBJECTS and len(body) < 4 << 20
        page = answer.info["episode"]  # type: ignore[union-attr]
        assert page["from"] == len(events) and len(page["snapshot"]["events"]) <= PAGE_EVENTS
        events.extend(page["snapshot"]["events"])
        pages += 1
    assert pages == -(-90_000 // PAGE_EVENTS)
    assert {**page["snapshot"], "events": events} == whole
    gone = host.answer(Request(7, {"episodes": {"episode": entry["id"] + 1}}))
    assert gone.info["episode"] is None  # type: ignore[union-attr]
    host.close()


def test_paged_forms_refuse_what_is_wrong() -> None:
    host = Host(CartPoleEnvironment)
    for part, message in (
        ({"index": False}, "episodes.index must be true"),
        ({"episode": -1}, "episodes.episode must be an integer >= 0"),
        ({"episode": 0, "from": 1.5}, "episodes.from must be an integer"),
        ({"from": 3}, "episodes.from goes with episodes.episode"),
        ({"index": True, "last": 2}, "one of last, index and episode"),
    ):
        reply = host.answer(Request(1, {"episodes": part}))
        assert isinstance(reply, ErrorReply) and reply.code == ErrorCode.BAD_REQUEST
        assert message in reply.message, reply.message
    host.close()


def test_the_watcher_fetches_each_kept_episode_once(serve: Serve) -> None:
    live = serve()
    watcher = Watcher([live.address])
    watcher.servers()  # connects: the server keeps episodes from now on
    with Client(live.address, timeout=10) as trainer:
        for seed in range(3):
            play(trainer, seed, [LEFT, RIGHT])
        trainer.reset()
        first = watcher.recent_episodes(0, 0)
        assert len(first) == 3
        play(trainer, 7, [LEFT])
        trainer.reset()
        again = watcher.recent_episodes(0, 0)
    assert again[:3] == first and all(a is b for a, b in zip(again, first, strict=False))
    assert len(again) == 4
    watcher.close()
