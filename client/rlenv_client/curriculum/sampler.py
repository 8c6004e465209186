"""Prioritized level replay: a buffer of scored levels that says which level to play next.

:class:`LevelSampler` follows jaxued's ``LevelSampler`` (PLR, Jiang et al. 2021; Robust PLR,
2021; ACCEL, 2022) in numpy, without a trainer: each call takes and returns plain values, the
sampler keeps its own seeded generator, and :meth:`LevelSampler.state_dict` is plain data that
msgpack and json carry, generator included, so a restored sampler continues bit for bit.

The weights of the levels in the buffer, ranked by score (rank 1 the highest, equal scores in
buffer order):

- ``rank``: ``h_i = (1 / rank_i) ** (1 / temperature)``, normalised to sum to 1;
- ``topk``: 1 for the ``k`` best, 0 for the others, normalised;
- staleness: ``episode_count - timestamp_i``, normalised (uniform while all are 0);
- replay weight: ``(1 - staleness_coeff) * score_weight + staleness_coeff * staleness_weight``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from rlenv_client.curriculum.levels import Level, level_copy, level_key

__all__ = ["PRIORITIZATIONS", "LevelSampler"]

PRIORITIZATIONS = ("rank", "topk")
"""The ways scores become weights: ``(1/rank)^(1/temperature)``, or uniform over the ``k`` best."""


class LevelSampler:
    """A fixed-size buffer of levels and their scores, replayed by score and staleness.

    Each :meth:`insert` and each :meth:`sample_replay_level` counts as an episode: the episode
    count goes up by one and the level is stamped with it. Replays start once the buffer holds
    ``capacity * minimum_fill_ratio`` levels. When the buffer is full, a new level takes the
    place of the level of lowest replay weight only if its score is higher; otherwise it is
    refused (:meth:`insert` returns None and counts no episode).

    The PLR loop, with ``level_id, level`` sent to an environment as its reset options::

        if sampler.sample_replay_decision():
            level_id, level = sampler.sample_replay_level()
            ...                                   # play it, train on it, score it
            sampler.update(level_id, score)
        else:
            level = new_level()                   # a fresh seed or generated scene
            ...                                   # play it, score it; train only if not robust
            sampler.insert(level, score)

    Robust PLR trains only on replayed levels: a new level is played and scored but not learnt
    from. The sampler stores ``robust`` for the caller to read (``if not sampler.robust``); it
    changes nothing in the sampler. ACCEL inserts edited copies of replayed levels the same way
    as new ones.

    Args:
        capacity: how many levels the buffer holds (at least 1).
        replay_prob: the chance that :meth:`sample_replay_decision` says replay, in [0, 1].
        staleness_coeff: the share of staleness in the replay weights, in [0, 1].
        prioritization: ``"rank"`` or ``"topk"``.
        temperature: the rank weights' temperature (> 0); lower favours the best levels more.
        k: how many of the best levels ``"topk"`` replays (at least 1).
        minimum_fill_ratio: the share of ``capacity`` filled before replays start, in [0, 1].
        duplicate_check: inserting a level whose data equal a buffered level's updates that
            level's score and stamp instead of adding a copy.
        robust: Robust PLR; read by the caller, see above.
        seed: the seed of the sampler's generator; None seeds it from the operating system.

    Raises:
        ValueError: an argument out of its range, named in the message.
    """

    def __init__(
        self,
        capacity: int,
        replay_prob: float = 0.95,
        staleness_coeff: float = 0.5,
        prioritization: str = "rank",
        temperature: float = 1.0,
        k: int = 1,
        minimum_fill_ratio: float = 1.0,
        duplicate_check: bool = True,
        robust: bool = False,
        seed: int | None = None,
    ) -> None:
        self.capacity = _count("capacity", capacity)
        self.replay_prob = _unit("replay_prob", replay_prob)
        self.staleness_coeff = _unit("staleness_coeff", staleness_coeff)
        if prioritization not in PRIORITIZATIONS:
            raise ValueError(
                f"prioritization must be one of {PRIORITIZATIONS}, not {prioritization!r}"
            )
        self.prioritization = prioritization
        if isinstance(temperature, bool) or not (
            isinstance(temperature, int | float) and temperature > 0
        ):
            raise ValueError(f"temperature must be a number > 0, not {temperature!r}")
        self.temperature = float(temperature)
        self.k = _count("k", k)
        self.minimum_fill_ratio = _unit("minimum_fill_ratio", minimum_fill_ratio)
        self.duplicate_check = bool(duplicate_check)
        self.robust = bool(robust)
        self._rng = np.random.default_rng(seed)
        self._clear()

    def __len__(self) -> int:
        """How many levels the buffer holds."""
        return self._size

    @property
    def episode_count(self) -> int:
        """How many episodes were counted: successful inserts and replays."""
        return self._episode_count

    def insert(self, level: Level, score: float) -> int | None:
        """Offer a level that was just played, with its score.

        Args:
            level: an int seed, or plain data (a packed scene's data); the buffer keeps a copy.
            score: how much there is to learn on it (see :mod:`rlenv_client.curriculum.scores`).

        Returns:
            The level's id; the id it already had when ``duplicate_check`` found it in the
            buffer; None when the buffer is full and the level's score is not higher than the
            score of the level of lowest weight.

        Raises:
            ValueError: ``level`` is not plain data, or ``score`` is not a finite number.
        """
        data = level_copy(level)
        value = _score(score)
        known = self._ids_by_key.get(level_key(data)) if self.duplicate_check else None
        if known is not None:
            self._scores[self._slots[known]] = value
            self._stamp(self._slots[known])
            return known
        slot = self._size if self._size < self.capacity else int(np.argmin(self._slot_weights()))
        if self._size == self.capacity and not value > self._scores[slot]:
            return None
        self._place(slot, self._next_id, data, value)
        self._stamp(slot)
        self._next_id += 1
        return self._next_id - 1

    def update(self, level_id: int, score: float) -> None:
        """Set the score of a buffered level (after replaying it); its stamp is left as is.

        Raises:
            KeyError: ``level_id`` is not in the buffer.
            ValueError: ``score`` is not a finite number.
        """
        self._scores[self._slot(level_id)] = _score(score)

    def sample_replay_decision(self) -> bool:
        """Whether the next episode replays a buffered level (True) or plays a new one.

        False while the buffer holds fewer than ``capacity * minimum_fill_ratio`` levels (or
        none); then True with probability ``replay_prob``.
        """
        filled = self._size > 0 and self._size / self.capacity >= self.minimum_fill_ratio
        return filled and bool(self._rng.random() < self.replay_prob)

    def sample_replay_level(self) -> tuple[int, Level]:
        """Draw a buffered level by its replay weight, and count the replay as an episode.

        Returns:
            ``(level_id, level)``, the level a copy of the buffered data.

        Raises:
            IndexError: the buffer is empty.
        """
        if self._size == 0:
            raise IndexError("sample_replay_level: the buffer is empty; insert a level first")
        slot = int(self._rng.choice(self._size, p=self._slot_weights()))
        self._stamp(slot)
        return int(self._ids[slot]), level_copy(self._levels[slot])

    def weights(self) -> dict[int, float]:
        """Each buffered level's probability of being drawn by :meth:`sample_replay_level`."""
        weights: np.ndarray | list[float] = self._slot_weights() if self._size else []
        return {
            int(level_id): float(weight)
            for level_id, weight in zip(self._ids[: self._size], weights, strict=True)
        }

    def level(self, level_id: int) -> Level:
        """A copy of a buffered level's data.

        Raises:
            KeyError: ``level_id`` is not in the buffer.
        """
        return level_copy(self._levels[self._slot(level_id)])

    def score(self, level_id: int) -> float:
        """A buffered level's score.

        Raises:
            KeyError: ``level_id`` is not in the buffer.
        """
        return float(self._scores[self._slot(level_id)])

    def state_dict(self) -> dict[str, Any]:
        """The sampler's state as plain data (msgpack carries it; json too if no level has bytes).

        Returns:
            A map of the episode count, the next id, the buffered levels in buffer order (id,
            level, score, stamp) and the generator's state.
        """
        return {
            "episode_count": self._episode_count,
            "next_id": self._next_id,
            "levels": [
                {
                    "id": int(self._ids[slot]),
                    "level": level_copy(self._levels[slot]),
                    "score": float(self._scores[slot]),
                    "timestamp": int(self._timestamps[slot]),
                }
                for slot in range(self._size)
            ],
            "rng": _generator_state(self._rng),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue from a :meth:`state_dict`, into a sampler made with the same arguments.

        Raises:
            ValueError: ``state`` holds more levels than ``capacity``, or a level is not plain
                data.
        """
        entries = state["levels"]
        if len(entries) > self.capacity:
            raise ValueError(
                f"state holds {len(entries)} levels, more than this sampler's "
                f"capacity ({self.capacity})"
            )
        levels = [
            (
                int(entry["id"]),
                level_copy(entry["level"]),
                _score(entry["score"]),
                int(entry["timestamp"]),
            )
            for entry in entries
        ]
        self._rng.bit_generator.state = _generator_state_from(state["rng"])
        self._clear()
        for slot, (level_id, data, score, timestamp) in enumerate(levels):
            self._place(slot, level_id, data, score)
            self._timestamps[slot] = timestamp
        self._episode_count = int(state["episode_count"])
        self._next_id = int(state["next_id"])

    def _clear(self) -> None:
        self._ids = np.full(self.capacity, -1, dtype=np.int64)
        self._levels: list[Level] = [None] * self.capacity
        self._scores = np.zeros(self.capacity, dtype=np.float64)
        self._timestamps = np.zeros(self.capacity, dtype=np.int64)
        self._slots: dict[int, int] = {}
        self._ids_by_key: dict[Any, int] = {}
        self._size = 0
        self._episode_count = 0
        self._next_id = 0

    def _place(self, slot: int, level_id: int, data: Level, score: float) -> None:
        """Put a level in ``slot``, in place of the level there if any."""
        if slot < self._size:
            del self._slots[int(self._ids[slot])]
            if self.duplicate_check:
                del self._ids_by_key[level_key(self._levels[slot])]
        else:
            self._size += 1
        self._ids[slot] = level_id
        self._levels[slot] = data
        self._scores[slot] = score
        self._slots[level_id] = slot
        if self.duplicate_check:
            self._ids_by_key[level_key(data)] = level_id

    def _stamp(self, slot: int) -> None:
        self._episode_count += 1
        self._timestamps[slot] = self._episode_count

    def _slot(self, level_id: int) -> int:
        try:
            return self._slots[level_id]
        except (KeyError, TypeError):
            raise KeyError(f"level_id {level_id!r} is not in the buffer") from None

    def _slot_weights(self) -> np.ndarray:
        """The replay weights of the filled slots, in slot order."""
        staleness = self._episode_count - self._timestamps[: self._size]
        total = staleness.sum()
        staleness_weights = (
            staleness / total if total > 0 else np.full(self._size, 1.0 / self._size)
        )
        return (
            1.0 - self.staleness_coeff
        ) * self._score_weights() + self.staleness_coeff * staleness_weights

    def _score_weights(self) -> np.ndarray:
        ranks = np.empty(self._size, dtype=np.float64)
        ranks[np.argsort(-self._scores[: self._size], kind="stable")] = np.arange(1, self._size + 1)
        if self.prioritization == "rank":
            weights = (1.0 / ranks) ** (1.0 / self.temperature)
        else:
            weights = (ranks <= self.k).astype(np.float64)
        return weights / weights.sum()


def _count(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name} must be an int >= 1, not {value!r}")
    return int(value)


def _unit(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0 <= value <= 1:
        raise ValueError(f"{name} must be a number in [0, 1], not {value!r}")
    return float(value)


def _score(score: Any) -> float:
    try:
        value = float(score)
    except (TypeError, ValueError):
        value = math.nan
    if not math.isfinite(value):
        raise ValueError(f"score must be a finite number, not {score!r:.60}")
    return value


def _generator_state(rng: np.random.Generator) -> dict[str, Any]:
    """The generator's state with its 128-bit integers as decimal strings (msgpack's are 64-bit)."""
    state = rng.bit_generator.state
    return {
        "bit_generator": state["bit_generator"],
        "state": str(state["state"]["state"]),
        "inc": str(state["state"]["inc"]),
        "has_uint32": int(state["has_uint32"]),
        "uinteger": int(state["uinteger"]),
    }


def _generator_state_from(data: dict[str, Any]) -> dict[str, Any]:
    return {
        "bit_generator": data["bit_generator"],
        "state": {"state": int(data["state"]), "inc": int(data["inc"])},
        "has_uint32": int(data["has_uint32"]),
        "uinteger": int(data["uinteger"]),
    }
