"""Instructions per env-step of 32 CartPoles in process, counted by callgrind: steps, resets, both.

``python benchmarks/step_instructions.py [OTHER_PYTHON ...] [--short N] [--long M] [--modes
MODE ...]`` runs, under ``valgrind --tool=callgrind`` (instruction counts: the same on a loaded
machine as on a quiet one, where timings drift), a process holding 32 CartPoles in a
``LocalClient`` (the host a server runs, without the socket and the codec) that sends ``steps``
requests at repeat_action 4, N and then M of them after a warm-up; the difference of the two
runs' totals, divided by the env-steps between them, is the cost of an env-step without the
start-up. Three kinds of request: ``step`` (CartPole configured not to end, small actions:
never a reset), ``reset`` (every instance reset at every request) and ``mixed`` (random actions,
episodes ending and reset as a vector's do, a 500-step limit: about a reset per 8 env-steps). A
fourth, ``tag``, is a fixed set of several agents: 32 single ``step`` requests of one Tag (the
chaser and both runners acting, small actions) stand for a request of 32 CartPoles. Each
interpreter given (the ``python`` of another checkout's virtual environment) is measured as well
as this one, from a folder of no checkout's; a shell script setting ``PYTHONPATH`` would count
the shell, so for another checkout's code run this script with its ``PYTHONPATH`` instead.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

INSTANCES = 32
ENDLESS = {"world": {"track_limit": 1e9}, "agent": {"angle_limit": 1e9}}
MODES = ("step", "reset", "mixed", "tag")


def worker(mode: str, requests: int) -> None:
    """Send ``requests`` steps requests of ``mode`` to 32 CartPoles, after 10 of warm-up."""
    import numpy as np

    from rlenv_client import LocalClient

    if mode == "tag":
        tag_worker(requests)
        return
    client = LocalClient("examples.cartpole:CartPoleEnvironment", instances=INSTANCES)
    resets = [client.reset_request(seed=i) for i in range(INSTANCES)]
    if mode != "mixed":
        for request in resets:
            request.parts["config"] = ENDLESS
    client.send_batch(resets)
    client.receive_batch()
    rng = np.random.default_rng(0)
    actions = [rng.uniform(-1, 1, (INSTANCES, 1)).astype(np.float32) for _ in range(64)]
    reset = np.zeros(INSTANCES, bool) if mode != "reset" else np.ones(INSTANCES, bool)
    steps = np.zeros(INSTANCES, int)
    for turn in range(10 + requests):
        action = actions[turn % 64] * (0.01 if mode == "step" else 1.0)
        client.send_steps(action, reset if mode != "step" else None, 4)
        answer = client.receive_steps()
        if mode == "mixed":
            steps[:] += 1
            ended = answer.terminated | answer.truncated | (steps >= 500)
            steps[ended] = 0
            reset = ended
        elif mode == "step" and (answer.terminated.any() or answer.truncated.any()):
            raise RuntimeError("a CartPole ended: the step figure would count a reset")


def tag_worker(requests: int) -> None:
    """Send ``INSTANCES`` single steps of one Tag per request, after 10 of warm-up."""
    import numpy as np

    from rlenv_client import LocalClient

    client = LocalClient("examples.tag:TagEnvironment")
    client.reset(seed=0)
    rng = np.random.default_rng(0)
    names = list(client.hello.agents)
    actions = [
        {name: rng.uniform(-0.01, 0.01, 2).astype(np.float32) for name in names} for _ in range(64)
    ]
    for turn in range((10 + requests) * INSTANCES):
        *_, terminated, truncated, _ = client.step(actions[turn % 64], repeat_action=4)
        if terminated or truncated:
            raise RuntimeError("a Tag episode ended: the tag figure would count a reset")


def instructions(python: str, mode: str, requests: int) -> int:
    """The total instructions callgrind counts in one worker process."""
    with tempfile.TemporaryDirectory() as folder:
        out = os.path.join(folder, "callgrind.out")
        subprocess.run(
            [
                "valgrind",
                "--tool=callgrind",
                f"--callgrind-out-file={out}",
                python,
                os.path.abspath(__file__),
                "--worker",
                mode,
                str(requests),
            ],
            check=True,
            capture_output=True,
            cwd=tempfile.gettempdir(),
            env={**os.environ, "PYTHONHASHSEED": "0"},
        )  # the same dicts each run
        with open(out) as counts:
            for line in counts:
                if line.startswith(("summary:", "totals:")):
                    return int(line.split()[1])
    raise RuntimeError("callgrind wrote no total")


def main() -> None:
    """Parse the arguments and count (or be a worker process, with ``--worker``)."""
    if sys.argv[1:2] == ["--worker"]:
        worker(sys.argv[2], int(sys.argv[3]))
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("other_python", nargs="*", help="interpreters of other checkouts")
    parser.add_argument("--short", type=int, default=20, help="requests of the short run")
    parser.add_argument("--long", type=int, default=60, help="requests of the long run")
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    arguments = parser.parse_args()
    env_steps = (arguments.long - arguments.short) * INSTANCES
    print(
        f"instructions per env-step ({INSTANCES} CartPoles, repeat 4): "
        + ", ".join(arguments.modes)
    )
    for python in [sys.executable, *arguments.other_python]:
        figures = [
            (
                instructions(python, mode, arguments.long)
                - instructions(python, mode, arguments.short)
            )
            / env_steps
            for mode in arguments.modes
        ]
        print(python, "  ".join(f"{figure / 1e3:.1f}K" for figure in figures))


if __name__ == "__main__":
    main()
