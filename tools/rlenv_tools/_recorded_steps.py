"""A recording as a timeline takes it: its target, its steps, and their observations checked.

:func:`recorded_target` is the target it re-simulates on (the recorded one, checked, unless
given); :func:`recorded_steps` cuts a recording's events into steps (a step's changes, then its
action and the parts that went on after it); :func:`check_digest` compares an observation a
timeline re-simulated with the digest the recording holds for its step (or records it, where
the recording holds none yet).
"""

from __future__ import annotations

from collections.abc import Sequence

from rlenv_client._recorded_parts import recorded_steps as steps_of
from rlenv_client.replay import EpisodeFile, older_settings
from rlenv_client.trusted_targets import check_target
from rlenv_tools._timeline_processes import Events

__all__ = ["check_digest", "recorded_steps", "recorded_target"]


def recorded_target(episode: EpisodeFile, target: str | None, trust_target: bool) -> str:
    """The target to re-simulate ``episode`` on: ``target``, else the recorded one.

    The recorded one is checked (:func:`~rlenv_client.trusted_targets.check_target`) unless
    ``trust_target``.

    Raises:
        ValueError: the recording names no target and none is given.
        UntrustedTargetError: the recorded target is not installed (a ``ValueError``).
    """
    if target is not None:
        return target
    if episode.target is None:
        raise ValueError("the recording names no target: pass target='MODULE:CLASS'")
    if not trust_target:
        check_target(
            episode.target,
            named_by="the episode" if episode.path is None else f"the recording {episode.path}",
            folder=None if episode.path is None else episode.path.parent,
        )
    return episode.target


def recorded_steps(episode: EpisodeFile) -> Events:
    """Each step's events in ``episode``: its changes, its action, then the parts that went on.

    (Parts: where the recording's server let driven agents decide during a step, see
    :mod:`rlenv_client._recorded_parts`.)

    Raises:
        ValueError: the recording's digests are not one more than its actions.
    """
    steps: Events = [list(map(list, step)) for step in steps_of(episode.snapshot["events"])]
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
