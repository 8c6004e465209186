"""``rlenv check``: run the checks trainers rely on against any rlenv server.

Each check is a small function over a :class:`~rlenv_client.env.RemoteEnv`; :func:`run_checks`
runs them all (one failing does not stop the others) and returns one :class:`CheckResult` per
check, which the command line prints as a pass/fail report.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from gymnasium.utils.env_checker import check_env

from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv_client.addresses import parse_address
from rlenv_client.env import RemoteEnv

__all__ = ["CheckResult", "run_checks"]


@dataclass(frozen=True)
class CheckResult:
    """The outcome of one check: ``status`` is ``"pass"``, ``"fail"`` or ``"skip"``."""

    name: str
    status: str
    detail: str = ""


def _warnings_of(call: Callable[[], object]) -> str:
    """The distinct warnings ``call()`` raises, joined, or ``"no warnings"``."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    return "; ".join(sorted({str(w.message).strip() for w in caught})) or "no warnings"


def _gymnasium_check_env(env: RemoteEnv) -> str:
    return _warnings_of(lambda: check_env(env, skip_render_check=True))


def _seeded_reset(env: RemoteEnv) -> str:
    first, _ = env.reset(seed=2024)
    env.step(env.action_space.sample())
    again, _ = env.reset(seed=2024)
    if not np.array_equal(np.asarray(first), np.asarray(again)):
        raise AssertionError("reset(seed=2024) twice gave different observations")
    return "reset(seed=2024) twice gives the same observation"


def _step_types(env: RemoteEnv) -> str:
    env.reset(seed=1)
    observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
    if type(reward) is not float or type(terminated) is not bool or type(truncated) is not bool:
        raise AssertionError(f"step returned reward {type(reward).__name__}, flags "
                             f"{type(terminated).__name__}/{type(truncated).__name__}")
    if observation not in env.observation_space:
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
        after = env.client.observe()["agent"]
        if not np.array_equal(np.asarray(before), np.asarray(after)):
            raise AssertionError("a refused action changed the observation") from None
        return f"refused with: {error.message}"
    raise AssertionError("a 3x3 NaN action was accepted")


def _render(env: RemoteEnv) -> str:
    frame = env.client.render()
    if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
        raise AssertionError(f"render gave shape {frame.shape} and dtype {frame.dtype}")
    return f"rgb_array frame {frame.shape[1]}x{frame.shape[0]}"


def _sb3_check_env(env: RemoteEnv) -> str:
    try:
        from stable_baselines3.common.env_checker import check_env as sb3_check_env
    except ImportError:
        raise _Skip("stable-baselines3 is not installed (pip install 'rlenv[sb3]')") from None
    return _warnings_of(lambda: sb3_check_env(env, warn=True))


class _Skip(Exception):
    """The check cannot run here."""


CHECKS: list[tuple[str, Callable[[RemoteEnv], str]]] = [
    ("gymnasium check_env", _gymnasium_check_env),
    ("seeded reset is reproducible", _seeded_reset),
    ("step returns gymnasium types", _step_types),
    ("a bad action is refused and changes nothing", _bad_action_refused),
    ("render", _render),
    ("stable-baselines3 check_env", _sb3_check_env),
]


def run_checks(target: str, timeout: float = 30.0, compliance: bool = False,
               token: str | None = None) -> list[CheckResult]:
    """Run every check against ``target``: ``HOST:PORT`` of a server, or ``MODULE:CLASS``.

    Args:
        target: the server to check.
        timeout: seconds to wait for any answer.
        compliance: also run the hostile-input compliance suite (:func:`rlenv_client
            .compliance.check_server`); the server must have no other controller.
        token: the server's token, if it requires one.

    Returns:
        One result per check, plus a first "connect" result; if connecting fails, only that.
    """
    is_address = ":" in target and target.rsplit(":", 1)[1].isdigit()
    try:
        env = RemoteEnv(address=target, timeout=timeout, token=token) if is_address else \
            RemoteEnv(target, timeout=timeout, max_restarts=0, share_server=False)
    except Exception as error:
        return [CheckResult("connect", "fail", f"{type(error).__name__}: {error}")]
    hello = env.client.hello
    results = [CheckResult("connect", "pass", f"{hello.environment}: action space "
                           f"{hello.action_space}, observation space {hello.observation_space}")]
    try:
        for name, check in CHECKS:
            try:
                results.append(CheckResult(name, "pass", check(env)))
            except _Skip as skip:
                results.append(CheckResult(name, "skip", str(skip)))
            except Exception as error:
                results.append(CheckResult(name, "fail", f"{type(error).__name__}: {error}"))
        if compliance:
            results.append(_compliance(env, token, timeout))
    finally:
        env.close()
    return results


def _compliance(env: RemoteEnv, token: str | None, timeout: float) -> CheckResult:
    from rlenv_client.compliance import check_server

    host, port = parse_address(env.client.address)
    env.client.close()  # release control: the suite brings its own controller
    server = env.server
    report = check_server(host, port, token=token, timeout=timeout,
                          pid=server.pid if server is not None else None)
    detail = report.summary() + "".join(f"\n      - {line}" for line in report.failures)
    return CheckResult("compliance under hostile input", "pass" if report.passed else "fail",
                       detail)
