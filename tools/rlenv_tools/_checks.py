"""``rlenv check``: run the checks trainers rely on against any rlenv server.

Each check is a small function over a :class:`~rlenv_client.env.RemoteEnv`; :func:`run_checks`
runs them all (one failing does not stop the others) and returns one :class:`CheckResult` per
check, which the command line prints as a pass/fail report. Observations, a map by agent name
with several agents, are compared member by member
(:func:`~rlenv_tools.observations.observation_difference`). Then, with a client of their own
(the environment's releases control first): PettingZoo's ``parallel_api_test``, where
PettingZoo is installed, and the compliance suite when asked.

A check that cannot apply is skipped, with why: SB3's ``check_env`` where Stable-Baselines3 is
not installed, or cannot train the spaces (a multi-agent environment's ``Dict`` actions, say).

Where agents come and go, or decide at their own pace (the hello's ``possible_agents``), an
answer holds only the agents due and those that just left, so the checks follow the agents:
each observation is checked against its own agent's space, and each action holds an entry for
every agent of the last answer ("agents come and go", :func:`_agents_come_and_go`). gymnasium's
``check_env`` runs on ``RemoteEnv``'s fixed slots (zeros for the agents not in an answer), and
``parallel_api_test`` on ``RemoteParallelEnv``, which follows the agents.
The details hold no ANSI colour codes (gymnasium colours its warnings; they are removed).
"""

from __future__ import annotations

import contextlib
import functools
import io
import re
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env

from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv_client._addresses import parse_address
from rlenv_client.env import RemoteEnv
from rlenv_tools.observations import observation_difference

__all__ = ["CheckResult", "run_checks"]

_PETTINGZOO_CYCLES = 50
"""Steps of each of ``parallel_api_test``'s episodes (they are truncated then)."""
_ANSI = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")
"""An ANSI escape sequence (gymnasium's warnings are coloured)."""


@dataclass(frozen=True)
class CheckResult:
    """The outcome of one check: ``status`` is ``"pass"``, ``"fail"`` or ``"skip"``."""

    name: str
    status: str
    detail: str = ""


class _Skip(Exception):
    """The check cannot run here; the message says why."""


def _warnings_of(call: Callable[[], object]) -> str:
    """The distinct warnings ``call()`` raises (colour codes removed), or ``"no warnings"``."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    messages = {_ANSI.sub("", str(w.message)).strip() for w in caught}
    return "; ".join(sorted(messages)) or "no warnings"


def _come_and_go(env: RemoteEnv) -> bool:
    """Whether ``env``'s agents come and go or decide at their own pace (its hello says)."""
    return env.client.hello.possible_agents is not None


def _gymnasium_check_env(env: RemoteEnv) -> str:
    return _warnings_of(lambda: check_env(env, skip_render_check=True))


_COME_AND_GO_STEPS = 200
"""The most steps of the "agents come and go" check's episode."""


def _agents_come_and_go(env: RemoteEnv) -> str:
    """An episode played agent by agent, as the hello's ``possible_agents`` declares them.

    Every answer holds possible agents only, each observation within its agent's space; a
    joined agent's first reward is ``None``; an agent that left is never in an answer again;
    each action holds an entry for the agents of the last answer only.
    """
    possible = env.client.hello.possible_agents or {}
    observation_spaces = cast(spaces.Dict, env.observation_space)  # by agent, here
    action_spaces = cast(spaces.Dict, env.action_space)
    observation, info = env.reset(seed=7)
    seen, gone = set(info["agents"]), set[str]()
    steps = 0
    for steps in range(1, _COME_AND_GO_STEPS + 1):
        _check_agents(observation, info, possible, observation_spaces, gone, seen, steps - 1)
        gone |= {
            name
            for name, flags in info["agents"].items()
            if flags["terminated"] or flags["truncated"]
        }
        seen |= set(info["agents"])
        action = {name: action_spaces[name].sample() for name in info["due"] if name not in gone}
        observation, reward, terminated, truncated, info = env.step(action)
        if type(reward) is not float:
            raise AssertionError(f"step {steps} returned reward {type(reward).__name__}")
        if terminated or truncated:
            break
    _check_agents(observation, info, possible, observation_spaces, gone, seen, steps)
    seen |= set(info["agents"])
    return f"{len(seen)} of {len(possible)} possible agents in {steps} steps, each in its space"


def _check_agents(
    observation: dict[str, Any],
    info: dict[str, Any],
    possible: dict[str, str],
    observation_spaces: spaces.Dict,
    gone: set[str],
    seen: set[str],
    step: int,
) -> None:
    """One answer of :func:`_agents_come_and_go`, agent by agent."""
    where = f"step {step}" if step else "the reset"
    if set(observation) != set(possible) or not set(info["due"]) <= set(info["agents"]):
        raise AssertionError(
            f"at {where}, the observation holds {sorted(observation)} (every possible agent "
            f"expected) and info['due'] {sorted(info['due'])} (some of info['agents'], "
            f"{sorted(info['agents'])})"
        )
    for name in info["agents"]:
        value = observation[name]
        if name not in possible:
            raise AssertionError(f"at {where}, {name!r} is not a possible agent")
        if name in gone:
            raise AssertionError(f"at {where}, {name!r} is back after it left")
        if value not in observation_spaces[name]:
            raise AssertionError(f"at {where}, {name!r}'s observation is outside its space")
        reward = info["agents"][name]["reward"]
        if (reward is None) == (name in seen):
            raise AssertionError(
                f"at {where}, {name!r}'s reward is {reward!r}: None exactly in the answer "
                "where it joined"
            )


def _seeded_reset(env: RemoteEnv) -> str:
    first, _ = env.reset(seed=2024)
    env.step(env.action_space.sample())
    again, _ = env.reset(seed=2024)
    difference = observation_difference(first, again)
    if difference is not None:
        raise AssertionError(f"reset(seed=2024) twice gave different observations, at {difference}")
    return "reset(seed=2024) twice gives the same observation"


def _step_types(env: RemoteEnv) -> str:
    env.reset(seed=1)
    observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
    if type(reward) is not float or type(terminated) is not bool or type(truncated) is not bool:
        raise AssertionError(
            f"step returned reward {type(reward).__name__}, flags "
            f"{type(terminated).__name__}/{type(truncated).__name__}"
        )
    if _come_and_go(env):
        by_agent = cast(spaces.Dict, env.observation_space)
        outside = [name for name, value in observation.items() if value not in by_agent[name]]
        if outside:
            raise AssertionError(
                f"the observations of {outside} after a step are outside their spaces"
            )
    elif observation not in env.observation_space:
        raise AssertionError("the observation after a step is outside the observation space")
    return f"{info['frames']} physics ticks per step"


def _bad_action_refused(env: RemoteEnv) -> str:
    env.reset(seed=3)
    before = env.client.observe()["agent"]
    try:
        env.client.step([[float("nan")] * 3] * 3)
    except RemoteError as error:
        if error.code != ErrorCode.INVALID_ACTION:
            raise AssertionError(f"expected invalid_action, got {error.code}") from None
        difference = observation_difference(before, env.client.observe()["agent"])
        if difference is not None:
            raise AssertionError(
                f"a refused action changed the observation, at {difference}"
            ) from None
        return f"refused with: {error.message}"
    raise AssertionError("a 3x3 NaN action was accepted")


def _render(env: RemoteEnv) -> str:
    frame = env.client.render()
    if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
        raise AssertionError(f"render gave shape {frame.shape} and dtype {frame.dtype}")
    return f"rgb_array frame {frame.shape[1]}x{frame.shape[0]}"


def _sb3_check_env(env: RemoteEnv) -> str:
    problem = _sb3_action_problem(env.action_space) or _sb3_observation_problem(
        env.observation_space
    )
    if problem is not None:
        several = len(env.client.hello.agents) > 1
        raise _Skip(
            f"SB3 cannot train these spaces: {problem}"
            + (
                "; with several agents, train one agent or a team (docs/several-agents.md)"
                if several
                else ""
            )
        )
    try:
        from stable_baselines3.common.env_checker import check_env as sb3_check_env
    except ImportError:
        raise _Skip("stable-baselines3 is not installed (pip install 'rlenv[sb3]')") from None
    return _warnings_of(lambda: sb3_check_env(env, warn=True))


def _sb3_action_problem(space: spaces.Space) -> str | None:
    """Why SB3's algorithms cannot act in ``space``, or ``None`` if they can.

    They take ``Box``, ``Discrete``, ``MultiDiscrete`` (a 1-D ``nvec``) and ``MultiBinary``
    (an int ``n``) actions (``stable_baselines3.common.preprocessing.get_action_dim``), and
    their discrete actions start at 0.
    """
    takes = (
        "(SB3's algorithms take Box, Discrete, MultiDiscrete or MultiBinary actions: "
        "stable_baselines3.common.preprocessing.get_action_dim)"
    )
    if isinstance(space, spaces.Box):
        return None
    if isinstance(space, spaces.MultiBinary):
        return (
            None
            if isinstance(space.n, int | np.integer)
            else f"the action space is a MultiBinary of shape {space.shape} (SB3 takes an int n)"
        )
    if isinstance(space, spaces.Discrete | spaces.MultiDiscrete):
        return _sb3_discrete_problem(space, "action")
    return f"the action space is a {type(space).__name__} {takes}"


def _sb3_observation_problem(space: spaces.Space) -> str | None:
    """Why SB3's policies cannot read ``space``, or ``None`` if they can.

    They read ``Box``, ``Discrete``, ``MultiDiscrete`` and ``MultiBinary`` observations, or a
    ``Dict`` of them, one level deep (``MultiInputPolicy``;
    ``stable_baselines3.common.preprocessing.get_obs_shape``).
    """
    reads = (
        "(SB3's policies read Box, Discrete, MultiDiscrete or MultiBinary observations, "
        "or a Dict of them one level deep: stable_baselines3.common.preprocessing"
        ".get_obs_shape)"
    )
    members = space.spaces.items() if isinstance(space, spaces.Dict) else [(None, space)]
    for key, member in members:
        where = "the observation space" if key is None else f"observation {key!r}"
        if isinstance(member, spaces.Box | spaces.MultiBinary):
            continue
        if isinstance(member, spaces.Discrete | spaces.MultiDiscrete):
            problem = _sb3_discrete_problem(member, "observation", where)
            if problem is not None:
                return problem
            continue
        return f"{where} is a {type(member).__name__} {reads}"
    return None


def _sb3_discrete_problem(
    space: spaces.Discrete | spaces.MultiDiscrete, kind: str, where: str | None = None
) -> str | None:
    """Why SB3 cannot take a (multi-)discrete ``kind`` space: a start not at 0, a 2-D nvec."""
    where = where or f"the {kind} space"
    name = type(space).__name__
    if isinstance(space, spaces.MultiDiscrete) and space.nvec.ndim > 1:
        return f"{where} is a MultiDiscrete of shape {space.shape} (SB3 takes a 1-D nvec)"
    if np.any(np.asarray(space.start) != 0):
        return f"{where} is a {name} starting at {space.start} (SB3's start at 0)"
    return None


def _pettingzoo_api_test(address: str, token: str | None, timeout: float) -> str:
    try:
        from pettingzoo.test import parallel_api_test

        from rlenv_client.pettingzoo import RemoteParallelEnv
    except ImportError:
        raise _Skip("pettingzoo is not installed (pip install 'rlenv[pettingzoo]')") from None
    env = RemoteParallelEnv(address=address, timeout=timeout, token=token)
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # it prints "Passed Parallel API test"
            found = _warnings_of(lambda: parallel_api_test(env, num_cycles=_PETTINGZOO_CYCLES))
    finally:
        env.close()
    return (
        f"agents {', '.join(env.possible_agents)}, episodes of {_PETTINGZOO_CYCLES} cycles: {found}"
    )


CHECKS: list[tuple[str, Callable[[RemoteEnv], str]]] = [
    ("gymnasium check_env", _gymnasium_check_env),
    ("agents come and go", _agents_come_and_go),  # where they do (run_checks)
    ("seeded reset is reproducible", _seeded_reset),
    ("step returns gymnasium types", _step_types),
    ("a bad action is refused and changes nothing", _bad_action_refused),
    ("render", _render),
    ("stable-baselines3 check_env", _sb3_check_env),
]
"""The checks of the environment, in order, each over the one :class:`RemoteEnv`."""


def run_checks(
    target: str, timeout: float = 30.0, compliance: bool = False, token: str | None = None
) -> list[CheckResult]:
    """Run every check against ``target``: ``HOST:PORT`` of a server, or ``MODULE:CLASS``.

    Args:
        target: the server to check.
        timeout: seconds to wait for any answer.
        compliance: also run the hostile-input compliance suite (:func:`rlenv_tools
            .compliance.check_server`); the server must have no other controller.
        token: the server's token, if it requires one.

    Returns:
        One result per check, plus a first "connect" result; if connecting fails, only that.
    """
    is_address = ":" in target and target.rsplit(":", 1)[1].isdigit()
    try:
        env = (
            RemoteEnv(address=target, timeout=timeout, token=token)
            if is_address
            else RemoteEnv(target, timeout=timeout, max_restarts=0, share_server=False)
        )
    except Exception as error:
        return [CheckResult("connect", "fail", f"{type(error).__name__}: {error}")]
    hello = env.client.hello
    results = [
        CheckResult(
            "connect",
            "pass",
            f"{hello.environment}: action space "
            f"{hello.action_space}, observation space {hello.observation_space}",
        )
    ]
    try:
        results += [
            _run(name, functools.partial(check, env))
            for name, check in CHECKS
            if check is not _agents_come_and_go or _come_and_go(env)
        ]
        address = env.client.address
        env.client.close()  # release control: the checks below bring their own clients
        results.append(
            _run(
                "pettingzoo parallel_api_test",
                lambda: _pettingzoo_api_test(address, token, timeout),
            )
        )
        if compliance:
            results.append(_compliance(env, address, token, timeout))
    finally:
        env.close()
    return results


def _run(name: str, check: Callable[[], str]) -> CheckResult:
    """The result of one check: passed (with its detail), skipped or failed (with why)."""
    try:
        return CheckResult(name, "pass", check())
    except _Skip as skip:
        return CheckResult(name, "skip", str(skip))
    except Exception as error:
        return CheckResult(name, "fail", f"{type(error).__name__}: {error}")


def _compliance(env: RemoteEnv, address: str, token: str | None, timeout: float) -> CheckResult:
    from rlenv_tools.compliance import check_server

    host, port = parse_address(address)
    server = env.server
    report = check_server(
        host, port, token=token, timeout=timeout, pid=server.pid if server is not None else None
    )
    detail = report.summary() + "".join(f"\n      - {line}" for line in report.failures)
    return CheckResult(
        "compliance under hostile input", "pass" if report.passed else "fail", detail
    )
