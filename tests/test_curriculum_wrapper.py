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
from rlenv.serving._lean import LeanSteps
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
    two_on_one: gymnasium.vector.VectorEnv,
) -> None:
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
    two_on_one: gymnasium.vector.VectorEnv,
) -> None:
    """With edit_levels, a replay is followed by its level edited (data), played as new."""
    sampler = LevelSampler(2, replay_prob=1.0, seed=0)
    wrapper = CurriculumVectorEnv(two_on_one, sampler, seed=4, edit_levels=2)
    observations, info = wrapper.reset()
    replays: list[list[Any]] = [[], []]  # per sub-env: what it played, in order
    for _ in range(1500):
        if "replayed" in info:
            for index in np.flatnonzero(info["_replayed"]):
                replays[index].append(
                    "replay"
                    if info["replayed"][index]
                    else type(wrapper._playing[index].level).__name__
                )
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
    two_on_one: gymnasium.vector.VectorEnv,
) -> None:
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
def test_two_sub_environments_get_other_levels_at_the_same_autoreset(mode: AutoresetMode) -> None:
    with RemoteVectorEnv(
        2, PLINKO, instances_per_server=2, max_episode_steps=3, autoreset_mode=mode
    ) as envs:
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
        client.send_steps(
            actions, np.array([True, False]), reset_with=[{"reset": {"seed": 7}}, None]
        )
        answers.append(client.receive_steps())
    assert counting.runs == 2  # the two requests without entries
    one, other = answers  # row 1 was reset unseeded: its generator differs on each host
    assert one.observation[0].tobytes() == other.observation[0].tobytes()
    assert one.frames.tolist() == other.frames.tolist()
    with LocalClient(CartPoleEnvironment, instances=2) as alone:
        observation, _ = alone.reset(seed=7)
    assert one.observation[0].tobytes() == observation.tobytes()


@pytest.mark.parametrize(
    "reset_with, message",
    [
        ([{"reset": {}}], "a list of 2 entries"),
        ([{"reset": {}}, {"reset": {}}], "instance 1 does not reset"),
        ([{"reset": {"seed": -1}}, None], "steps.reset_with[0]: reset.seed"),
        ([{"seed": 1}, None], "unknown key 'seed' in steps.reset_with[0]"),
    ],
)
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

    with RemoteVectorEnv(
        2,
        PLINKO,
        instances_per_server=2,
        max_episode_steps=40,
        autoreset_mode=AutoresetMode.SAME_STEP,
    ) as envs:
        sampler = LevelSampler(8, replay_prob=0.5, minimum_fill_ratio=0.25, robust=True, seed=0)
        wrapper = CurriculumVectorEnv(envs, sampler, score="external", seed=0)
        callback = CurriculumCallback(wrapper)
        model = sb3.PPO(
            "MlpPolicy",
            SB3VecEnv(vector=wrapper),
            n_steps=128,
            batch_size=64,
            n_epochs=1,
            normalize_advantage=False,
            seed=0,
            device="cpu",
        )
        model.learn(256, callback=callback)
        assert callback.scored >= 4
        assert len(sampler) >= 2
        assert any(score > 0 for score in (sampler.score(i) for i in sampler.weights()))
        with pytest.raises(ValueError, match="normalize_advantage=False"):
            sb3.PPO("MlpPolicy", SB3VecEnv(vector=wrapper), n_steps=64, device="cpu").learn(
                64, callback=CurriculumCallback(wrapper)
            )


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_a_level_on_trial_is_played_n_times_then_offered_with_their_mean(
    mode: AutoresetMode,
) -> None:
    """rollouts_per_level=3: a new level's 3 episodes (on either sub-env) come before its score."""
    with RemoteVectorEnv(2, PLINKO, instances_per_server=2, autoreset_mode=mode) as envs:
        sampler = LevelSampler(100, replay_prob=0.0, seed=0)
        scores: dict[int, list[float]] = {}  # level -> the callable's scores, in order
        players: dict[int, set[int]] = {}  # level -> the sub-envs that played it

        def score(episode: Any) -> float:
            assert episode.trial is not None and not episode.replayed
            assert episode.level not in map(sampler.level, sampler.weights())  # not yet
            value = float(episode.first_step % 7)
            scores.setdefault(episode.level, []).append(value)
            players.setdefault(episode.level, set()).add(episode.env)
            return value

        wrapper = CurriculumVectorEnv(envs, sampler, score=score, seed=5, rollouts_per_level=3)
        observations, info = wrapper.reset()
        firsts: dict[int, set[bytes]] = {}  # level -> its episodes' first observations
        for step in range(3000):
            for index in np.flatnonzero(info.get("_replayed", np.zeros(2, bool))):
                assert not info["replayed"][index] and info["level"][index] is None
                level = wrapper._playing[index].level
                firsts.setdefault(level, set()).add(observations[index].tobytes())
            if step == 70:  # episodes under way are cut short: their levels are played again
                observations, info = wrapper.reset()
                continue
            observations, _, _, _, info = wrapper.step(follow(observations))
            assert len(wrapper._trials) <= 2 * wrapper.num_envs
            held = [e.trial for e in wrapper._playing if e is not None] + [
                chosen[2] for chosen in wrapper._next if chosen is not None
            ]
            for number, trial in wrapper._trials.items():  # no trial is lost or overplayed
                assert trial.under_way == held.count(number)
                assert len(trial.results) + trial.under_way <= 3
            buffered = {sampler.level(i): sampler.score(i) for i in sampler.weights()}
            for level, values in scores.items():
                assert len(values) <= 3
                if len(values) == 3:
                    assert buffered[level] == pytest.approx(np.mean(values))
                else:
                    assert level not in buffered
            if len(sampler) >= 4 and any(len(played) == 2 for played in players.values()):
                break
        assert len(sampler) >= 4, "fewer than 4 levels were offered"
        assert any(len(played) == 2 for played in players.values()), (
            "no level's trial went on another sub-env"
        )
        assert all(len(observed) == 1 for observed in firsts.values())  # the level, replayed


@pytest.mark.parametrize("rollouts", [1, 2])
def test_with_several_rollouts_learnable_levels_enter_a_full_buffer(
    two_on_one: gymnasium.vector.VectorEnv, rollouts: int
) -> None:
    """The first 2 levels are always caught (learnability 0); each later level is caught on
    its first rollout only (0.25 over 2): with one rollout no level enters the full buffer."""
    sampler = LevelSampler(2, replay_prob=0.5, seed=0)
    wrapper = CurriculumVectorEnv(two_on_one, sampler, seed=6, rollouts_per_level=rollouts)
    observations, info = wrapper.reset()
    catch = np.ones(2, bool)
    starts: dict[int, int] = {}  # trial -> its episodes started
    outcomes: dict[int, list[float]] = {}  # trial -> its outcomes
    trials: list[Any] = [None, None]  # the trial each sub-env plays
    levels: dict[int, Any] = {}  # trial -> its level
    new_levels = 0
    for _ in range(3000):
        for index in np.flatnonzero(info.get("_replayed", np.zeros(2, bool))):
            episode = wrapper._playing[index]
            trials[index] = trial = episode.trial
            if trial is not None:
                starts[trial] = starts.get(trial, 0) + 1
                levels[trial] = episode.level
            catch[index] = trial is None or trial <= 2 or starts[trial] == 1
            new_levels += not info["replayed"][index]
        actions = follow(observations) * np.where(catch, 1, -1)[:, None].astype(np.float32)
        observations, rewards, terminated, truncated, info = wrapper.step(actions)
        for index in np.flatnonzero(terminated | truncated):
            trial = trials[index]
            if trial is None:
                continue
            outcomes.setdefault(trial, []).append(float(terminated[index] and rewards[index] > 0))
            if len(outcomes[trial]) == rollouts:  # offered now: in the buffer if it entered
                buffered = {sampler.level(i): sampler.score(i) for i in sampler.weights()}
                if levels[trial] in buffered:
                    assert buffered[levels[trial]] == pytest.approx(learnability(outcomes[trial]))
        if new_levels >= 40 and (rollouts == 1 or max(sampler.weights()) >= 4):
            break
    if rollouts == 1:
        assert sorted(sampler.weights()) == [0, 1]  # refused: 0 is not above the lowest
    else:
        entered = [i for i in sampler.weights() if i >= sampler.capacity]
        assert entered and all(sampler.score(i) > 0 for i in entered)
        assert max(sampler.weights()) >= 4, "fewer than 3 levels entered the full buffer"


@pytest.mark.parametrize(
    "options, message",
    [
        ({"rollouts_per_level": 0}, "rollouts_per_level must be an int >= 1, got 0"),
        ({"rollouts_per_level": 2, "score": "external"}, "not 'external'"),
    ],
)
def test_rollouts_per_level_is_checked(options: dict[str, Any], message: str) -> None:
    envs = gymnasium.make_vec("rlenv/Plinko-v0", num_envs=1)
    try:
        with pytest.raises(ValueError, match=message):
            CurriculumVectorEnv(envs, **options)
    finally:
        envs.close()


def test_accel_edits_go_on_trial_like_new_levels(two_on_one: gymnasium.vector.VectorEnv) -> None:
    sampler = LevelSampler(2, replay_prob=1.0, seed=0)
    wrapper = CurriculumVectorEnv(two_on_one, sampler, seed=4, edit_levels=2, rollouts_per_level=2)
    observations, info = wrapper.reset()
    plays: dict[bytes, int] = {}  # an edited level (packed) -> its episodes started
    for _ in range(3000):
        for index in np.flatnonzero(info.get("_replayed", np.zeros(2, bool))):
            episode = wrapper._playing[index]
            if isinstance(episode.level, dict):
                assert episode.trial is not None and not info["replayed"][index]
                key = msgpack.packb(episode.level)
                plays[key] = plays.get(key, 0) + 1
        observations, _, _, _, info = wrapper.step(follow(observations))
        if sum(count == 2 for count in plays.values()) >= 3:
            break
    assert sum(count == 2 for count in plays.values()) >= 3
    assert all(count <= 2 for count in plays.values())
    for level_id in sampler.weights():  # a buffered edit was played twice first
        level = sampler.level(level_id)
        if isinstance(level, dict):
            assert plays[msgpack.packb(level)] == 2
