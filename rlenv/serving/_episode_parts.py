"""Episodes as data: the ``snapshot``, ``episodes`` and ``restore`` parts.

Records of :data:`rlenv.serving._parts.PARTS`: the episode so far as a snapshot, the last
finished episodes the instance keeps (:mod:`rlenv.serving._recent`), and a snapshot checked
whole, then replayed (its log and format: :mod:`rlenv.serving._snapshots`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from rlenv.protocol.errors import RequestError
from rlenv.serving import _inspector as inspector
from rlenv.serving._actions import check_repeat_action
from rlenv.serving._instance import Episode, Instance, Plan
from rlenv.serving._part_record import Part, as_map, bad
from rlenv.serving._settings import check_keys
from rlenv.serving._snapshots import generator_from_state, parse_snapshot
from rlenv.serving._step_parts import check_options

__all__ = ["Episodes", "Restore", "Snapshot"]


class Snapshot(Part):
    """``{}``: the episode so far as data (see :mod:`rlenv.serving._snapshots`)."""

    name = "snapshot"
    alone = True

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
        if as_map(parts["snapshot"], "snapshot", where):
            raise bad("snapshot takes an empty map")
        _need_lockstep(instance)
        instance.log.check_snapshot()
        if instance.state is Episode.NOT_STARTED:  # stopped by an error
            instance.refuse_without_episode()

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        instance.answer.info = {"snapshot": instance.log.snapshot()}  # type: ignore[union-attr]


class Episodes(Part):
    """The instance's last finished episodes, as snapshots (2.5; by index and in pages, 2.6).

    See :mod:`rlenv.serving._recent`. ``{}`` or ``{"last": n}``: ``info["episodes"]`` lists
    them whole, oldest first, each ``{"snapshot", "terminated", "truncated", "steps"}``.
    ``{"index": true}``: ``info["episodes"]`` lists them without events, each ``{"id",
    "terminated", "truncated", "steps", "events"}``. ``{"episode": id, "from": k}``:
    ``info["episode"]`` is one page of one (``None`` when it is no longer kept). Any form
    starts the keeping (``[]`` until an episode finishes, and always when the server keeps
    none). It takes no control and needs no episode: any client may ask, at any time.
    """

    name = "episodes"
    alone = True
    _KEYS = frozenset({"last", "index", "episode", "from"})

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
        episodes = as_map(parts["episodes"], "episodes", where)
        check_keys(episodes, self._KEYS, "episodes")
        forms = [key for key in ("last", "index", "episode") if key in episodes]
        if len(forms) > 1:
            raise bad(f"episodes takes one of last, index and episode, got {' and '.join(forms)}")
        if "from" in episodes and "episode" not in episodes:
            raise bad("episodes.from goes with episodes.episode (a page of that episode)")
        if "index" in episodes:
            if episodes["index"] is not True:
                raise bad(f"episodes.index must be true, got {episodes['index']!r:.40}")
            return ("index",)
        if "episode" in episodes:
            return ("page", _count(episodes, "episode"), _count(episodes, "from"))
        last = episodes.get("last")
        if last is not None and (type(last) is not int or last < 1):
            raise bad(f"episodes.last must be an integer >= 1, got {last!r:.40}")
        return ("whole", last)

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        recent = instance.recent
        recent.start()
        if value[0] == "index":
            info: dict[str, Any] = {"episodes": recent.index()}
        elif value[0] == "page":
            info = {"episode": recent.page(value[1], value[2])}
        else:
            info = {"episodes": recent.to_wire(value[1])}
        instance.answer.info = info  # type: ignore[union-attr]


def _count(part: Mapping[str, Any], key: str) -> int:
    """``part[key]``, an integer >= 0 (0 if absent)."""
    value = part.get(key, 0)
    if type(value) is not int or value < 0:
        raise bad(f"episodes.{key} must be an integer >= 0, got {value!r:.40}")
    return value


class Restore(Part):
    """A snapshot: check everything in it, then reset and replay it."""

    name = "restore"
    takes_control = True
    alone = True

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
        snapshot = parse_snapshot(as_map(parts["restore"], "restore", where))
        _need_lockstep(instance)
        for config in [snapshot["config"]] + [e[1] for e in snapshot["events"] if e[0] == "config"]:
            settings = config.get("environment")
            if isinstance(settings, Mapping) and settings.get("real_time"):
                raise bad("restore: snapshots replay in lockstep; this one asks for real time")
        instance.settings.check(snapshot["config"], recorded=True)
        if snapshot["options"]:
            check_options(instance, snapshot["options"], "restore: options")
        actions = []
        for index, event in enumerate(snapshot["events"]):
            where = f"restore: events[{index}]: "
            if event[0] == "config":  # checked again when the replay reaches it
                instance.settings.check(event[1], recorded=True)
            elif event[0] == "action":
                check_repeat_action(event[2], f"{where}the action's frames")
                actions.append(
                    instance.checked_action(event[1], fresh=True, replayed=True, where=where)
                )
            elif instance.environment.get_node_or_null(event[1]) is not None:
                # A node the episode builds later is checked when the replay sets it.
                _prefixed(
                    where, inspector.set_property, instance.environment, *event[1:], dry_run=True
                )
        return snapshot, actions, generator_from_state(snapshot["rng"])

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        snapshot, actions, rng = value
        instance.replaying = True
        try:
            instance.settings.configure(snapshot["config"], recorded=True)
            instance.environment.np_random = rng
            instance.begin_episode(None, snapshot["options"])
            checked = iter(actions)
            for index, event in enumerate(snapshot["events"]):
                if event[0] == "config":  # the agents it names may have come since
                    _prefixed(f"restore: events[{index}]: ", instance.settings.check, event[1])
                    instance.settings.configure(event[1])
                elif event[0] == "set":
                    _prefixed(f"restore: events[{index}]: ", instance.set_property, *event[1:])
                else:
                    if instance.state is Episode.ENDED:
                        raise RuntimeError("the snapshot acts after its episode ended")
                    instance.act(next(checked), event[2], goes_on=len(event) == 4)
        except RequestError as error:  # a set the replay refused: the episode is half restored
            instance.abandon_episode("a restore failed part way")
            raise RequestError(error.code, f"{error}; reset required") from None
        finally:
            instance.replaying = False


def _prefixed(where: str, call: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
    """``call``; a refusal it raises names ``where`` first."""
    try:
        call(*args, **kwargs)
    except RequestError as error:
        raise RequestError(error.code, f"{where}{error}") from None


def _need_lockstep(instance: Instance) -> None:
    if instance.tree.real_time:
        raise bad("snapshots need lockstep mode: configure real_time=False first")
