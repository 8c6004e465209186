"""A recorded step taken again, where driven agents decided during it (its parts).

While agents decide at their own pace, a server that drives some agents (``rlenv serve
--policy``) lets a step go on when only driven agents are due: their actions are logged as
parts of that step, ``["action", action, frames, true]`` (docs/protocol.md, "Snapshots and
introspection"). A replay's server drives no one, so :func:`take_step` sends each part as a
request of its own (the logged actions, the driven agents' included, and the ticks each part
ran) and merges the answers into the one the recording's client saw:

- the observation holds the agents of the last answer that did not leave, then every agent
  that left during the step, in the order they left;
- an agent that joined during the step has no reward (``None``) where it is still in play at
  the step's end, and a reward of 0.0 where it left during it; the others keep the last
  answer's reward (the driven ones' counts from their last decision, as the server counts it);
- the reward is the sum of those (in that order), the flags the last answer's, and
  ``info["frames"]`` the ticks of every part.

:func:`recorded_steps` cuts a snapshot's events into steps, each its changes, its action, and
the parts that went on after it. The adaptors leave the driven agents out of what a recording
digests (:mod:`rlenv_client.trainer_view`: their observations, and their rewards from the
reward): :func:`driven_agents` names them (as recorded, or else as the parts show them) and
:func:`as_recorded` leaves them out of a replay's results as the adaptors did.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from rlenv.protocol import Hello
from rlenv_client._agents_in_play import answer_reward
from rlenv_client.trainer_view import TrainerView

if TYPE_CHECKING:
    from rlenv_client.base import BaseClient, StepResult

__all__ = ["as_recorded", "driven_agents", "is_part", "recorded_steps", "split_step", "take_step"]


def is_part(event: Sequence[Any]) -> bool:
    """Whether ``event`` is a part of a step that went on (``["action", a, frames, true]``)."""
    return event[0] == "action" and len(event) == 4


def recorded_steps(events: Sequence[Sequence[Any]]) -> list[list[Sequence[Any]]]:
    """A snapshot's events cut into steps: each its changes, then its action and parts.

    Events after the last action (changes no action followed) are left out.
    """
    steps: list[list[Sequence[Any]]] = []
    pending: list[Sequence[Any]] = []
    for event in events:
        if is_part(event) and steps and not pending:
            steps[-1].append(event)
            continue
        pending.append(event)
        if event[0] == "action":
            steps.append(pending)
            pending = []
    return steps


def driven_agents(
    events: Sequence[Sequence[Any]], recorded: Sequence[str] | None
) -> frozenset[str]:
    """The agents a recording's server drove: as it ``recorded`` them, else as its parts show.

    (A recording older than :attr:`~rlenv_client.replay.EpisodeFile.driven` names those that
    decided during a step, the only ones it can.)
    """
    if recorded is not None:
        return frozenset(recorded)
    return frozenset(name for event in events if is_part(event) for name in event[1])


def as_recorded(result: StepResult, hello: Hello, driven: frozenset[str]) -> StepResult:
    """A replayed step's ``result`` as the recording's adaptor saw it, ``driven`` left out.

    As :class:`~rlenv_client.env.RemoteEnv` leaves them out: the observation without theirs,
    the reward the others' sum, and (where every agent plays every answer) the end the others'.
    ``hello`` is the replaying server's, which drives no one.
    """
    if not driven:
        return result
    view = TrainerView(dataclasses.replace(hello, driven=tuple(driven & set(hello.agents))))
    if hello.possible_agents is None:
        return view.result(result)
    observation, _, terminated, truncated, info = result
    kept = {name: value for name, value in observation.items() if name not in driven}
    return kept, answer_reward(info, view.agents), terminated, truncated, info


def split_step(step: Sequence[Sequence[Any]]) -> tuple[list[Sequence[Any]], list[Sequence[Any]]]:
    """A step's changes (``config``, ``set``) and its action events (action, then parts)."""
    changes = [event for event in step if event[0] != "action"]
    actions = [event for event in step if event[0] == "action"]
    return changes, actions


def take_step(client: BaseClient, actions: Sequence[Sequence[Any]]) -> StepResult:
    """Take one recorded step on ``client``: its action, then each part, as requests.

    Returns what the recording's client saw of the step (see the module's docstring).

    Raises:
        ValueError: a step of several parts beside a group of agents (not supported).
    """
    first = client.step(actions[0][1], actions[0][2])
    if len(actions) == 1:
        return first
    answers = [first, *(client.step(part[1], part[2]) for part in actions[1:])]
    return _merged(answers)


def _merged(answers: Sequence[StepResult]) -> StepResult:
    """The one answer a server that drove agents gave for the parts' ``answers``."""
    joined: set[str] = set()  # joined in an earlier part, not gone since
    gone_observations: dict[str, Any] = {}
    gone: dict[str, dict[str, Any]] = {}
    *earlier, last = answers
    for observation, _, _, _, info in earlier:
        for name, outcome in _outcomes(info).items():
            if _left(outcome):
                gone_observations[name] = observation[name]
                gone[name] = {**outcome, "reward": 0.0} if name in joined else outcome
                joined.discard(name)
            elif outcome["reward"] is None:
                joined.add(name)
    observation, _, terminated, truncated, info = last
    staying_observations: dict[str, Any] = {}
    staying: dict[str, dict[str, Any]] = {}
    for name, outcome in _outcomes(info).items():
        if _left(outcome):
            gone_observations[name] = observation[name]
            gone[name] = {**outcome, "reward": 0.0} if name in joined else outcome
        else:
            staying_observations[name] = observation[name]
            staying[name] = {**outcome, "reward": None} if name in joined else outcome
    outcomes = {**staying, **gone}
    reward = sum(o["reward"] for o in outcomes.values() if o["reward"] is not None)
    frames = sum(int(answer[4].get("frames", 0)) for answer in answers)
    merged_info = {**info, "agents": outcomes, "frames": frames}
    return {**staying_observations, **gone_observations}, reward, terminated, truncated, merged_info


def _outcomes(info: Mapping[str, Any]) -> Mapping[str, dict[str, Any]]:
    outcomes = info.get("agents") or {}
    for name, outcome in outcomes.items():
        if "active" in outcome:  # a group's rows would merge row by row: not done yet
            raise ValueError(
                f"a recorded step in which driven agents decided, beside the group of agents "
                f"{name!r}: replaying its parts is not supported (restore its snapshot on a "
                "server instead)"
            )
    return outcomes


def _left(outcome: Mapping[str, Any]) -> bool:
    return bool(outcome["terminated"] or outcome["truncated"])
