"""PPO on Plinko or Maze with five level curricula, evaluated on held-out levels.

``python benchmarks/curriculum_experiment.py [--env plinko|maze] [--steps S] [--seeds K]
[--envs N] [--methods ...] [--difficulty D] [--out PNG]``

``--env maze`` runs the same experiment on ``rlenv/Maze-v0`` (a partially observed agent looks
for a goal behind walls; MiniGrid's reward, ``1 - 0.9 * steps / 250`` on reaching it), at
difficulty 0.6 by default (31% of the inner cells walled). Its hard levels are 6 hand-made
mazes (:func:`hard_mazes`: a serpentine, a comb of dead ends, two rooms, the goal in a box
whose door faces away, a spiral, a walled corner room) in their 4 quarter turns, as level
data; its upper reference is :class:`BFSExpert`, which sees the level and walks a shortest
path, its lower one a uniformly random discrete policy; the table has the success rate (the
goal reached) beside the return, and the PNG goes to ``docs/images/curriculum-maze.png``. On
the development machine a run makes 900 (the machine shared) to 2,200 Maze env-steps/s with its
evaluations (50,000 env-steps x 5 methods x 3 seeds took 12 minutes), and an evaluation of the
50 held-out seeds takes up to 5 s (an agent that never finds the goal plays 250 steps); ``--env
maze --steps 2000 --seeds 1 --methods dr`` runs end to end in about half a minute.

The rest of this docstring describes the Plinko run (the default).

Optional: needs torch and stable-baselines3 (``make sb3``). Trains Stable-Baselines3's PPO on
``rlenv/Plinko-v0`` (``gymnasium.make_vec`` with ``SAME_STEP`` autoreset, wrapped by
``CurriculumVectorEnv``, adapted by ``SB3VecEnv(vector=...)``) for ``--steps`` env-steps with
each method of ``--methods``, ``--seeds`` training seeds each, one run after the other:

- ``dr``: domain randomisation, a fresh seed every episode (``replay_prob=0``);
- ``plr``: PLR, ``score="external"`` and ``CurriculumCallback(..., "positive_value_loss")``;
- ``robust_plr``: the same with ``LevelSampler(robust=True)`` and
  ``PPO(normalize_advantage=False)``;
- ``accel``: Robust PLR with ``edit_levels=EDITS`` and the ``max_mc`` score;
- ``sfl``: ``score="learnability"``, ``rollouts_per_level=SFL_ROLLOUTS``,
  ``prioritization="topk"``, ``staleness_coeff=0``.

Every run plays at ``world.difficulty = --difficulty`` (0.7 by default: more rows, bouncier
pegs, narrower catcher), configured at every reset through ``EnvironmentParameters``. Every
``--eval-every`` steps and at the end, the policy (deterministic actions) plays the held-out
levels: ``HELD_OUT`` seeds from ``2**32`` on (the wrapper draws training seeds in
``[0, 2**31)``: never trained on), and at the end also ``HARD`` hand-made hard levels (a
held-out seed's level at difficulty 1, 30 server-side edits by ``client.edit_level``, then
every peg at the highest bounciness of ``BOUNCINESS``), each with ``BALLS`` balls. The
hand-written ``follow`` policy (upper reference) and a random policy (lower reference) play
the same levels. Prints a table of the catch rate (mean return: 1 per caught ball) on the
held-out seeds, the hard levels and both, as mean +- std over the training seeds, and writes
the learning curves (held-out catch rate against env-steps, mean over seeds) as a PNG drawn
with numpy (no matplotlib): colours in ``COLOURS``, references dashed.

Time, on the 2-core development machine (8 environments in one server, torch on one thread):
about 1,200 env-steps/s of PPO with the evaluations, so a run of the default 50,000 env-steps
takes ~45 s and the default 5 methods x 3 seeds ~12 minutes (ACCEL's edits cost ~20% more);
``--steps 2000 --seeds 1 --methods dr`` runs end to end in well under a minute.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import torch
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

import rlenv_client  # noqa: F401  (registers rlenv/Plinko-v0 and rlenv/Maze-v0)
from rlenv import PackedScene
from rlenv.examples import maze
from rlenv.examples.plinko import BOUNCINESS, follow
from rlenv_client.curriculum import CurriculumVectorEnv, EnvironmentParameters, LevelSampler
from rlenv_client.sb3 import CurriculumCallback, SB3VecEnv
from rlenv_tools.http._png import encode_png

METHODS = ("dr", "plr", "robust_plr", "accel", "sfl")
ENVS = {"plinko": "rlenv/Plinko-v0", "maze": "rlenv/Maze-v0"}
NAMES = {
    "dr": "DR",
    "plr": "PLR",
    "robust_plr": "Robust PLR",
    "accel": "ACCEL",
    "sfl": "SFL",
    "follow": "follow (upper ref.)",
    "bfs": "BFS expert (upper ref.)",
    "random": "random (lower ref.)",
}
COLOURS = {
    "dr": (0, 0, 0),
    "plr": (31, 119, 180),
    "robust_plr": (44, 160, 44),
    "accel": (214, 39, 40),
    "sfl": (148, 103, 189),
    "follow": (150, 150, 150),
    "bfs": (150, 150, 150),
    "random": (255, 127, 14),
}
"""The curves' colours (RGB): black, blue, green, red, purple; grey (the upper reference,
``follow`` or ``bfs``) and orange dashed."""
HELD_OUT = 50
"""Held-out seeds: 2**32 .. 2**32 + HELD_OUT - 1."""
HELD_OUT_START = 2**32
HARD = 6
"""Hand-made hard levels."""
BALLS = 5
"""Balls (episode seeds) per hard level."""
EDITS = 30
"""Edits of a hard level."""
CAPACITY = 128
"""Every sampler's buffer."""
REPLAY_PROB = 0.5
"""Replay probability of the buffered methods (PLR's Procgen value)."""
ACCEL_EDITS = 2
SFL_K = 32
SFL_ROLLOUTS = 4
"""SFL: how many episodes score a new level's learnability (one outcome's is 0)."""
N_STEPS = 128
"""PPO's rollout length per environment."""

Level = tuple[int, Any]  # (episode seed, level data or None: the seed's own level)
Policy = Callable[[np.ndarray], np.ndarray]


ENV_ID = ENVS["plinko"]
"""The environment trained and evaluated on (``--env`` sets it)."""


def make_vector(num_envs: int, instances_per_server: int | None = None) -> Any:
    return gymnasium.make_vec(
        ENV_ID,
        num_envs=num_envs,
        autoreset_mode=AutoresetMode.SAME_STEP,
        instances_per_server=instances_per_server,
    )


def hard_levels(difficulty: float) -> list[Level]:
    """HARD levels x BALLS balls: held-out seeds' levels at difficulty 1, edited, bouncy."""
    levels: list[Level] = []
    with make_vector(1, 1) as vector:
        client = vector.clients[0]
        client.configure(world={"difficulty": 1.0})
        for number in range(HARD):
            seed = HELD_OUT_START + 10_000 + number
            client.reset(seed=seed)
            data = client.edit_level(client.get_property("World", "level"), seed, n_edits=EDITS)
            pegs = next(child for child in data["root"]["children"] if child["name"] == "Pegs")
            for peg in pegs.get("children", []):
                for shape in peg.get("children", []):
                    if shape["class"] == "CollisionShape":
                        shape.setdefault("properties", {})["elasticity"] = BOUNCINESS[1]
            levels += [(seed + 1000 * ball, data) for ball in range(1, BALLS + 1)]
    del difficulty  # the hard levels carry their own pegs; the world's difficulty still
    return levels  # sets the catcher's width


# -- Maze-v0: hand-made hard mazes and a BFS expert -----------------------------------------

STEPS_PER_CELL = 5
"""Maze-v0 steps to cross one cell (3 m/s for 4 ticks of 1/60 s: a fifth of a cell a step)."""
_MOVES = {(0, 1): 1, (0, -1): 2, (-1, 0): 3, (1, 0): 4}  # cell step -> Maze-v0 action


def _maze_layouts() -> list[tuple[str, set[maze.Cell], maze.Cell, maze.Cell]]:
    """Hand-made hard mazes (name, walls, start, goal) on the 9 x 9 inside (cells 1..9)."""
    every = range(1, 10)
    serpentine = (
        {(c, 2) for c in every if c != 9}
        | {(c, 4) for c in every if c != 1}
        | {(c, 6) for c in every if c != 9}
        | {(c, 8) for c in every if c != 1}
    )
    comb = {(c, r) for c in (2, 4, 6, 8) for r in range(1, 9)}
    two_rooms = {(5, r) for r in range(1, 9)} | {(c, 5) for c in (1, 2, 3, 7, 8, 9)}
    # the goal in a walled box, its door on the far side from the start
    box = (
        {(c, 3) for c in range(3, 8)}
        | {(3, r) for r in range(3, 8)}
        | {(7, r) for r in range(3, 8)}
        | {(c, 7) for c in (3, 4, 6, 7)}
    )
    # a spiral, the goal at its centre
    spiral = (
        {(c, 2) for c in range(2, 9)}
        | {(8, r) for r in range(2, 9)}
        | {(c, 8) for c in range(3, 9)}
        | {(3, r) for r in range(4, 9)}
        | {(c, 4) for c in range(3, 7)}
        | {(6, r) for r in range(4, 7)}
    )
    corner = (
        {(c, 6) for c in range(5, 10) if c != 9}
        | {(5, r) for r in range(6, 10)}
        | {(c, 3) for c in range(2, 10)}
    )
    return [
        ("serpentine", serpentine, (1, 1), (1, 9)),
        ("comb", comb, (1, 1), (9, 1)),
        ("two rooms", two_rooms, (2, 2), (8, 2)),
        ("box", box, (5, 1), (5, 5)),
        ("spiral", spiral, (1, 1), (5, 5)),
        ("corner room", corner, (1, 1), (8, 8)),
    ]


def _rotate(cell: maze.Cell) -> maze.Cell:
    """A quarter turn of the inside about its centre (5, 5)."""
    return (10 - cell[1], cell[0])


def hard_mazes() -> list[Level]:
    """Each hand-made maze in its 4 quarter turns, as level data (episode seeds unused)."""
    levels: list[Level] = []
    for number, (_, walls, start, goal) in enumerate(_maze_layouts()):
        for turn in range(4):
            assert maze.shortest_path(walls, start, goal) is not None
            levels.append(
                (HELD_OUT_START + 20_000 + 4 * number + turn, maze.make_level(walls, start, goal))
            )
            walls, start, goal = {_rotate(c) for c in walls}, _rotate(start), _rotate(goal)
    return levels


def maze_grid(level: Level, difficulty: float) -> tuple[set[maze.Cell], maze.Cell, maze.Cell]:
    """The walls, start and goal of a level: its data's, or the one its seed builds."""
    seed, data = level
    if data is None:
        rng, _ = seeding.np_random(seed)
        data = PackedScene.pack(maze.build_level(rng, difficulty)).to_data()
    return maze.grid_of(data)


class BFSExpert:
    """Sees the level: walks a shortest path cell by cell (STEPS_PER_CELL steps a cell)."""

    def __init__(self, difficulty: float) -> None:
        self.difficulty = difficulty
        self.plans: list[list[int]] = []
        self.t = 0

    def begin(self, batch: Sequence[Level]) -> None:
        self.plans, self.t = [], 0
        for level in batch:
            walls, start, goal = maze_grid(level, self.difficulty)
            path = maze.shortest_path(walls, start, goal) or [start]
            self.plans.append(
                [
                    _MOVES[(b[0] - a[0], b[1] - a[1])]
                    for a, b in zip(path, path[1:], strict=False)
                    for _ in range(STEPS_PER_CELL)
                ]
            )

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        actions = np.array([plan[self.t] if self.t < len(plan) else 0 for plan in self.plans])
        self.t += 1
        return actions


def evaluate(policy: Policy, levels: Sequence[Level], vector: Any, difficulty: float) -> np.ndarray:
    """Each level's return under ``policy``, played ``vector.num_envs`` at a time."""
    returns: list[float] = []
    n = vector.num_envs
    for start in range(0, len(levels), n):
        batch = list(levels[start : start + n])
        for index in range(n):
            seed, data = batch[index] if index < len(batch) else batch[-1]
            vector.set_next_reset(
                index,
                seed=seed,
                options=None if data is None else {"level": data},
                config={"world": {"difficulty": difficulty}},
            )
        if hasattr(policy, "begin"):  # the BFS expert: it sees the levels
            policy.begin([batch[min(index, len(batch) - 1)] for index in range(n)])
        observations, _ = vector.reset()
        done = np.zeros(n, bool)
        total = np.zeros(n)
        while not done.all():
            observations, rewards, terminated, truncated, _ = vector.step(policy(observations))
            total += np.where(done, 0.0, rewards)
            done |= terminated | truncated
        returns += total[: len(batch)].tolist()
    return np.array(returns)


def follow_policy(observations: np.ndarray) -> np.ndarray:
    return np.stack([follow(row) for row in observations])


def random_policy(seed: int) -> Policy:
    rng = np.random.default_rng(seed)
    if ENV_ID == ENVS["maze"]:
        return lambda observations: rng.integers(0, len(maze.ACTIONS), len(observations))
    return lambda observations: rng.uniform(-1.0, 1.0, (len(observations), 1)).astype(np.float32)


class HeldOutCurve(BaseCallback):
    """Evaluates on the held-out seeds every ``every`` env-steps (and at step 0)."""

    def __init__(self, every: int, levels: Sequence[Level], vector: Any, difficulty: float) -> None:
        super().__init__()
        self.every, self.levels, self.vector, self.difficulty = every, levels, vector, difficulty
        self.points: list[tuple[int, float]] = []
        self._next = 0

    def _policy(self, observations: np.ndarray) -> np.ndarray:
        return self.model.predict(observations, deterministic=True)[0]

    def _on_rollout_start(self) -> None:
        if self.num_timesteps >= self._next:
            score = float(evaluate(self._policy, self.levels, self.vector, self.difficulty).mean())
            self.points.append((self.num_timesteps, score))
            self._next += self.every

    def _on_step(self) -> bool:
        return True


def train(
    method: str,
    seed: int,
    steps: int,
    num_envs: int,
    difficulty: float,
    eval_every: int,
    eval_vector: Any,
    held_out: Sequence[Level],
) -> tuple[PPO, list]:
    """One PPO run; returns the model and its held-out curve."""
    vector = make_vector(num_envs)
    parameters = EnvironmentParameters({"difficulty": difficulty}, seed=seed)
    ppo: dict[str, Any] = {}
    score: Any = "external"
    callbacks: list[BaseCallback] = []
    edits = 0
    rollouts = 1
    if method == "dr":
        sampler = LevelSampler(CAPACITY, replay_prob=0.0, seed=seed)
        score = "learnability"
    elif method == "plr":
        sampler = LevelSampler(CAPACITY, replay_prob=REPLAY_PROB, seed=seed)
    elif method in ("robust_plr", "accel"):
        sampler = LevelSampler(CAPACITY, replay_prob=REPLAY_PROB, robust=True, seed=seed)
        ppo["normalize_advantage"] = False
        edits = ACCEL_EDITS if method == "accel" else 0
    elif method == "sfl":
        sampler = LevelSampler(
            CAPACITY,
            replay_prob=REPLAY_PROB,
            prioritization="topk",
            k=SFL_K,
            staleness_coeff=0.0,
            seed=seed,
        )
        score = "learnability"
        rollouts = SFL_ROLLOUTS
    else:
        raise ValueError(f"unknown method {method!r}: one of {', '.join(METHODS)}")
    wrapper = CurriculumVectorEnv(
        vector,
        sampler,
        parameters,
        score,
        seed=seed,
        edit_levels=edits,
        rollouts_per_level=rollouts,
    )
    if score == "external":
        callbacks.append(
            CurriculumCallback(wrapper, "max_mc" if method == "accel" else "positive_value_loss")
        )
    curve = HeldOutCurve(eval_every, held_out, eval_vector, difficulty)
    callbacks.append(curve)
    env = SB3VecEnv(vector=wrapper)
    model = PPO(
        "MlpPolicy", env, n_steps=N_STEPS, batch_size=256, seed=seed, verbose=0, device="cpu", **ppo
    )
    try:
        model.learn(steps, callback=CallbackList(callbacks))
    finally:
        env.close()
    return model, curve.points


# -- the PNG, drawn with numpy -------------------------------------------------------------

WIDTH, HEIGHT, LEFT, RIGHT, TOP, BOTTOM = 800, 500, 60, 20, 20, 50


def _line(
    image: np.ndarray,
    x0: float,
    y0: float,
    x1: float,
    y1: float,
    colour: tuple[int, int, int],
    width: int = 2,
    dash: int = 0,
) -> None:
    count = int(max(abs(x1 - x0), abs(y1 - y0))) + 1
    for step, t in enumerate(np.linspace(0.0, 1.0, count)):
        if dash and (step // dash) % 2:
            continue
        x, y = int(round(x0 + t * (x1 - x0))), int(round(y0 + t * (y1 - y0)))
        image[
            max(y - width // 2, 0) : y + (width + 1) // 2,
            max(x - width // 2, 0) : x + (width + 1) // 2,
        ] = colour


def draw_curves(
    curves: dict[str, list[tuple[int, float]]], references: dict[str, float], steps: int, path: Path
) -> None:
    """Catch rate (0..1, y) against env-steps (0..steps, x): gridlines every 0.1 and every
    tenth of the steps, the axes in black, references as dashed horizontal lines."""
    image = np.full((HEIGHT, WIDTH, 3), 255, np.uint8)
    plot_w, plot_h = WIDTH - LEFT - RIGHT, HEIGHT - TOP - BOTTOM

    def at(step: float, value: float) -> tuple[float, float]:
        return LEFT + plot_w * step / steps, TOP + plot_h * (1.0 - value)

    for tenth in range(11):
        grey = (225, 225, 225) if tenth % 5 else (190, 190, 190)
        _line(image, *at(0, tenth / 10), *at(steps, tenth / 10), grey, 1)
        _line(image, *at(steps * tenth / 10, 0), *at(steps * tenth / 10, 1), grey, 1)
    _line(image, *at(0, 0), *at(steps, 0), (0, 0, 0), 2)
    _line(image, *at(0, 0), *at(0, 1), (0, 0, 0), 2)
    for name, value in references.items():
        _line(image, *at(0, value), *at(steps, value), COLOURS[name], 2, dash=8)
    for name, points in curves.items():
        for (s0, v0), (s1, v1) in zip(points, points[1:], strict=False):
            _line(image, *at(s0, v0), *at(s1, v1), COLOURS[name], 3)
    # the legend: a swatch per method, in METHODS' order, below the x axis
    for number, name in enumerate([*curves, *references]):
        x = LEFT + 20 + number * 100
        image[HEIGHT - 25 : HEIGHT - 10, x : x + 40] = COLOURS[name]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(encode_png(image))


def _cell(values: Sequence[float]) -> str:
    mean = statistics.fmean(values)
    std = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{mean:.3f} ± {std:.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=50_000, help="env-steps per run")
    parser.add_argument("--seeds", type=int, default=3, help="training seeds per method")
    parser.add_argument("--envs", type=int, default=8, help="sub-environments")
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--env", choices=tuple(ENVS), default="plinko")
    parser.add_argument(
        "--difficulty",
        type=float,
        default=None,
        help="world.difficulty (default: 0.7 on plinko, 0.6 on maze)",
    )
    parser.add_argument(
        "--eval-every",
        type=int,
        default=0,
        help="env-steps between held-out evaluations (default: steps / 5)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="the curves' PNG (default: "
        "docs/images/curriculum-experiment.png, or curriculum-maze.png)",
    )
    parser.add_argument("--json", type=Path, default=None, help="also write the results here")
    arguments = parser.parse_args()
    global ENV_ID
    ENV_ID = ENVS[arguments.env]
    is_maze = arguments.env == "maze"
    if arguments.difficulty is None:
        arguments.difficulty = 0.6 if is_maze else 0.7
    if arguments.out is None:
        arguments.out = Path(
            "docs/images/" + ("curriculum-maze.png" if is_maze else "curriculum-experiment.png")
        )
    torch.set_num_threads(1)
    began = time.perf_counter()
    steps, difficulty = arguments.steps, arguments.difficulty
    upper = "bfs" if is_maze else "follow"
    eval_every = arguments.eval_every or max(steps // 5, 1)

    held_out: list[Level] = [(HELD_OUT_START + number, None) for number in range(HELD_OUT)]
    hard = hard_mazes() if is_maze else hard_levels(difficulty)
    results: dict[str, dict[str, list[float]]] = {}
    curves: dict[str, list[list[tuple[int, float]]]] = {}
    with make_vector(arguments.envs) as eval_vector:

        def final(name: str, policy: Policy) -> None:
            row = results.setdefault(
                name,
                {"held_out": [], "hard": [], "all": [], "held_out_success": [], "hard_success": []},
            )
            seeds_returns = evaluate(policy, held_out, eval_vector, difficulty)
            hard_returns = evaluate(policy, hard, eval_vector, difficulty)
            row["held_out"].append(float(seeds_returns.mean()))
            row["hard"].append(float(hard_returns.mean()))
            row["all"].append(float(np.concatenate([seeds_returns, hard_returns]).mean()))
            row["held_out_success"].append(float((seeds_returns > 0).mean()))
            row["hard_success"].append(float((hard_returns > 0).mean()))

        final(upper, BFSExpert(difficulty) if is_maze else follow_policy)
        for seed in range(arguments.seeds):
            final("random", random_policy(seed))
        for method in arguments.methods:
            for seed in range(arguments.seeds):
                started = time.perf_counter()
                model, points = train(
                    method,
                    seed,
                    steps,
                    arguments.envs,
                    difficulty,
                    eval_every,
                    eval_vector,
                    held_out,
                )
                trained = time.perf_counter() - started

                def policy(observations: np.ndarray, model: PPO = model) -> np.ndarray:
                    return model.predict(observations, deterministic=True)[0]

                final(method, policy)
                points.append((model.num_timesteps, results[method]["held_out"][-1]))
                curves.setdefault(method, []).append(points)
                print(
                    f"{NAMES[method]:>11} seed {seed}: {trained:.0f} s, "
                    f"{model.num_timesteps / trained:.0f} env-steps/s (with evaluations), "
                    f"held-out {results[method]['held_out'][-1]:.3f}, "
                    f"hard {results[method]['hard'][-1]:.3f}",
                    flush=True,
                )

    print(
        f"\nPPO on {ENV_ID}, {steps} env-steps per run, {arguments.envs} environments, "
        f"difficulty {difficulty}, {arguments.seeds} seed(s); "
        f"{'return' if is_maze else 'catch rate'}, mean ± std over seeds"
    )
    if is_maze:
        print(
            f"{HELD_OUT} held-out seeds, {len(hard)} hand-made hard mazes "
            f"({len(hard) // 4} x 4 quarter turns); success: the goal reached\n"
        )
        print("| method | held-out return | held-out success | hard return | hard success |")
        print("| --- | --- | --- | --- | --- |")
    else:
        print(f"{HELD_OUT} held-out seeds, {HARD} hard levels x {BALLS} balls\n")
        print("| method | held-out seeds | hard levels | all |")
        print("| --- | --- | --- | --- |")
    for name in [*arguments.methods, upper, "random"]:
        row = results[name]
        if is_maze:
            print(
                f"| {NAMES[name]} | {_cell(row['held_out'])} | "
                f"{_cell(row['held_out_success'])} | {_cell(row['hard'])} | "
                f"{_cell(row['hard_success'])} |"
            )
        else:
            print(
                f"| {NAMES[name]} | {_cell(row['held_out'])} | {_cell(row['hard'])} | "
                f"{_cell(row['all'])} |"
            )
    mean_curves = {}
    for method, runs in curves.items():
        length = min(len(run) for run in runs)
        mean_curves[method] = [
            (int(np.mean([run[i][0] for run in runs])), float(np.mean([run[i][1] for run in runs])))
            for i in range(length)
        ]
    references = {name: statistics.fmean(results[name]["held_out"]) for name in (upper, "random")}
    right = max([steps, *(point[0] for curve in mean_curves.values() for point in curve)])
    draw_curves(mean_curves, references, max(right, 1), arguments.out)
    print(f"\ncurves: {arguments.out}; {time.perf_counter() - began:.0f} s in all")
    if arguments.json:
        arguments.json.write_text(
            json.dumps(
                {
                    "results": results,
                    "curves": curves,
                    "steps": steps,
                    "difficulty": difficulty,
                    "env": ENV_ID,
                },
                indent=1,
            )
        )


if __name__ == "__main__":
    main()
