"""Sample Factory on rlenv: its APPO on the CPU, with gymnasium >= 1.2 kept beside its pins.

    pip install torch==2.13.0            # a CPU torch first, or pip pulls a CUDA build
    pip install sample-factory           # pins gymnasium < 1.0: pip brings 0.29.1
    pip install rlenv                    # after it: gymnasium back to >= 1.2.2 (pip warns)
    python examples/recipes/sample_factory_recipe.py [--smoke] [--rounds R] [--seconds S]

Sample Factory 2.1.1 asks for ``gymnasium<1.0``; under 0.29.1 ``import rlenv_client`` fails
(``cannot import name 'AutoresetMode'``). Installing rlenv after it brings gymnasium back
(pip prints a conflict and goes on), and Sample Factory runs on it. A registered id is a
gymnasium id to its ``register_env``, as in its own ``sf_examples/train_gym_env.py``. Checked:
a short APPO run on the CPU (serial mode: one process) finishes and reports episodes. Then the
figure: its training steps/s (its own "FPS") on ``rlenv/CartPole-v1`` against ``CartPole-v1``,
one run of ``--seconds`` a side a round, in turns.
"""

from __future__ import annotations

import tempfile
import time
from importlib.metadata import version

import gymnasium as gym
from _turns import arguments, contest
from sample_factory.algo.runners.runner import AlgoObserver, Runner
from sample_factory.algo.utils.misc import ExperimentStatus
from sample_factory.cfg.arguments import parse_full_cfg, parse_sf_args
from sample_factory.envs.env_utils import register_env
from sample_factory.train import make_runner

import rlenv_client  # noqa: F401  (registers the rlenv/ ids with gymnasium)

APPO = [
    "--algo=APPO",
    "--device=cpu",
    "--serial_mode=True",
    "--async_rl=False",
    "--num_workers=1",
    "--num_envs_per_worker=4",
    "--worker_num_splits=1",
    "--batch_size=256",
    "--rollout=32",
    "--use_rnn=False",
    "--recurrence=1",
    "--with_vtrace=False",
    "--reward_scale=0.1",
    "--save_every_sec=100000",
    "--restart_behavior=overwrite",
]
"""A small APPO on the CPU, after ``sf_examples/train_gym_env.py``'s CartPole line."""


def make_env(
    full_env_name: str,
    cfg: object = None,
    env_config: object = None,
    render_mode: str | None = None,
) -> gym.Env:
    """Sample Factory's environment function: ``gym.make`` of the id, as its gym example does."""
    return gym.make(full_env_name, render_mode=render_mode)


class Clock(AlgoObserver):
    """Ends training after ``seconds`` (2.1.1's ``--train_for_seconds`` is never counted)."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.start = 0.0

    def on_start(self, runner: Runner) -> None:
        """Training starts now."""
        self.start = time.monotonic()

    def on_training_step(self, runner: Runner, training_iteration_since_resume: int) -> None:
        """The seconds trained so far, where Sample Factory's stopping rule reads them."""
        runner.total_train_seconds = time.monotonic() - self.start


def train(env_id: str, seconds: float) -> Runner:
    """APPO on ``env_id`` for ``seconds`` of training; the finished runner."""
    register_env(env_id, make_env)
    with tempfile.TemporaryDirectory() as folder:
        argv = [f"--env={env_id}", "--experiment=recipe", f"--train_dir={folder}", *APPO]
        argv.append(f"--train_for_seconds={max(1, round(seconds))}")
        parser, _ = parse_sf_args(argv=argv)
        _, runner = make_runner(parse_full_cfg(parser, argv))
        runner.register_observer(Clock(seconds))
        status = runner.init()
        if status == ExperimentStatus.SUCCESS:
            status = runner.run()
    assert status == ExperimentStatus.SUCCESS, f"APPO on {env_id} ended with status {status}"
    return runner


def fps(runner: Runner) -> float:
    """Env-steps per second of training, as Sample Factory's closing "FPS" line counts them."""
    return runner.total_env_steps_since_resume / runner.timing.main_loop


def main() -> None:
    """The check, then the figure."""
    args = arguments(__doc__, smoke_rounds=1)
    gymnasium = tuple(int(part) for part in gym.__version__.split(".")[:2])
    assert gymnasium >= (1, 2), f"gymnasium {gym.__version__}: install rlenv after sample-factory"
    runner = train("rlenv/CartPole-v1", 2.0)
    assert runner.total_env_steps_since_resume > 0
    assert runner.policy_avg_stats["len"][0], "APPO's workers report episodes"
    print(
        f"Sample Factory {version('sample-factory')} APPO on gymnasium {gym.__version__}: "
        f"{runner.total_env_steps_since_resume} env-steps, episodes reported: ok"
    )
    print(
        contest(
            "Sample Factory APPO (serial mode, 4 envs)",
            lambda: fps(train("rlenv/CartPole-v1", args.seconds)),
            lambda: fps(train("CartPole-v1", args.seconds)),
            args.rounds,
        )
    )


if __name__ == "__main__":
    main()
