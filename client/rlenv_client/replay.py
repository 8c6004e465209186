"""Exact replays: record episodes as seed + configuration + actions, re-run them, compare.

An episode file holds the server's snapshot of the episode (its configuration, generator state,
reset options and every action, see :mod:`rlenv.serving._snapshots`), a digest of every
observation the client saw, a digest of every step's reward and flags (agent by agent, with
several agents: :func:`outcome_digest`; recordings made before it lack it), and how the episode
ended (``terminated``, ``truncated``: what the
last step returned, time limits included; recordings made before these two were added lack
them and still load, with ``None``). Replaying restores the start of the episode on a fresh server,
sends the same actions, and compares each observation (and each reward and flag, where
recorded) with the recorded digest: a deterministic environment gives bit-identical answers,
and the first difference is reported. Where agents come and go, an answer's observation holds
the agents of that answer, and so does its digest.

    env = RecordEpisodes(gymnasium.make("rlenv/CartPole-v0"), "episodes/")
    ...                                        # episodes/episode-0001.rlenv, ... as they end
    $ rlenv replay episodes/episode-0001.rlenv
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium

from rlenv.protocol import pack, unpack
from rlenv.protocol.errors import RequestError
from rlenv.protocol.snapshots import parse_snapshot
from rlenv_client._recorded_parts import (
    as_recorded,
    driven_agents,
    recorded_steps,
    split_step,
    take_step,
)
from rlenv_client.recordings import check_frames, read_recording
from rlenv_client.time_limits import truncate_agents

if TYPE_CHECKING:  # only named: base.py's Inspection builds EpisodeFiles
    from rlenv_client.base import BaseClient

__all__ = [
    "EpisodeFile",
    "RecordEpisodes",
    "ReplayResult",
    "Trajectory",
    "apply_change",
    "digest",
    "next_episode_path",
    "outcome_digest",
    "older_settings",
    "replay",
]

_FORMAT = "rlenv-episode"
_VERSION = 1
_NAME = re.compile(r"episode-(\d+)\.rlenv")


def digest(observation: Any) -> str:
    """A short fingerprint of an observation's exact bytes (dtype and shape included)."""
    return hashlib.blake2b(pack(observation), digest_size=16).hexdigest()


def outcome_digest(reward: Any, terminated: Any, truncated: Any, info: Mapping[str, Any]) -> str:
    """A short fingerprint of a step's reward and flags, and each agent's (``info["agents"]``).

    Agents count by name, whatever order the answer listed them in; an agent's reward is
    ``None`` in the answer where it joined.
    """
    agents = info.get("agents") or {}
    by_agent = sorted(((str(name), agents[name]) for name in agents), key=lambda item: item[0])
    return digest([float(reward), bool(terminated), bool(truncated), by_agent])


def next_episode_path(directory: Path) -> Path:
    """``directory/episode-NNNN.rlenv``, numbered after the highest one there."""
    numbers = [
        int(match.group(1)) for path in directory.iterdir() if (match := _NAME.fullmatch(path.name))
    ]
    return directory / f"episode-{max(numbers, default=0) + 1:04d}.rlenv"


@dataclass
class EpisodeFile:
    """One recorded episode: the server snapshot, the digests of what the client saw, its end.

    ``terminated`` and ``truncated`` are ``None`` in recordings older than them. ``agent``
    names the agent a person played, in a demonstration of one agent of several (the
    inspector's Take control); ``None`` otherwise. ``outcomes`` holds each step's
    :func:`outcome_digest` (``None`` in recordings older than it, and where not kept).
    ``driven`` names the agents the recording's server drove (its hello's ``driven``, ``rlenv
    serve --policy``), which the adaptors leave out of their observations and so the digests
    do (``None``: none, or a recording older than it). ``path`` is where :meth:`load` read it.
    """

    target: str | None
    snapshot: dict[str, Any]
    observations: list[str]
    terminated: bool | None = None
    truncated: bool | None = None
    agent: str | None = None
    outcomes: list[str] | None = None
    driven: list[str] | None = None
    path: Path | None = field(default=None, compare=False, repr=False)
    """The file it was read from (``None``: made in this process, or a server's)."""

    def save(self, path: str | Path) -> None:
        """Write the episode to ``path`` (the end only when known: older readers skip it)."""
        data = {
            "format": _FORMAT,
            "version": _VERSION,
            "target": self.target,
            "snapshot": self.snapshot,
            "observations": self.observations,
        }
        if self.terminated is not None and self.truncated is not None:
            data.update(terminated=self.terminated, truncated=self.truncated)
        if self.agent is not None:
            data["agent"] = self.agent
        if self.outcomes is not None:
            data["outcomes"] = self.outcomes
        if self.driven is not None:
            data["driven"] = self.driven
        Path(path).write_bytes(pack(data))

    @classmethod
    def load(cls, path: str | Path) -> EpisodeFile:
        """Read an episode written by :meth:`save`, within bounds.

        Through :func:`~rlenv_client.recordings.read_recording`: a regular file of at most
        64 MiB, each action of at most :data:`~rlenv.protocol.messages.MAX_REPEAT_ACTION`
        ticks, its snapshot of the form a server restores.

        The episode keeps ``path`` (:attr:`path`): the folder it came from counts in whether
        its ``target`` may be imported (:mod:`rlenv_client.trusted_targets`).

        Raises:
            ValueError: the file is not an rlenv episode, not a regular file, or too large.
            OSError: the file cannot be opened.
        """
        raw = read_recording(path)
        try:
            data = unpack(raw)
        except Exception as error:
            raise ValueError(f"{path} is not an rlenv episode: {error}") from None
        if (
            not isinstance(data, dict)
            or data.get("format") != _FORMAT
            or data.get("version") != _VERSION
        ):
            raise ValueError(f"{path} is not an rlenv episode (version {_VERSION})")
        target, observations = data.get("target"), data.get("observations")
        if (
            not (target is None or isinstance(target, str))
            or not isinstance(observations, list)
            or not all(isinstance(seen, str) for seen in observations)
        ):
            raise ValueError(
                f"{path} is not an rlenv episode: its target must be a string and "
                "its observations a list of digests"
            )

        try:
            snapshot = parse_snapshot(data.get("snapshot"))
        except RequestError as error:
            raise ValueError(f"{path} is not an rlenv episode: {error}") from None
        check_frames(snapshot["events"], str(path))
        agent = data.get("agent")
        if not (agent is None or isinstance(agent, str)):
            raise ValueError(f"{path} is not an rlenv episode: its agent must be a name")
        outcomes = data.get("outcomes")
        if outcomes is not None and (
            not isinstance(outcomes, list)
            or not all(isinstance(seen, str) for seen in outcomes)
            or len(outcomes) > len(observations)
        ):
            raise ValueError(
                f"{path} is not an rlenv episode: its outcomes must be a list of digests, "
                "one per step"
            )
        driven = data.get("driven")
        if driven is not None and (
            not isinstance(driven, list) or not all(isinstance(name, str) for name in driven)
        ):
            raise ValueError(f"{path} is not an rlenv episode: its driven must be a list of names")
        return cls(
            target,
            snapshot,
            observations,
            data.get("terminated"),
            data.get("truncated"),
            agent,
            outcomes,
            driven,
            Path(path),
        )


class RecordEpisodes(gymnasium.Wrapper):
    """Write every episode of an rlenv environment to ``directory`` when it ends.

    Args:
        env: a ``gymnasium.make("rlenv/...")`` environment (or a RemoteEnv).
        directory: where the ``episode-NNNN.rlenv`` files go.
    """

    def __init__(self, env: gymnasium.Env, directory: str | Path) -> None:
        super().__init__(env)
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.episodes = 0
        self._observations: list[str] = []
        self._outcomes: list[str] = []

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        """Reset and start recording a new episode."""
        observation, info = self.env.reset(**kwargs)
        self._observations = [digest(_answered(observation, info))]
        self._outcomes = []
        return observation, info

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        """Step, remember the observation's digest, and write the episode when it ends."""
        observation, reward, terminated, truncated, info = self.env.step(action)
        self._observations.append(digest(_answered(observation, info)))
        self._outcomes.append(outcome_digest(reward, terminated, truncated, info))
        if terminated or truncated:
            self.episodes += 1
            remote = self.env.unwrapped
            client: BaseClient = remote.client  # type: ignore[attr-defined]
            target: str | None = remote.target  # type: ignore[attr-defined]
            EpisodeFile(
                target,
                client.snapshot(),
                self._observations,
                bool(terminated),
                bool(truncated),
                outcomes=self._outcomes,
                driven=list(client.hello.driven) or None,
            ).save(self.directory / f"episode-{self.episodes:04d}.rlenv")
        return observation, reward, terminated, truncated, info


@dataclass
class Trajectory:
    """What a replay saw, as gymnasium returned it: ``observations`` has one more than the rest.

    ``terminated`` and ``truncated`` are what the server's last step returned (a client-side
    time limit does not show there). ``agents`` holds each step's ``info["agents"]`` (each agent
    of the answer's reward and flags; ``None`` with one agent).
    """

    observations: list[Any] = field(default_factory=list)
    actions: list[Any] = field(default_factory=list)
    rewards: list[Any] = field(default_factory=list)
    agents: list[Any] = field(default_factory=list)
    terminated: bool = False
    truncated: bool = False


@dataclass(frozen=True)
class ReplayResult:
    """What a replay found: ``divergence`` is ``None`` when every observation matched.

    And every reward and flag, where the recording kept them (``outcomes_checked``).

    ``trajectory`` holds the replayed steps when :func:`replay` was asked to keep them.
    """

    steps: int
    divergence: str | None
    trajectory: Trajectory | None = None
    outcomes_checked: bool = False


def apply_change(client: BaseClient, event: Sequence[Any]) -> None:
    """Make on ``client`` a change a snapshot's events recorded between two actions.

    ``["config", part]`` is a ``configure`` (its ``record`` setting left out: a re-run records
    nothing); ``["set", path, property, value]`` a property set during the episode (an
    inspector's, say).
    """
    if event[0] == "config":
        part = event[1]
        settings = {k: v for k, v in part.get("environment", {}).items() if k != "record"}
        client.configure(agent=part.get("agent"), world=part.get("world"), **settings)
    else:
        client.set_property(*event[1:])


def older_settings(snapshot: Mapping[str, Any], agents: Sequence[str]) -> str:
    """Why a recording of several agents may not replay: it predates their settings by name.

    Before protocol 2.6 a snapshot kept one ``config.agent`` map, the first agent's, and a
    restore gave it to every agent: agents whose settings differed replay with another's.
    Returns that, to add to a divergence's message (``""`` where it does not apply).
    """
    kept = snapshot.get("config", {}).get("agent") or {}
    if len(agents) < 2 or not kept or any(name in kept for name in agents):
        return ""
    return (
        " (the recording predates settings per agent, protocol 2.6: it kept one agent's "
        f"settings, {dict(kept)!r:.60}, which replay on every agent; if the agents' "
        "settings differed, it cannot replay)"
    )


def _answered(observation: Any, info: Mapping[str, Any]) -> Any:
    """The observation of the answer's agents, where agents come and go (``info["due"]``).

    ``RemoteEnv`` fills the slots of the agents not in the answer with zeros; a recording keeps
    what the server answered, which a replay's ``Client`` compares.
    """
    if "due" not in info or not isinstance(observation, Mapping):
        return observation
    return {name: observation[name] for name in info["agents"] if name in observation}


def replay(episode: EpisodeFile, client: BaseClient, *, keep: bool = False) -> ReplayResult:
    """Re-run ``episode`` on ``client``'s environment and compare every observation.

    Args:
        episode: the recording.
        client: a client of a (fresh) server of the recording's environment.
        keep: also return every observation, action and reward (``result.trajectory``).

    A step in which the recording's server let driven agents decide (``rlenv serve
    --policy``, where agents decide at their own pace) is taken part by part, with the
    logged actions, on a server that drives no one, and its answers merged into the one the
    recording saw (:mod:`rlenv_client._recorded_parts`).
    """
    start = {**episode.snapshot, "events": []}
    driven = driven_agents(episode.snapshot["events"], episode.driven)
    hello = client.hello
    observation = as_recorded((client.restore(start)[0], 0.0, False, False, {}), hello, driven)[0]
    expected = iter(episode.observations)
    if digest(observation) != next(expected, None):
        return ReplayResult(
            0,
            "the first observation (after the reset) differs"
            + older_settings(episode.snapshot, client.hello.agents),
        )
    kept = Trajectory([observation]) if keep else None
    outcomes = iter(episode.outcomes or ())
    steps = 0
    for step in recorded_steps(episode.snapshot["events"]):
        changes, actions = split_step(step)
        for change in changes:
            apply_change(client, change)
        steps += 1
        try:
            taken = take_step(client, actions)
        except ValueError as error:  # a step of parts it cannot merge: said, not raised
            return ReplayResult(steps, f"step {steps}: {error}")
        observation, reward, terminated, truncated, info = as_recorded(taken, hello, driven)
        recorded = next(expected, None)
        if recorded is None:
            break
        if digest(observation) != recorded:
            return ReplayResult(
                steps,
                f"step {steps}: the observation differs from the "
                f"recording{older_settings(episode.snapshot, client.hello.agents)}",
            )
        outcome = next(outcomes, None)
        if outcome is not None and not _same_outcome(
            outcome, (reward, terminated, truncated, info), episode, steps
        ):
            return ReplayResult(
                steps,
                f"step {steps}: the reward or flags differ from the recording (of "
                f"{', '.join(map(str, info.get('agents') or {})) or 'the agent'})",
            )
        if kept is not None:
            kept.observations.append(observation)
            kept.actions.append(actions[0][1])
            kept.rewards.append(reward)
            kept.agents.append(info.get("agents"))
            kept.terminated, kept.truncated = bool(terminated), bool(truncated)
    return ReplayResult(steps, None, kept, episode.outcomes is not None)


def _same_outcome(
    recorded: str, answer: tuple[Any, Any, Any, dict[str, Any]], episode: EpisodeFile, step: int
) -> bool:
    """Whether the replayed step's reward and flags are the recorded ones.

    The recording's last step may have been truncated by the client's time limit
    (``max_episode_steps``, or gymnasium's ``TimeLimit``), which the server's answer does not
    show: there (unless the recording says it was not truncated) the replay applies that
    truncation too before it compares.
    """
    reward, terminated, truncated, info = answer
    if outcome_digest(reward, terminated, truncated, info) == recorded:
        return True
    last = step == len(episode.outcomes or ())  # its end unknown (None): may be truncated
    if not last or episode.truncated is False:
        return False
    # rlenv's own time limits truncate each agent too; gymnasium's TimeLimit only the episode
    return recorded in (
        outcome_digest(reward, terminated, True, truncate_agents(info)),
        outcome_digest(reward, terminated, True, info),
    )
