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

Where agents come and go, or decide at their own pace (the hello's ``possible_agents``), an
answer holds only some agents, and a Minari dataset holds one space: :func:`create_datasets`
(which ``rlenv dataset create`` calls) writes **one dataset per agent class**, each agent's life
an episode of its class's dataset, in its class's spaces: from its first observation (at the
reset, or the answer it joined in) to its final transition (the answer it left in), one step per
decision: the observation it decided on, the action it took, the reward it earned until its
next decision, and ``terminated`` or ``truncated`` at its end (an agent still in play when a
client's time limit cut the recording: ``truncated`` at its last decision). Its dataset's id is
the one given with the class's name before the version (``hunt/expert-v0``:
``hunt/expert-Hunter-v0`` and ``hunt/expert-Prey-v0``); its episodes follow the recordings, and
in each the order the agents first appeared. Agents the recording's server drove (``rlenv
serve --policy``) are left out, as they were of the recording, and so are agents that left in
the answer they first appeared in (an episode of no step). ``recover_environment()`` gives the
whole environment, every agent in it.
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
from rlenv_client.replay import EpisodeFile, Trajectory, replay
from rlenv_client.trusted_targets import check_target
from rlenv_tools._agent_lives import AgentLife, agent_lives, member_lives

try:
    import minari
    from minari.data_collector import EpisodeBuffer
except ImportError as missing:  # pragma: no cover - the message names the extra
    raise ImportError(
        f"rlenv_tools.datasets needs the minari extra: pip install 'rlenv[minari]' ({missing})"
    ) from None

__all__ = [
    "DATASET_ID_FORM",
    "check_dataset_id",
    "class_dataset_id",
    "create_dataset",
    "create_datasets",
    "environment_spec",
]

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


def class_dataset_id(dataset_id: str, class_name: str) -> str:
    """The id of one agent class's dataset: ``class_name`` before the version.

    ``class_dataset_id("hunt/expert-v0", "Prey")`` is ``"hunt/expert-Prey-v0"``.
    """
    name, _, version = dataset_id.rpartition("-v")
    return f"{name}-{class_name}-v{version}"


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
            an environment whose agents come and go (one dataset per agent class: use
            :func:`create_datasets`), a recording that is no regular file or is too large
            (:func:`~rlenv_client.recordings.read_recording`), or a recorded target that is no
            installed package with neither ``target`` nor ``trust_target``.
    """
    datasets = _create(
        dataset_id,
        directory,
        target,
        trust_target,
        _Metadata(description, algorithm_name, author, author_email, code_permalink),
        report,
        per_class=False,
    )
    return datasets[0]


def create_datasets(
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
) -> list[minari.MinariDataset]:
    """The recordings in ``directory`` as Minari datasets: one, or one per agent class.

    One dataset ``dataset_id`` (as :func:`create_dataset`) where every agent plays every
    answer; where agents come and go or decide at their own pace, one per agent class, named
    by :func:`class_dataset_id`, each agent's life an episode (see the module's docstring).
    The arguments are :func:`create_dataset`'s.

    Raises:
        ValueError: as :func:`create_dataset` (a dataset that exists: none is written).
    """
    return _create(
        dataset_id,
        directory,
        target,
        trust_target,
        _Metadata(description, algorithm_name, author, author_email, code_permalink),
        report,
        per_class=None,
    )


@dataclasses.dataclass(frozen=True)
class _Metadata:
    """What Minari records of who made a dataset, and how."""

    description: str | None
    algorithm_name: str | None
    author: str | None
    author_email: str | None
    code_permalink: str | None


def _create(
    dataset_id: str,
    directory: str | Path,
    target: str | None,
    trust_target: bool,
    metadata: _Metadata,
    report: Callable[[str], None] | None,
    per_class: bool | None,
) -> list[minari.MinariDataset]:
    """Re-simulate the recordings and write their dataset(s).

    ``per_class``: one dataset per agent class (``None``: where agents come and go; ``False``:
    never, refusing such an environment).
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
        hello = client.hello
        if hello.possible_agents is None and not hello.groups:
            buffers = [
                _episode(number, path, episode, client, report)
                for number, (path, episode) in enumerate(zip(paths, episodes, strict=True))
            ]
            described = f"{len(buffers)} episodes of {target}, recorded by rlenv and re-simulated"
            return [_write(dataset_id, buffers, env, metadata, described)]
        if per_class is False:
            _refuse_several_datasets(target, hello)
        return _class_datasets(dataset_id, target, paths, episodes, env, client, metadata)
    finally:
        env.close()


def _write(
    dataset_id: str,
    buffers: list[EpisodeBuffer],
    env: gymnasium.Env,
    metadata: _Metadata,
    described: str,
    spaces: tuple[gymnasium.Space, gymnasium.Space] | None = None,
) -> minari.MinariDataset:
    """One dataset of ``buffers`` (in ``spaces``, observation then action: default, env's)."""
    observation_space, action_space = spaces or (None, None)
    return minari.create_dataset_from_buffers(
        dataset_id,
        buffers,
        env=env,
        description=metadata.description or described,
        algorithm_name=metadata.algorithm_name,
        author=metadata.author,
        author_email=metadata.author_email,
        code_permalink=metadata.code_permalink,
        requirements=_requirements(),
        data_format="hdf5",
        jpeg_encoding=False,
        observation_space=observation_space,
        action_space=action_space,
    )


def _class_datasets(
    dataset_id: str,
    target: str,
    paths: Sequence[Path],
    episodes: Sequence[EpisodeFile],
    env: gymnasium.Env,
    client: Any,
    metadata: _Metadata,
) -> list[minari.MinariDataset]:
    """One dataset per agent class or group, each life an episode (none written if one fails).

    An agent's role is its class (the hello's ``possible_agents``; its name where the
    environment declares none); a group's, its name, its members' lives in its member spaces.
    """
    hello = client.hello
    groups = frozenset(hello.groups)
    classes: dict[str, str] = hello.possible_agents or {name: name for name in hello.agents}
    roles = dict.fromkeys(name if name in groups else classes[name] for name in hello.agents)
    lives: dict[str, list[AgentLife]] = {role: [] for role in roles}
    spaces: dict[str, tuple[gymnasium.Space, gymnasium.Space]] = {}
    for name in hello.agents:
        if name in groups:
            spaces[name] = (hello.groups[name].observation_space, hello.groups[name].action_space)
        else:
            spaces.setdefault(
                classes[name], (hello.observation_space[name], hello.action_space[name])
            )
    for path, episode in zip(paths, episodes, strict=True):
        trajectory = _replayed(path, episode, client)
        for life in agent_lives(trajectory, groups):
            lives[classes[life.name]].append(life)
        for group in groups:
            lives[group] += member_lives(trajectory, group)
    written: list[minari.MinariDataset] = []
    try:
        for cls, each in lives.items():
            if not each:
                continue
            buffers = [
                _buffer(number, life.observations, life.actions, life.rewards, life.ends)
                for number, life in enumerate(each)
            ]
            names = ", ".join(list(dict.fromkeys(life.name for life in each))[:8])
            names += ", ..." if len(each) > 8 else ""
            described = (
                f"{len(buffers)} lives of {cls} agents ({names}) in {len(paths)} episodes of "
                f"{target}, recorded by rlenv and re-simulated"
            )
            written.append(
                _write(
                    class_dataset_id(dataset_id, cls),
                    buffers,
                    env,
                    metadata,
                    described,
                    spaces[cls],
                )
            )
    except BaseException:
        for dataset in written:
            minari.delete_dataset(dataset.id)
        raise
    return written


def _refuse_several_datasets(target: str, hello: Any) -> None:
    """Refuse, in :func:`create_dataset`, an environment that makes one dataset per role."""
    if hello.groups:
        why = f"it has a group of agents ({', '.join(hello.groups)}), whose members' lives"
    else:
        why = (
            f"its agents come and go or decide at their own pace (its possible agents: "
            f"{', '.join(hello.possible_agents)}), and its answers hold only some agents, whose"
        )
    raise ValueError(
        f"{target}: {why} are episodes of their own, and a Minari episode holds one "
        "observation of one space at every step; make one dataset per agent class with "
        "create_datasets (as rlenv dataset create does)"
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


def _replayed(path: Path, episode: EpisodeFile, client: Any) -> Trajectory:
    """Re-simulate one recording and check it: what the replay saw."""
    result = replay(episode, client, keep=True)
    if result.divergence is not None:
        raise ValueError(f"{path} no longer replays: {result.divergence}")
    trajectory = result.trajectory
    assert trajectory is not None  # keep=True
    if not trajectory.actions:
        raise ValueError(f"{path} holds no step")
    return trajectory


def _end_of(episode: EpisodeFile, trajectory: Trajectory) -> tuple[bool, bool]:
    """How a recorded episode ended: as recorded, or as re-simulated for older recordings."""
    if episode.terminated is not None and episode.truncated is not None:
        return episode.terminated, episode.truncated
    terminated = trajectory.terminated
    return terminated, trajectory.truncated or not terminated  # else a time limit cut it


def _episode(
    number: int, path: Path, episode: EpisodeFile, client: Any, report: Callable[[str], None] | None
) -> EpisodeBuffer:
    """Re-simulate one recording, check it, and return it as Minari's episode buffer."""
    trajectory = _replayed(path, episode, client)
    ends = _end_of(episode, trajectory)
    if (episode.terminated is None or episode.truncated is None) and report is not None:
        report(
            f"{path.name} is an older recording, without its end: "
            f"{'terminated' if ends[0] else 'truncated'}, as re-simulated"
        )
    rewards = [float(reward) for reward in trajectory.rewards]
    return _buffer(number, trajectory.observations, trajectory.actions, rewards, ends)


def _buffer(
    number: int,
    observations: Sequence[Any],
    actions: Sequence[Any],
    rewards: Sequence[float],
    ends: tuple[bool, bool],
) -> EpisodeBuffer:
    """Minari's episode buffer: T + 1 ``observations``, T of the rest, ``ends`` at the last."""
    terminated, truncated = ends
    steps = len(actions)
    buffer = EpisodeBuffer(id=number, observations=observations[0])
    for t in range(steps):
        last = t == steps - 1
        buffer = buffer.add_step_data(
            {
                "observation": observations[t + 1],
                "action": actions[t],
                "reward": rewards[t],
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
