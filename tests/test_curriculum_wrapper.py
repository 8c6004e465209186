"""CurriculumVectorEnv over real Plinko servers; the ``steps`` request's ``reset_with``."""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import gymnasium
import msgpack
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from examples.cartpole import CartPoleEnvironment
from rlenv.protocol import Request
from rlenv.protocol.errors import RemoteError
from rlenv.serving.lean import LeanSteps
from rlenv_client import LocalClient, RemoteVectorEnv
from rlenv_client.curriculum import CurriculumVectorEnv, LevelSampler, learnability

PLINKO = "examples.plinko:PlinkoEnvironment"


def follow(observations: np.ndarray) -> np.ndarray:
    """Move each catcher towards its ball: Plinko episodes then end either way."""
    return np.clip(observations[:, 2:3] - observations[:, 0:1], -1, 1).astype(np.float32)


def difficulties(envs: RemoteVectorEnv) -> list[float]:
    """The World's difficulty in each instance of the vector's one server."""
    (client,) = envs.clients
    get = Request(0, {"inspect": {"get": {"path": "World", "property": "difficulty"}}})
    client.send_batch([get, get])
    return [reply.info["value"] for reply in client.receive_batch()]


class CountingLean(LeanSteps):
    """The lean path, counting the requests it serves."""

    runs = 0

    def run(self, reply_id: int, plan: Any) -> Any:
        """Count, then serve as the lean path does."""
        self.runs += 1
        return super().run(reply_id, plan)


@pytest.fixture
def two_on_one() -> Iterator[gymnasium.vector.VectorEnv]:
    """Two Plinko sub-environments hosted by one server (its steps carry both)."""
    envs = gymnasium.make_vec("rlenv/Plinko-v0", num_envs=2, instances_per_server=2)
    yield envs
    envs.close()


def test_a_new_level_then_replays_with_their_infos_and_masks(
        two_on_one: gymnasium.vector.VectorEnv) -> None:
    sampler = LevelSampler(2, replay_prob=1.0, seed=0)
    wrapper = CurriculumVectorEnv(two_on_one, sampler, seed=1)
    observations, info = wrapper.reset(seed=3)
    assert info["replayed"].tolist() == [False, False]
    assert info["level"].tolist() == [None, None]
    assert info["_replayed"].all() and info["_level"].all()
    resets = 0
    for _ in range(600):
        filled = len(sampler) == sampler.capacity
        observations, _, terminated, truncated, info = wrapper.step(follow(observations))
        if "replayed" not in info:
            continue
        started = info["_replayed"]
        assert (info["_level"] == started).all()
        for index in np.flatnonzero(started):
            if filled:  # full before this step: every reset replays
                assert info["replayed"][index]
                assert info["level"][index] in sampler.weights()
                resets += 1
            else:
                assert info["replayed"][index] == (info["level"][index] is not None)
        if resets >= 4:
            break
    assert resets >= 4


def test_learnability_scores_reach_the_buffer(two_on_one: gymnasium.vector.VectorEnv) -> None:
    sampler = LevelSampler(2, replay_prob=1.0, seed=0)
    wrapper = CurriculumVectorEnv(two_on_one, sampler, seed=2)
    observations, info = wrapper.reset()
    playing: list[Any] = [None, None]  # the level id each sub-env plays ("new" if new)
    outcomes: dict[int, list[float]] = {}
    inserted = 0
    mixed = False
    episodes = np.zeros((2, 1), np.float32)  # each sub-env's count of finished episodes
    for _ in range(1500):
        if "replayed" in info:
            for index in np.flatnonzero(info["_replayed"]):
                playing[index] = info["level"][index] if info["replayed"][index] else "new"
        # a replayed seed replays the episode as long as the actions do: every other episode
        # runs from the ball, so that a level may see both outcomes
        actions = follow(observations) * np.where(episodes % 2, -1, 1).astype(np.float32)
        observations, rewards, terminated, truncated, info = wrapper.step(actions)
        episodes[terminated | truncated] += 1
        for index in np.flatnonzero(terminated | truncated):
            success = float(bool(terminated[index]) and rewards[index] > 0)
            level = playing[index]
            if level == "new":
                if inserted == sampler.capacity:
                    continue  # refused: a score of 0 is not above the buffer's lowest
                level, inserted = inserted, inserted + 1
            outcomes.setdefault(level, []).append(success)
            assert sampler.score(level) == pytest.approx(learnability(outcomes[level]))
            mixed = mixed or 0 < sum(outcomes[level]) < len(outcomes[level])
        if mixed:
            break
    assert mixed, "no level saw both outcomes"
    assert max(sampler.score(level) for level in sampler.weights()) > 0


def test_accel_plays_an_edit_of_each_replayed_level_next(
        two_on_one: gymnasium.vector.VectorEnv) -> None:
    """With edit_levels, a replay is followed by its level edited (data), played as new."""
    sampler = LevelSampler(2, replay_prob=1.0, seed=0)
    wrapper = CurriculumVectorEnv(two_on_one, sampler, seed=4, edit_levels=2)
    observations, info = wrapper.reset()
    replays: list[list[Any]] = [[], []]  # per sub-env: what it played, in order
    for _ in range(1500):
        if "replayed" in info:
            for index in np.flatnonzero(info["_replayed"]):
                replays[index].append("replay" if info["replayed"][index] else
                                      type(wrapper._playing[index].level).__name__)
        observations, _, _, _, info = wrapper.step(follow(observations))
        if sum(kind == "dict" for played in replays for kind in played) >= 2:
            break
    for played in replays:
        for before, after in zip(played, played[1:], strict=False):
            assert (after == "dict") == (before == "replay")  # an edit after each replay only
    assert sum(kind == "dict" for played in replays for kind in played) >= 2
    edited = [level for level in map(sampler.level, sampler.weights()) if isinstance(level, dict)]
    assert all(level["format"] == "rlenv.PackedScene" for level in edited)


def test_edit_levels_must_be_a_count() -> None:
    envs = gymnasium.make_vec("rlenv/Plinko-v0", num_envs=1)
    try:
        with pytest.raises(ValueError, match="edit_levels must be an int >= 0, got -1"):
            CurriculumVectorEnv(envs, edit_levels=-1)
    finally:
        envs.close()


def test_a_replayed_seed_replays_the_first_observation_bit_for_bit(
        two_on_one: gymnasium.vector.VectorEnv) -> None:
    sampler = LevelSampler(1, replay_prob=1.0, seed=0)
    wrapper = CurriculumVectorEnv(two_on_one, sampler, seed=4)
    observations, info = wrapper.reset()
    first = [observations[0].tobytes(), observations[1].tobytes()]
    original: bytes | None = None  # the first observation of the level buffered
    replays = 0
    for _ in range(600):
        observations, _, terminated, truncated, info = wrapper.step(follow(observations))
        if original is None and len(sampler):
            ended = np.flatnonzero(terminated | truncated)
            original = first[int(ended[0])]  # the lowest finishing index is inserted first
            assert isinstance(sampler.level(0), int)
        for index in np.flatnonzero(info.get("_replayed", np.zeros(2, bool))):
            assert info["replayed"][index] and info["level"][index] == 0
            assert observations[index].tobytes() == original
            replays += 1
        if replays >= 3:
            break
    assert replays >= 3


def test_a_replayed_data_level_is_played_bit_for_bit() -> None:
    with gymnasium.make_vec("rlenv/Plinko-v0", num_envs=2, instances_per_server=1) as envs:
        envs.reset(seed=[5, 6])
        level = envs.clients[0].get_property("World", "level")
        sampler = LevelSampler(1, replay_prob=1.0, seed=0)
        sampler.insert(level, 0.0)
        wrapper = CurriculumVectorEnv(envs, sampler, score="external", seed=0)
        observations, info = wrapper.reset()
        assert info["replayed"].tolist() == [True, True] and info["level"].tolist() == [0, 0]
        expected = msgpack.packb(level)
        for client in envs.clients:
            assert msgpack.packb(client.get_property("World", "level")) == expected
        for _ in range(300):  # and at an autoreset, inside a steps request
            observations, _, _, _, info = wrapper.step(follow(observations))
            if info.get("_replayed", np.zeros(2, bool))[1]:
                assert info["level"][1] == 0
                played = envs.clients[1].get_property("World", "level")
                assert msgpack.packb(played) == expected
                break
        else:
            pytest.fail("sub-environment 1 never reset")
        assert wrapper.finished and all(e.replayed for e in wrapper.finished)


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_two_sub_environments_get_other_levels_at_the_same_autoreset(
        mode: AutoresetMode) -> None:
    with RemoteVectorEnv(2, PLINKO, instances_per_server=2, max_episode_steps=3,
                         autoreset_mode=mode) as envs:
        observations, _ = envs.reset(seed=[11, 12])
        first = observations.copy()
        default = difficulties(envs)
        envs.set_next_reset(0, seed=12)
        envs.set_next_reset(1, seed=11, config={"world": {"difficulty": 0.9}})
        actions = np.zeros((2, 1), np.float32)
        for _ in range(3):
            observations, _, _, truncated, _ = envs.step(actions)
        assert truncated.all()
        if mode is AutoresetMode.NEXT_STEP:
            observations, *_ = envs.step(actions)
        assert observations[0].tobytes() == first[1].tobytes()
        assert observations[1].tobytes() == first[0].tobytes()
        assert difficulties(envs) == [default[0], 0.9]
        for _ in range(3):  # once only: the next autoresets continue each generator
            observations, *_ = envs.step(actions)
        if mode is AutoresetMode.NEXT_STEP:
            observations, *_ = envs.step(actions)
        assert observations[0].tobytes() != first[1].tobytes()


def test_steps_without_reset_with_stay_on_the_lean_path() -> None:
    lean, general = (LocalClient(CartPoleEnvironment, instances=2) for _ in range(2))
    counting = lean.host.lean = CountingLean(lean.host.instances)
    general.host.lean = None
    actions = np.zeros((2, 1), np.float32)
    answers = []
    for client in (lean, general):
        client.send_steps(actions, np.ones(2, bool))
        client.receive_steps()
        client.send_steps(actions, np.array([True, False]), reset_with=[None, None])
        client.receive_steps()
        client.send_steps(actions, np.array([True, False]),
                          reset_with=[{"reset": {"seed": 7}}, None])
        answers.append(client.receive_steps())
    assert counting.runs == 2  # the two requests without entries
    one, other = answers  # row 1 was reset unseeded: its generator differs on each host
    assert one.observation[0].tobytes() == other.observation[0].tobytes()
    assert one.frames.tolist() == other.frames.tolist()
    with LocalClient(CartPoleEnvironment, instances=2) as alone:
        observation, _ = alone.reset(seed=7)
    assert one.observation[0].tobytes() == observation.tobytes()


@pytest.mark.parametrize("reset_with, message", [
    ([{"reset": {}}], "a list of 2 entries"),
    ([{"reset": {}}, {"reset": {}}], "instance 1 does not reset"),
    ([{"reset": {"seed": -1}}, None], "steps.reset_with[0]: reset.seed"),
    ([{"seed": 1}, None], "unknown key 'seed' in steps.reset_with[0]"),
])
def test_bad_reset_with_is_refused_whole(reset_with: list[Any], message: str) -> None:
    actions = np.zeros((2, 1), np.float32)
    with LocalClient(CartPoleEnvironment, instances=2) as client:
        client.send_steps(actions, np.ones(2, bool))
        client.receive_steps()
        client.send_steps(actions, np.array([True, False]), reset_with=reset_with)
        with pytest.raises(RemoteError, match=re.escape(message)):
            client.receive_steps()


def test_the_sb3_callback_scores_a_ppo_rollout() -> None:
    sb3 = pytest.importorskip("stable_baselines3")
    from rlenv_client.sb3 import CurriculumCallback, SB3VecEnv

    with RemoteVectorEnv(2, PLINKO, instances_per_server=2, max_episode_steps=40,
                         autoreset_mode=AutoresetMode.SAME_STEP) as envs:
        sampler = LevelSampler(8, replay_prob=0.5, minimum_fill_ratio=0.25, robust=True, seed=0)
        wrapper = CurriculumVectorEnv(envs, sampler, score="external", seed=0)
        callback = CurriculumCallback(wrapper)
        model = sb3.PPO("MlpPolicy", SB3VecEnv(vector=wrapper), n_steps=128, batch_size=64,
                        n_epochs=1, normalize_advantage=False, seed=0, device="cpu")
        model.learn(256, callback=callback)
        assert callback.scored >= 4
        assert len(sampler) >= 2
        assert any(score > 0 for score in (sampler.score(i) for i in sampler.weights()))
        with pytest.raises(ValueError, match="normalize_advantage=False"):
            sb3.PPO("MlpPolicy", SB3VecEnv(vector=wrapper), n_steps=64, device="cpu").learn(
                64, callback=CurriculumCallback(wrapper))
