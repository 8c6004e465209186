"""An agent that fails, recorded to debug with time travel (docs/time-travel.md).

``python -m examples.time_travel [DIR]`` records one CartPole episode of :func:`drifting` into
``DIR`` (default ``episodes/``): the balancing controller with a small bias to the right. It
keeps the pole up, but the cart drifts left until it leaves the track (step 86); then::

    rlenv replay episodes/episode-0001.rlenv --inspect

opens the episode in the inspector's page, to scrub back to before it went wrong, watch it tick by
tick, and branch: with the keys, or with :func:`~examples.cartpole.controller` as a policy
(``python -m examples.time_travel --inspect`` serves the page with it).
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .cartpole import TARGET, controller

__all__ = ["BIAS", "drifting", "main", "record_failure"]

BIAS = 0.01
"""How much further right than the controller :func:`drifting` pushes."""


def drifting(observation: np.ndarray) -> np.ndarray:
    """The balancing controller, pushing :data:`BIAS` too far right: the pole falls."""
    return np.clip(controller(observation) + BIAS, -1.0, 1.0).astype(np.float32)


def record_failure(directory: str | Path, bias: float = BIAS) -> Path:
    """Record one episode (seed 0) of the controller biased by ``bias``; its file."""
    from rlenv_tools.demonstrations import record

    def agent(observation: np.ndarray) -> np.ndarray:
        return np.clip(controller(observation) + bias, -1.0, 1.0).astype(np.float32)

    return record(TARGET, agent, 1, directory, seed=0)[0]


def main(argv: Sequence[str] | None = None) -> int:
    """Record the failure; with ``--inspect``, also serve it in the page (until Ctrl-C).

    The page then offers :func:`~examples.cartpole.controller` as a policy to branch with.
    """
    arguments = list(sys.argv[1:] if argv is None else argv)
    inspect = "--inspect" in arguments
    arguments = [a for a in arguments if a != "--inspect"]
    path = record_failure(arguments[0] if arguments else "episodes")
    print(f"recorded {path}: rlenv replay {path} --inspect", flush=True)
    if inspect:
        from rlenv_tools.inspector import inspect_recordings

        page = inspect_recordings([path], policies={"controller": controller})  # says its URL
        try:
            threading.Event().wait()
        except KeyboardInterrupt:
            pass
        finally:
            page.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
