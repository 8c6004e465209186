"""The compliance suite: check any running rlenv server the way a network service is checked.

:func:`check_server` connects a well-behaved client that controls the environment and steps
between every probe, while hostile connections send what a network service must survive (an
HTTP request, a TLS hello, a 4 GiB length prefix, random frames, invalid msgpack, wrong types,
foreign msgpack ext types, a slow drip); the controller itself sends wrong actions and
out-of-order calls. Every probe must get its error, and the controller must keep stepping (like
dm_env_rpc's ``compliance`` and trio's ``check_two_way_stream``). ``rlenv check HOST:PORT
--compliance`` runs it.

Then the promises of the protocol contract (``docs/protocol.md``), each a probe whose failure
line says what was expected and what came back: a refused request takes no control and, while
the controller holds control, other clients may look and edit (``inspect``) but not step; a set
lasts for its episode, so ``reset(seed)`` and a snapshot replay bit for bit after one; a
snapshot restored twice replays its episode each time; no ext type but 1 travels either way;
the token is checked on the first request, not the first frame. A probe that cannot apply to
the server (no token given, no writable property) is reported skipped, with why.

Here is the public API, :class:`ComplianceReport` and :func:`check_server`, which runs the
probes in a fixed order (the random frames, actions and seeds follow from ``seed``). The rest:

- :mod:`~rlenv_tools.compliance._harness`: what every probe runs in: the controller and the
  state of a run (running a probe, stepping the controller after it), raw connections and
  their frames, and the reply tap that checks every frame the server sends for ext types;
- :mod:`~rlenv_tools.compliance._hostile`: the hostile-input probes: raw frames, malformed
  requests, random frames, a frame cut short, a slow drip, and the refusals the controller
  gets;
- :mod:`~rlenv_tools.compliance._contract`: the contract probes: control, determinism after
  sets, repeated restores, ext types, the token rule, with the trajectories they compare.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rlenv_tools.compliance._contract import ContractProbes
from rlenv_tools.compliance._harness import Harness, ReplyTap, TappedClient, peak_rss_kib
from rlenv_tools.compliance._hostile import HostileProbes

__all__ = ["ComplianceReport", "check_server"]


@dataclass
class ComplianceReport:
    """What :func:`check_server` tried and found.

    Attributes:
        failures: one line per probe that did not get the answer it should have.
        skipped: one line per probe that could not apply to this server, with the reason.
        frames_tried: hostile or malformed frames sent.
        probes: probes run (skipped ones included).
        controller_steps: steps the well-behaved controller took between the probes.
        replies_read: frames from the server that were checked for foreign ext types.
        rss_growth_kib: growth of the server's peak resident memory over the run, when its pid
            was given (Linux only).
    """

    failures: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    frames_tried: int = 0
    probes: int = 0
    controller_steps: int = 0
    replies_read: int = 0
    rss_growth_kib: int | None = None

    @property
    def passed(self) -> bool:
        """Whether every probe got its answer (skipped probes do not count against it)."""
        return not self.failures

    def summary(self) -> str:
        """One line of figures, then the skipped probes and why."""
        memory = (
            ""
            if self.rss_growth_kib is None
            else f", server peak memory grew {self.rss_growth_kib} KiB"
        )
        skipped = f"; skipped: {'; '.join(self.skipped)}" if self.skipped else ""
        return (
            f"{self.probes} probes, {self.frames_tried} malformed frames, "
            f"{self.controller_steps} controller steps, {self.replies_read} replies read, "
            f"{len(self.failures)} failures, {len(self.skipped)} skipped{memory}{skipped}"
        )


def check_server(
    host: str,
    port: int,
    *,
    token: str | None = None,
    pid: int | None = None,
    random_frames: int = 200,
    frame_deadline: float | None = None,
    seed: int = 0,
    timeout: float = 10.0,
    action: Callable[[], Any] | None = None,
) -> ComplianceReport:
    """Run the compliance suite against a running server (which must have no controller).

    Args:
        host: the server's address.
        port: the server's port.
        token: the server's token, if it requires one (the token rule is checked only then).
        pid: the server's process id, to report its memory growth.
        random_frames: how many random frames to send.
        frame_deadline: the server's frame deadline; when given, a slow-drip client checks that
            the server drops it in time (keep it short: the probe waits for it).
        seed: seed of the random frames, actions and episodes.
        timeout: seconds to wait for any answer.
        action: gives the controller's actions between probes; by default samples of the
            action space.

    Returns:
        The report; :attr:`ComplianceReport.passed` says whether the server complied.
    """
    report = ComplianceReport()
    peak_before = peak_rss_kib(pid)
    tap = ReplyTap()
    with TappedClient(
        tap, "the controller", host, port, timeout=timeout, token=token
    ) as controller:
        harness = Harness(
            host, port, token, timeout, controller, report, random.Random(seed), action, tap
        )
        hostile, contract = HostileProbes(harness), ContractProbes(harness)
        # Before the controller's first reset: nobody controls the environment yet.
        harness.run("a refused request takes no control", contract.refused_request_takes_no_control)
        if harness.started:
            for name, probe in [
                *hostile.frame_probes(),
                *contract.ext_type_probes(),
                *hostile.request_probes(random_frames),
                ("the token rule", contract.token_rule),
            ]:
                harness.run(name, probe)
            if frame_deadline is not None:
                harness.run("slow drip", lambda: hostile.slow_drip(frame_deadline))
            for name, probe in [*hostile.controller_probes(), *contract.probes_under_control()]:
                harness.run(name, probe)
        else:
            report.failures.append(
                "the controller could not start an episode: the other "
                "probes need one (does another client control the server?)"
            )
    report.failures.extend(tap.unreported())  # in the frames read after the last check
    report.replies_read = tap.frames
    peak_after = peak_rss_kib(pid)
    if peak_before is not None and peak_after is not None:
        report.rss_growth_kib = peak_after - peak_before
    return report
