"""A recording's steps as a timeline takes them, and their observations checked.

:func:`recorded_steps` cuts a recording's events at each action (a step's changes, then its
action); :func:`check_digest` compares an observation a timeline re-simulated with the digest the
recording holds for its step (or records it, where the recording holds none yet).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from rlenv_client.replay import EpisodeFile, older_settings
from rlenv_tools._timeline_processes import Events

__all__ = ["check_digest", "recorded_steps"]


def recorded_steps(episode: EpisodeFile) -> Events:
    """Each step's events in ``episode``, its action last.

    Raises:
        ValueError: the recording's digests are not one more than its actions, or its
            server drove agents that decided during a step (not supported: a timeline takes
            one action per step).
    """
    if any(event[0] == "action" and len(event) == 4 for event in episode.snapshot["events"]):
        raise ValueError(
            "its server drove agents that decided during a step (rlenv serve --policy, where "
            "agents decide at their own pace): a timeline cannot take those steps yet; restore "
            "its snapshot on a server instead"
        )
    steps: Events = []
    pending: list[list[Any]] = []
    for event in episode.snapshot["events"]:
        pending.append(event)
        if event[0] == "action":
            steps.append(pending)
            pending = []
    if episode.observations and len(episode.observations) != len(steps) + 1:
        raise ValueError(
            f"the recording has {len(episode.observations)} observations for "
            f"{len(steps)} actions (one more expected)"
        )
    return steps


def check_digest(episode: EpisodeFile, agents: Sequence[str], step: int, observed: str) -> None:
    """Check the digest ``observed`` of step ``step``'s re-simulated observation.

    A step the recording holds no digest for yet (the first time through) records it in
    ``episode``. ``agents``: the environment's (its hello's), which say why where a recording
    predates their settings by name (:func:`~rlenv_client.replay.older_settings`).

    Raises:
        RuntimeError: the observation differs from the recording.
    """
    digests = episode.observations
    if step == len(digests):  # not recorded: the first time through records it
        digests.append(observed)
    elif observed != digests[step]:
        why = older_settings(episode.snapshot, agents) or (
            " (the environment depends on something a snapshot does not hold)"
        )
        raise RuntimeError(
            f"step {step}: the re-simulated observation differs from the "
            "recording: its snapshot's settings, generator state and actions "
            f"gave another observation{why}"
        )
