"""The level sampler (PLR's buffer) and its scores, against weights computed by hand."""

from __future__ import annotations

import json
from typing import Any

import pytest

from rlenv.protocol import pack, unpack
from rlenv_client.curriculum import (
    LevelSampler,
    learnability,
    max_mc,
    positive_value_loss,
)


def _filled(scores: list[float], **options: Any) -> LevelSampler:
    """A sampler holding seeds 100, 101, ... with ``scores``, in that order (ids 0, 1, ...)."""
    sampler = LevelSampler(len(scores), seed=0, **options)
    for index, score in enumerate(scores):
        assert sampler.insert(100 + index, score) == index
    return sampler


def _weights(sampler: LevelSampler) -> list[float]:
    weights = sampler.weights()
    return [weights[level_id] for level_id in sorted(weights)]


# --- the formulas --------------------------------------------------------------------------------


def test_rank_weights_at_temperature_1() -> None:
    # ranks 3, 1, 2 -> 1/3, 1, 1/2, over 11/6
    sampler = _filled([1.0, 3.0, 2.0], staleness_coeff=0.0)
    assert _weights(sampler) == pytest.approx([2 / 11, 6 / 11, 3 / 11])


def test_rank_weights_at_temperature_half_square_the_rank_weights() -> None:
    # (1/3)^2, 1, (1/2)^2 = 4/36, 36/36, 9/36, over 49/36
    sampler = _filled([1.0, 3.0, 2.0], staleness_coeff=0.0, temperature=0.5)
    assert _weights(sampler) == pytest.approx([4 / 49, 36 / 49, 9 / 49])


def test_equal_scores_rank_in_buffer_order() -> None:
    sampler = _filled([1.0, 1.0], staleness_coeff=0.0)
    assert _weights(sampler) == pytest.approx([2 / 3, 1 / 3])


def test_topk_is_uniform_over_the_k_best() -> None:
    sampler = _filled([1.0, 3.0, 2.0, 0.0], staleness_coeff=0.0, prioritization="topk", k=2)
    assert _weights(sampler) == pytest.approx([0.0, 0.5, 0.5, 0.0])


def test_a_k_beyond_the_buffer_is_uniform() -> None:
    sampler = _filled([1.0, 3.0], staleness_coeff=0.0, prioritization="topk", k=5)
    assert _weights(sampler) == pytest.approx([0.5, 0.5])


def test_staleness_is_mixed_with_the_score_weights() -> None:
    # stamps 1, 2, 3 at episode 3: staleness 2, 1, 0 -> 2/3, 1/3, 0;
    # 0.5 * (2/11, 6/11, 3/11) + 0.5 * (2/3, 1/3, 0) = 28/66, 29/66, 9/66
    sampler = _filled([1.0, 3.0, 2.0], staleness_coeff=0.5)
    assert sampler.episode_count == 3
    assert _weights(sampler) == pytest.approx([28 / 66, 29 / 66, 9 / 66])


def test_staleness_is_uniform_while_all_levels_are_fresh() -> None:
    sampler = _filled([1.0], staleness_coeff=1.0)
    assert sampler.weights() == {0: 1.0}


def test_a_replay_counts_an_episode_and_stamps_its_level() -> None:
    sampler = _filled([1.0, 2.0], staleness_coeff=1.0)  # stamps 1, 2 at episode 2
    assert _weights(sampler) == [1.0, 0.0]
    assert sampler.sample_replay_level() == (0, 100)  # the only level of weight > 0
    assert sampler.episode_count == 3  # level 0 stamped 3, level 1 still 2
    assert _weights(sampler) == [0.0, 1.0]
    assert sampler.sample_replay_level() == (1, 101)


def test_update_sets_the_score_and_not_the_stamp() -> None:
    sampler = _filled([1.0, 2.0], staleness_coeff=0.0)
    sampler.update(0, 5.0)
    assert sampler.score(0) == 5.0
    assert sampler.episode_count == 2
    assert _weights(sampler) == pytest.approx([2 / 3, 1 / 3])


# --- when replays happen, and what the buffer keeps ---------------------------------------------


def test_no_replay_below_the_fill_ratio() -> None:
    sampler = LevelSampler(4, replay_prob=1.0, minimum_fill_ratio=0.5, seed=0)
    assert not sampler.sample_replay_decision()
    sampler.insert(1, 1.0)
    assert not sampler.sample_replay_decision()  # 1/4 < 0.5
    sampler.insert(2, 1.0)
    assert all(sampler.sample_replay_decision() for _ in range(20))  # 2/4


def test_replay_prob_is_the_share_of_replays_once_filled() -> None:
    never = _filled([1.0], replay_prob=0.0)
    assert not any(never.sample_replay_decision() for _ in range(50))
    sometimes = _filled([1.0], replay_prob=0.25)
    replays = sum(sometimes.sample_replay_decision() for _ in range(4000))
    assert 850 < replays < 1150


def test_an_empty_fill_ratio_still_needs_a_level() -> None:
    sampler = LevelSampler(4, replay_prob=1.0, minimum_fill_ratio=0.0, seed=0)
    assert not sampler.sample_replay_decision()
    with pytest.raises(IndexError, match="empty"):
        sampler.sample_replay_level()


def test_a_full_buffer_replaces_its_lowest_weight_level_only_by_a_higher_score() -> None:
    # rank weights 1/3, 2/3 and staleness 1, 0: 0.1 * (1/3, 2/3) + 0.9 * (1, 0) = 0.933, 0.067.
    # Level 1 has the higher score but the lower weight: it is the one a new level must beat.
    sampler = _filled([1.0, 2.0], staleness_coeff=0.9)
    assert _weights(sampler) == pytest.approx([0.1 / 3 + 0.9, 0.2 / 3])
    assert sampler.insert(7, 1.5) is None
    assert sampler.insert(7, 2.0) is None  # equal is not higher
    assert sampler.episode_count == 2  # a refused level counts no episode
    assert sampler.insert(7, 2.5) == 2
    assert sorted(sampler.weights()) == [0, 2]
    assert sampler.level(2) == 7 and sampler.score(2) == 2.5
    with pytest.raises(KeyError, match="level_id 1"):
        sampler.level(1)


def test_ids_are_not_reused_after_a_replacement() -> None:
    sampler = _filled([1.0], staleness_coeff=0.0)
    assert sampler.insert(200, 2.0) == 1
    assert sampler.insert(300, 3.0) == 2
    assert list(sampler.weights()) == [2] and len(sampler) == 1


def test_a_duplicate_updates_the_level_it_matches() -> None:
    sampler = LevelSampler(4, staleness_coeff=0.0, seed=0)
    scene = {"nodes": [{"class": "RigidBody", "properties": {"mass": 1.0, "size": (1, 2)}}]}
    assert sampler.insert(5, 1.0) == 0
    assert sampler.insert(scene, 1.0) == 1
    assert sampler.insert(5, 3.0) == 0
    same_scene = {"nodes": [{"properties": {"size": [1, 2], "mass": 1.0}, "class": "RigidBody"}]}
    assert sampler.insert(same_scene, 2.0) == 1
    assert len(sampler) == 2 and sampler.score(0) == 3.0 and sampler.score(1) == 2.0
    assert sampler.episode_count == 4  # the duplicates were stamped: episodes 3 and 4
    assert sampler.state_dict()["levels"][0]["timestamp"] == 3


def test_without_duplicate_check_equal_levels_are_kept_twice() -> None:
    sampler = LevelSampler(4, duplicate_check=False, seed=0)
    assert [sampler.insert(5, 1.0), sampler.insert(5, 2.0)] == [0, 1]
    assert len(sampler) == 2


def test_the_buffer_keeps_a_copy_of_each_level() -> None:
    sampler = LevelSampler(2, seed=0)
    scene = {"bodies": [1, 2]}
    level_id = sampler.insert(scene, 1.0)
    scene["bodies"].append(3)
    returned = sampler.level(level_id)
    returned["bodies"].append(4)
    assert sampler.level(level_id) == {"bodies": [1, 2]}


# --- determinism and saved state ------------------------------------------------------------------


def _episodes(sampler: LevelSampler, count: int, first_seed: int) -> list[Any]:
    """Run the PLR loop for ``count`` episodes; scores are a function of the level and the step."""
    trace: list[Any] = []
    for step in range(count):
        if sampler.sample_replay_decision():
            level_id, level = sampler.sample_replay_level()
            sampler.update(level_id, (level * 7 + step) % 11 / 10)
            trace.append(("replay", level_id, level))
        else:
            seed = first_seed + step
            trace.append(("new", sampler.insert(seed, seed % 13 / 10)))
    return trace


def _sampler(seed: int | None) -> LevelSampler:
    return LevelSampler(8, replay_prob=0.6, minimum_fill_ratio=0.5, seed=seed)


def test_a_seed_fixes_the_decisions_and_levels() -> None:
    first, second = _episodes(_sampler(3), 200, 0), _episodes(_sampler(3), 200, 0)
    assert first == second
    assert {entry[0] for entry in first} == {"new", "replay"}
    assert _episodes(_sampler(4), 200, 0) != first


def test_robust_is_a_flag_for_the_caller_and_changes_no_draw() -> None:
    robust = LevelSampler(8, replay_prob=0.6, minimum_fill_ratio=0.5, robust=True, seed=3)
    assert robust.robust and not _sampler(3).robust
    assert _episodes(robust, 100, 0) == _episodes(_sampler(3), 100, 0)


def test_a_refused_state_leaves_the_sampler_as_it_was() -> None:
    sampler = _filled([1.0, 2.0])
    state = sampler.state_dict()
    broken = {**state, "levels": [*state["levels"][:1], {**state["levels"][1], "score": "x"}]}
    with pytest.raises(ValueError, match="score"):
        sampler.load_state_dict(broken)
    assert sampler.state_dict() == state


@pytest.mark.parametrize("codec", ["msgpack", "json"])
def test_a_restored_sampler_continues_bit_for_bit(codec: str) -> None:
    original = _sampler(11)
    _episodes(original, 60, 0)
    state = original.state_dict()
    carried = unpack(pack(state)) if codec == "msgpack" else json.loads(json.dumps(state))
    restored = _sampler(None)
    restored.load_state_dict(carried)
    assert restored.weights() == original.weights()
    assert _episodes(restored, 100, 1000) == _episodes(original, 100, 1000)
    assert restored.state_dict() == original.state_dict()


def test_a_state_larger_than_the_capacity_is_refused() -> None:
    state = _filled([1.0, 2.0, 3.0]).state_dict()
    with pytest.raises(ValueError, match="capacity"):
        LevelSampler(2).load_state_dict(state)


# --- scores -------------------------------------------------------------------------------------


def test_positive_value_loss_is_the_mean_positive_advantage() -> None:
    assert positive_value_loss([1.0, -2.0, 3.0, 0.0]) == 1.0  # (1 + 0 + 3 + 0) / 4


def test_max_mc_is_the_mean_regret_against_the_best_return() -> None:
    assert max_mc(10.0, [4.0, 6.0, 8.0]) == 4.0  # (6 + 4 + 2) / 3


def test_learnability_is_p_times_one_minus_p() -> None:
    assert learnability([1, 0, 0, 1, 1]) == pytest.approx(0.24)  # 0.6 * 0.4
    assert learnability([True, False]) == 0.25
    assert learnability([1, 1, 1]) == 0.0


@pytest.mark.parametrize(
    ("score", "values", "name"),
    [
        (positive_value_loss, [], "advantages"),
        (lambda values: max_mc(1.0, values), [], "values"),
        (learnability, [], "successes"),
        (learnability, [1, 0.5], "successes"),
    ],
)
def test_scores_refuse_what_is_not_an_episode(score: Any, values: list[float], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        score(values)


# --- errors -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("options", "name"),
    [
        ({"capacity": 0}, "capacity"),
        ({"capacity": 2.5}, "capacity"),
        ({"replay_prob": 1.5}, "replay_prob"),
        ({"replay_prob": -0.1}, "replay_prob"),
        ({"staleness_coeff": 2}, "staleness_coeff"),
        ({"prioritization": "proportional"}, "prioritization"),
        ({"temperature": 0}, "temperature"),
        ({"k": 0}, "k"),
        ({"minimum_fill_ratio": 1.1}, "minimum_fill_ratio"),
    ],
)
def test_bad_arguments_are_named(options: dict[str, Any], name: str) -> None:
    arguments = {"capacity": 4, **options}
    with pytest.raises(ValueError, match=f"^{name} "):
        LevelSampler(**arguments)


@pytest.mark.parametrize("level", [object(), 2.5j, {1: "a"}, {"a": {1, 2}}, [None, object()]])
def test_a_level_must_be_plain_data(level: Any) -> None:
    with pytest.raises(ValueError, match="level"):
        LevelSampler(4).insert(level, 1.0)


@pytest.mark.parametrize("score", [float("nan"), float("inf"), "high", None])
def test_a_score_must_be_a_finite_number(score: Any) -> None:
    with pytest.raises(ValueError, match="score"):
        LevelSampler(4).insert(1, score)


def test_an_unknown_level_id_is_a_key_error() -> None:
    sampler = _filled([1.0])
    for call in (
        lambda: sampler.update(7, 1.0),
        lambda: sampler.level(7),
        lambda: sampler.score(7),
        lambda: sampler.level("0"),
    ):
        with pytest.raises(KeyError, match="level_id"):
            call()
