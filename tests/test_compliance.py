"""The compliance suite's contract probes against real servers: passes, skips and failures.

Every server here is a real ``rlenv serve`` subprocess; the environment that breaks the
contract on purpose lives in ``tests/compliance_envs.py``.
"""

from __future__ import annotations

import re
from pathlib import Path

import msgpack
from conftest import Serve

from rlenv.protocol import pack
from rlenv_tools.compliance import check_server
from rlenv_tools.compliance._harness import ReplyTap

TESTS = Path(__file__).parent
TOKEN = "s3cret"


def _probe_names(lines: list[str]) -> list[str]:
    return [line.split(":", 1)[0] for line in lines]


def test_cartpole_keeps_the_contract_with_a_token_and_two_instances(
    serve: Serve, figures: dict[str, str]
) -> None:
    """Every probe runs (CartPole exports World/Physics:gravity; the token is given): none is
    skipped and none fails."""
    server = serve(args=["--token", TOKEN, "--instances", "2"])
    report = check_server(server.host, server.port, token=TOKEN, pid=server.pid, random_frames=30)
    figures["compliance (CartPole x 2, token)"] = report.summary()
    assert report.passed, "\n".join(report.failures)
    assert report.skipped == []
    assert report.controller_steps == report.probes and report.replies_read > 100


def test_probes_that_cannot_apply_are_skipped_not_failed(serve: Serve) -> None:
    """No writable float property (CountingEnvironment exports a bool and an int) and no
    token: those two probes are reported skipped, with why, and the suite passes."""
    server = serve("examples.faulty:CountingEnvironment")
    report = check_server(server.host, server.port, random_frames=20, action=lambda: 0)
    assert report.passed, "\n".join(report.failures)
    assert _probe_names(report.skipped) == ["the token rule", "determinism after sets"]
    assert "no writable float" in report.skipped[1]
    assert "0 failures, 2 skipped; skipped: the token rule: no token" in report.summary()


def test_a_server_that_breaks_the_contract_fails_those_probes_precisely(serve: Serve) -> None:
    """An environment whose episodes depend on how many came before: the set and restore
    probes fail, each naming what it expected and what came back; nothing else fails."""
    server = serve("compliance_envs:DriftingEnvironment", env={"PYTHONPATH": str(TESTS)})
    report = check_server(server.host, server.port, random_frames=20, action=lambda: 0)
    assert not report.passed
    assert _probe_names(report.failures) == ["determinism after sets", "repeated restores"]
    determinism, restores = report.failures
    assert re.match(
        r"determinism after sets: after inspect set /root/Drifting/Agent:gain = 2\.0 then "
        r"reset\(seed=\d+\), the same actions gave another trajectory than before the set, at "
        r"the first observation: expected observation \[(\d+)\.0, 0\.0\], got observation "
        r"\[(\d+)\.0, 0\.0\]; a snapshot taken right after that reset, restored, gave another "
        r"trajectory",
        determinism,
    ), determinism
    assert "the first restore of a snapshot taken after reset(seed=" in restores
    assert "inspect set /root/Drifting/Agent:gain = 2.0" in restores
    assert "the two restores differ from each other, at the first observation" in restores


def test_the_reply_tap_finds_timestamps_and_foreign_ext_types() -> None:
    """The check behind "the server sends no ext type but 1", on frames made here."""
    tap = ReplyTap()
    assert tap.read(pack({"id": 1, "info": {"x": [1.0]}}), "a test") == {
        "id": 1,
        "info": {"x": [1.0]},
    }
    assert tap.unreported() == []
    stamped = msgpack.packb({"id": 2, "info": {"when": msgpack.Timestamp(5)}})
    foreign = msgpack.packb({"id": 3, "info": [msgpack.ExtType(5, b"ab")]})
    tap.read(stamped, "a test")
    tap.read(foreign, "a test")
    tap.read(foreign, "a test")  # each code is reported once
    found = tap.unreported()
    assert [line.split(" (", 1)[0] for line in found] == [
        "the server sent ext type -1",
        "the server sent ext type 5",
    ]
    assert tap.unreported() == [] and tap.frames == 4
