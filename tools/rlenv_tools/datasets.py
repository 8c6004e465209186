"""Recorded episodes as a Minari dataset (the ``minari`` extra; nothing else imports this).

:func:`create_dataset` re-simulates every recording of a folder (made by
:class:`~rlenv_client.replay.RecordEpisodes`) on a scratch server, checks each observation
against the recorded digest, and writes the episodes as Minari defines them: T+1
observations, T actions, rewards, terminations and truncations, no infos. Observations and
actions are the recording's bit for bit (images are stored losslessly, not as JPEG); the
terminations and truncations are how each episode ended. The dataset's ``env_spec`` makes
``dataset.recover_environment()`` start the same environment (its registered id, such as
``rlenv/CartPole-v1``, or ``rlenv_client.env:RemoteEnv`` with the target), and its
``requirements`` pin rlenv and pymunk to the versions that re-simulated it.

    $ rlenv dataset create cartpole/expert-v0 --from episodes/

An environment whose agents come and go, or decide at their own pace (its hello's
``possible_agents``), is refused: a Minari episode holds one observation in its space at every
step, and such an environment's answers hold only some of its agents (each agent's life would
be an episode of its own, of its class's spaces, which Minari's one space per dataset cannot
hold for agents of several classes).
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium
from gymnasium.envs.registration import EnvSpec

from rlenv.targets import same_target
from rlenv_client.registration import ENVIRONMENTS
from rlenv_client.replay import EpisodeFile, replay
from rlenv_client.trusted_targets import check_target

try:
    import minari
    from minari.data_collector import EpisodeBuffer
except ImportError as missing:  # pragma: no cover - the message names the extra
    raise ImportError(
        f"rlenv_tools.datasets needs the minari extra: pip install 'rlenv[minari]' ({missing})"
    ) from None

__all__ = ["DATASET_ID_FORM", "check_dataset_id", "create_dataset", "environment_spec"]

DATASET_ID_FORM = "ENV/NAME-vN or NAMESPACE/ENV/NAME-vN (for example cartpole/expert-v0)"
"""The form of the dataset ids this module writes, as Minari names its datasets."""
_DATASET_ID = re.compile(r"(?:[-\w]+/)?[-\w]+/[-\w]+?-v\d+")
_ENTRY_POINT = "rlenv_client.env:RemoteEnv"


def check_dataset_id(dataset_id: str) -> None:
    """Refuse a dataset id that is not of Minari's form :data:`DATASET_ID_FORM`.

    Raises:
        ValueError: the id is of another form.
    """
    if not _DATASET_ID.fullmatch(dataset_id):
        raise ValueError(f"dataset id {dataset_id!r} is not of the form {DATASET_ID_FORM}")


def environment_spec(target: str, repeat_action: int | None = None) -> EnvSpec:
    """The gymnasium spec that makes ``target``'s environment: its registered id if it has one.

    Args:
        target: the environment as ``MODULE:CLASS``.
        repeat_action: ticks per step, when the recordings used another than the server's.
    """
    extra = {} if repeat_action is None else {"repeat_action": repeat_action}
    for env_id, registration in ENVIRONMENTS.items():
        if same_target(registration.target, target):  # a checkout's examples.X too
            spec = gymnasium.spec(env_id)
            return dataclasses.replace(spec, kwargs={**spec.kwargs, **extra})
    name = target.rpartition(":")[2] or target
    return EnvSpec(id=f"rlenv/{name}", entry_point=_ENTRY_POINT, kwargs={"target": target, **extra})


def create_dataset(
    dataset_id: str,
    directory: str | Path,
    *,
    target: str | None = None,
    trust_target: bool = False,
    description: str | None = None,
    algorithm_name: str | None = None,
    author: str | None = None,
    author_email: str | None = None,
    code_permalink: str | None = None,
    report: Callable[[str], None] | None = None,
) -> minari.MinariDataset:
    """Turn the recordings in ``directory`` into the Minari dataset ``dataset_id``.

    Args:
        dataset_id: Minari's id, of the form :data:`DATASET_ID_FORM`.
        directory: a folder of ``*.rlenv`` recordings, all of one environment.
        target: ``MODULE:CLASS`` to re-simulate with (default: the recorded one, imported only
            where it is an installed package: :mod:`rlenv_client.trusted_targets`).
        trust_target: import the recorded target whatever it is (it runs its code: only for
            recordings you trust).
        description: what the dataset holds (default: how many episodes of what).
        algorithm_name: what chose the actions (Minari's metadata, like the next three).
        author: who made the dataset.
        author_email: how to reach them.
        code_permalink: a link to the code that made it.
        report: called with a line for each recording whose end had to be derived (recordings
            older than the ``terminated`` and ``truncated`` they now carry).

    Returns:
        The dataset, as :func:`minari.load_dataset` would read it.

    Raises:
        ValueError: a malformed id, an empty folder, recordings of several environments or of
            none, a recording that no longer replays (its step is named), a dataset that exists,
            an environment whose agents come and go (not supported: the message says why),
            a recording that is no regular file or is too large
            (:func:`~rlenv_client.recordings.read_recording`), or a recorded target that is no
            installed package with neither ``target`` nor ``trust_target``.
    """
    check_dataset_id(dataset_id)
    paths = _recordings(Path(directory))
    episodes = [EpisodeFile.load(path) for path in paths]
    if target is None:
        target = _one_target(episodes, Path(directory))
        if not trust_target:
            check_target(target, named_by=f"a recording in {directory}", folder=Path(directory))
    spec = environment_spec(target, _repeat_action(episodes))
    env = gymnasium.make(spec)
    try:
        client = env.unwrapped.client  # type: ignore[attr-defined]
        _check_fixed_agents(target, client.hello.possible_agents)
        buffers = [
            _episode(number, path, episode, client, report)
            for number, (path, episode) in enumerate(zip(paths, episodes, strict=True))
        ]
        return minari.create_dataset_from_buffers(
            dataset_id,
            buffers,
            env=env,
            description=description
            or f"{len(buffers)} episodes of {target}, recorded by rlenv and re-simulated",
            algorithm_name=algorithm_name,
            author=author,
            author_email=author_email,
            code_permalink=code_permalink,
            requirements=_requirements(),
            data_format="hdf5",
            jpeg_encoding=False,
        )
    finally:
        env.close()


def _check_fixed_agents(target: str, possible_agents: dict[str, str] | None) -> None:
    """Refuse an environment whose agents come and go (see the module's docstring)."""
    if possible_agents is None:
        return
    raise ValueError(
        f"{target}'s agents come and go or decide at their own pace (its possible agents: "
        f"{', '.join(possible_agents)}): its answers hold only some agents, and a Minari "
        "episode holds one observation of one space at every step; datasets of such "
        "environments are not supported (record and replay them, or open them as timelines)"
    )


def _recordings(directory: Path) -> list[Path]:
    """The ``*.rlenv`` files of ``directory``, in order."""
    if not directory.is_dir():
        raise ValueError(f"{directory} is not a folder of recordings")
    paths = sorted(directory.glob("*.rlenv"))
    if not paths:
        raise ValueError(
            f"{directory} holds no recordings (*.rlenv files written by RecordEpisodes)"
        )
    return paths


def _one_target(episodes: Sequence[EpisodeFile], directory: Path) -> str:
    """The one environment the recordings name."""
    targets = {episode.target for episode in episodes}
    if None in targets:
        raise ValueError(
            f"a recording in {directory} names no environment (it was made at an "
            f"address); pass the target (--target MODULE:CLASS)"
        )
    if len(targets) > 1:
        raise ValueError(
            f"{directory} holds recordings of several environments: "
            f"{', '.join(sorted(map(str, targets)))}; a dataset holds one"
        )
    return str(targets.pop())


def _repeat_action(episodes: Sequence[EpisodeFile]) -> int | None:
    """The ticks per step every recorded action ran, if they all ran the same."""
    frames = {
        event[2]
        for episode in episodes
        for event in episode.snapshot["events"]
        if event[0] == "action"
    }
    return frames.pop() if len(frames) == 1 else None


def _episode(
    number: int, path: Path, episode: EpisodeFile, client: Any, report: Callable[[str], None] | None
) -> EpisodeBuffer:
    """Re-simulate one recording, check it, and return it as Minari's episode buffer."""
    result = replay(episode, client, keep=True)
    if result.divergence is not None:
        raise ValueError(f"{path} no longer replays: {result.divergence}")
    trajectory = result.trajectory
    assert trajectory is not None  # keep=True
    if not trajectory.actions:
        raise ValueError(f"{path} holds no step")
    terminated, truncated = episode.terminated, episode.truncated
    if terminated is None or truncated is None:
        terminated = trajectory.terminated
        truncated = trajectory.truncated or not terminated  # else a client's time limit cut it
        if report is not None:
            report(
                f"{path.name} is an older recording, without its end: "
                f"{'terminated' if terminated else 'truncated'}, as re-simulated"
            )
    steps = len(trajectory.actions)
    buffer = EpisodeBuffer(id=number, observations=trajectory.observations[0])
    for t in range(steps):
        last = t == steps - 1
        buffer = buffer.add_step_data(
            {
                "observation": trajectory.observations[t + 1],
                "action": trajectory.actions[t],
                "reward": float(trajectory.rewards[t]),
                "terminated": last and terminated,
                "truncated": last and truncated,
                "info": {},
            }
        )
    return buffer


def _requirements() -> list[str]:
    """The packages a re-simulation needs, at the versions that made this one."""
    pins = []
    for name in ("rlenv", "pymunk"):
        try:
            pins.append(f"{name}=={importlib.metadata.version(name)}")
        except importlib.metadata.PackageNotFoundError:  # rlenv run from a checkout
            continue
    return pins
