"""The request parts: one record per kind, registered in one table, :data:`PARTS`.

A request is a map of parts (``config``, ``reset``, ``action`` ...). Each kind of part is one
record that says

- whether it **takes control** of the environment (only the controlling client may send it);
- how it is **checked** against an instance, before anything is applied: every part of a
  request is checked first, so a refused request changes nothing;
- how it is **applied**, in the table's order (``config`` before ``reset`` before ``action``...).

Most parts concern one instance (:class:`Part`); ``batch`` and ``steps`` address every instance
of the host at once (:class:`HostPart`) and go alone. To add a kind of request: write its record
here, add it to :data:`PARTS`, and give the client a method that sends it.
"""

from __future__ import annotations

import logging
import traceback
from collections.abc import Callable, Mapping
from typing import Any, ClassVar, Protocol

import numpy as np
from gymnasium import spaces
from gymnasium.vector.utils import iterate

from rlenv.protocol import BatchResponse, ErrorReply, Reply, Request
from rlenv.protocol.codec import DEFAULT_MAX_FRAME_SIZE, pack, unpack
from rlenv.protocol.errors import ErrorCode, RemoteProtocolError, RequestError
from rlenv.protocol.messages import MAX_RENDER_SIZE
from rlenv.protocol.spaces import SpaceMismatch
from rlenv.scene2d.packed_scene import PackedSceneError, check_size
from rlenv.serving import _inspector as inspector
from rlenv.serving._actions import check_repeat_action
from rlenv.serving._columns import Columns
from rlenv.serving._instance import Answer, Episode, Instance, Plan
from rlenv.serving._lean import LeanSteps
from rlenv.serving._settings import check_keys
from rlenv.serving._snapshots import generator_from_state, parse_snapshot
from rlenv.world import MAX_LEVEL_EDITS, RLEnvWorld

__all__ = ["PARTS", "HostPart", "Part", "Shape", "StepsPlan", "dispatch", "plan_for", "shape_of",
           "takes_control"]

logger = logging.getLogger(__name__)

_MAX_LEVEL_SIZE = DEFAULT_MAX_FRAME_SIZE - 4096  # an edited level, with room for its answer
AGENT_ONLY: Mapping[str, Any] = {"agent": {}}
_RUNNING = Episode.RUNNING


def _bad(message: str) -> RequestError:
    return RequestError(ErrorCode.BAD_REQUEST, message)


def _map(value: Any, name: str, where: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise _bad(f"request {where}{name!r} must be a map")
    return value


class Part:
    """One kind of part of a request to one instance.

    Attributes:
        name: the part's key in a request.
        takes_control: whether it changes the environment (only its controller may send it).
        alone: whether it goes alone (with an ``observation`` at most).
    """

    name: ClassVar[str]
    takes_control: ClassVar[bool] = False
    alone: ClassVar[bool] = False

    def controls(self, value: Any) -> bool:
        """Whether this part, with this value, takes control."""
        return self.takes_control

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        """Check the part (``parts[self.name]``) against ``instance``; the value to apply.

        ``fresh`` says whether the request starts an episode first (``reset``, ``restore``).

        Raises:
            RequestError: the refusal, naming the field (prefixed with ``where``).
        """
        raise NotImplementedError

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        """Apply the checked value to ``instance`` (its ``answer`` collects what to report).

        ``request`` is the whole plan (an ``action`` reads its ``repeat_action``).
        """


class Config(Part):
    """``{"environment": {...}, "agent": {...}, "world": {...}}``: settings of each node."""

    name = "config"
    takes_control = True

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        config = _map(parts["config"], "config", where)
        instance.settings.check(config)
        return config

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        instance.settings.configure(value)


class Reset(Part):
    """``{"seed": int >= 0, "options": {...}}``, both optional: start an episode."""

    name = "reset"
    takes_control = True
    _KEYS = frozenset({"seed", "options"})

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        reset = _map(parts["reset"], "reset", where)
        check_keys(reset, self._KEYS, "reset")
        seed, options = reset.get("seed"), reset.get("options")
        if seed is not None and (type(seed) is not int or seed < 0):
            raise _bad(f"reset.seed must be an integer >= 0, got {seed!r:.40}")
        if options is not None and not isinstance(options, Mapping):
            raise _bad("reset.options must be a map")
        if options:
            check_options(instance, options, "reset.options")
        return {"seed": seed, "options": options or {}}

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        instance.begin_episode(value["seed"], value["options"])


def check_options(instance: Instance, options: Mapping[str, Any], where: str) -> None:
    """Refuse (``bad_request``) options the environment does not take, before anything changes.

    An option key the environment does not declare is refused (one that declares none,
    ``reset_options = None``, accepts any); a ``level`` larger than the hello's limits
    (:func:`~rlenv.scene2d.packed_scene.check_size`); then whatever the world's
    :meth:`~rlenv.RLEnvWorld.check_options` refuses (a ``ValueError``).
    """
    environment = instance.environment
    declared = environment.reset_options
    if declared is not None:
        for key in options:
            if key not in declared:
                accepted = ", ".join(map(str, declared)) or "none"
                raise _bad(f"{where}: {type(environment).__name__} has no reset option "
                           f"{str(key)!r:.60}; it accepts {accepted}")
    if "level" in options:
        try:
            check_size(options["level"])
        except PackedSceneError as error:
            raise _bad(f"{where}.level: {error}") from None
    world = environment.world
    if world is not None:
        try:
            world.check_options(options)
        except ValueError as error:  # refused before anything changed: the episode goes on
            raise _bad(f"{where}: {error}") from None


class Action(Part):
    """A member of the action space: run it for ``repeat_action`` ticks."""

    name = "action"
    takes_control = True

    def controls(self, value: Any) -> bool:
        return value is not None  # nil: no action

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        action = parts["action"]
        if action is None:  # nil: no action
            return None
        if not fresh and instance.state is not _RUNNING:
            instance.check_can_act()  # refuses
        return instance.checked_action(action, fresh,
                                       heuristic=frozenset(parts.get("heuristic") or ()))

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        if value is not None:
            instance.act(value, request.get("repeat_action") or
                         instance.environment.repeat_action,
                         request.get("heuristic") or frozenset())
            instance.answer.acted = True  # type: ignore[union-attr]


class Heuristic(Part):
    """Agent names (2.6): in this request's action, they act by their ``RLAgent.heuristic``.

    As for agents the server drives (``rlenv serve --policy NAME=heuristic``), each named agent
    still in the episode gets its heuristic's action for its observation just before the
    action applies, and the episode's log records it; the action has no entry for them. The
    inspector's demonstrations send it: a person plays one agent, the others their heuristic.
    """

    name = "heuristic"

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        names = parts["heuristic"]
        agents = {agent.name: agent for agent in instance.agents}
        if not (isinstance(names, list) and all(isinstance(n, str) for n in names)):
            raise _bad(f"{where}'heuristic' must be a list of agent names")
        if parts.get("action") is None:
            raise _bad(f"{where}'heuristic' given without an 'action'")
        if not instance.multi_agent:
            raise _bad(f"{where}'heuristic' names agents of an action of several; to let a "
                       "lone agent's heuristic play, serve it with --policy NAME=heuristic")
        driven = instance.driven.names if instance.driven is not None else frozenset()
        for name in names:
            agent = agents.get(name)
            if agent is None:
                raise _bad(f"{where}heuristic: no agent {name!r:.40}; the agents: "
                           f"{', '.join(agents)}")
            if not agent.has_heuristic():
                raise _bad(f"{where}heuristic: agent {name!r} (class {type(agent).__name__}) "
                           "has no heuristic")
            if name in driven:
                raise _bad(f"{where}heuristic: agent {name!r} is driven by the server "
                           "already (rlenv serve --policy)")
        return frozenset(names)


class RepeatAction(Part):
    """How many ticks this request's action runs (instead of the configured number)."""

    name = "repeat_action"

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        repeat = check_repeat_action(parts["repeat_action"], f"{where}'repeat_action'")
        if parts.get("action") is None:
            raise _bad(f"{where}'repeat_action' given without an 'action'")
        return repeat


class Observation(Part):
    """``{"agent": {}, "world": {}, "render": {"width", "height"}, "draw": {}}``, any of them."""

    name = "observation"
    _KEYS = frozenset({"agent", "world", "render", "draw"})
    _RENDER_KEYS = frozenset({"width", "height"})

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        observation = parts["observation"]
        if observation.__class__ is not dict:
            observation = _map(observation, "observation", where)
        if not observation.keys() <= self._KEYS:
            check_keys(observation, self._KEYS, "observation")
        for key in ("agent", "world"):
            if key in observation and observation[key].__class__ is not dict:
                _map(observation[key], f"observation.{key}", where)
        if "render" in observation:
            self._check_render(observation["render"])
        if "draw" in observation and _map(observation["draw"], "observation.draw", where):
            raise _bad("observation.draw takes an empty map")
        if instance.state is Episode.NOT_STARTED and not fresh:
            instance.refuse_without_episode()
        return observation

    def _check_render(self, size: Any) -> None:
        if not isinstance(size, Mapping):
            raise _bad("observation.render must be a map")
        check_keys(size, self._RENDER_KEYS, "observation.render")
        for key, value in size.items():
            if type(value) is not int or not 1 <= value <= MAX_RENDER_SIZE:
                raise _bad(f"observation.render.{key} must be an integer in "
                           f"[1, {MAX_RENDER_SIZE}], got {value!r:.40}")

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        instance.send_response(value)


class Snapshot(Part):
    """``{}``: the episode so far as data (see :mod:`rlenv.serving._snapshots`)."""

    name = "snapshot"
    alone = True

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        if _map(parts["snapshot"], "snapshot", where):
            raise _bad("snapshot takes an empty map")
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

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        episodes = _map(parts["episodes"], "episodes", where)
        check_keys(episodes, self._KEYS, "episodes")
        forms = [key for key in ("last", "index", "episode") if key in episodes]
        if len(forms) > 1:
            raise _bad(f"episodes takes one of last, index and episode, got "
                       f"{' and '.join(forms)}")
        if "from" in episodes and "episode" not in episodes:
            raise _bad("episodes.from goes with episodes.episode (a page of that episode)")
        if "index" in episodes:
            if episodes["index"] is not True:
                raise _bad(f"episodes.index must be true, got {episodes['index']!r:.40}")
            return ("index",)
        if "episode" in episodes:
            return ("page", _count(episodes, "episode"), _count(episodes, "from"))
        last = episodes.get("last")
        if last is not None and (type(last) is not int or last < 1):
            raise _bad(f"episodes.last must be an integer >= 1, got {last!r:.40}")
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
        raise _bad(f"episodes.{key} must be an integer >= 0, got {value!r:.40}")
    return value


class Restore(Part):
    """A snapshot: check everything in it, then reset and replay it."""

    name = "restore"
    takes_control = True
    alone = True

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        snapshot = parse_snapshot(_map(parts["restore"], "restore", where))
        _need_lockstep(instance)
        for config in [snapshot["config"]] + [e[1] for e in snapshot["events"] if e[0] == "config"]:
            settings = config.get("environment")
            if isinstance(settings, Mapping) and settings.get("real_time"):
                raise _bad("restore: snapshots replay in lockstep; this one asks for real time")
        instance.settings.check(snapshot["config"])
        if snapshot["options"]:
            check_options(instance, snapshot["options"], "restore: options")
        actions = []
        for index, event in enumerate(snapshot["events"]):
            where = f"restore: events[{index}]: "
            if event[0] == "config":
                instance.settings.check(event[1])
            elif event[0] == "action":
                check_repeat_action(event[2], f"{where}the action's frames")
                actions.append(instance.checked_action(event[1], fresh=True, replayed=True,
                                                       where=where))
            elif instance.environment.get_node_or_null(event[1]) is not None:
                # A node the episode builds later is checked when the replay sets it.
                _prefixed(where, inspector.set_property, instance.environment, *event[1:],
                          dry_run=True)
        return snapshot, actions, generator_from_state(snapshot["rng"])

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        snapshot, actions, rng = value
        instance.replaying = True
        try:
            instance.settings.configure(snapshot["config"])
            instance.environment.np_random = rng
            instance.begin_episode(None, snapshot["options"])
            checked = iter(actions)
            for index, event in enumerate(snapshot["events"]):
                if event[0] == "config":
                    instance.settings.configure(event[1])
                elif event[0] == "set":
                    _prefixed(f"restore: events[{index}]: ", instance.set_property, *event[1:])
                else:
                    if instance.state is Episode.ENDED:
                        raise RuntimeError("the snapshot acts after its episode ended")
                    instance.act(next(checked), event[2])
        except RequestError as error:  # a set the replay refused: the episode is half restored
            instance.abandon_episode("a restore failed part way")
            raise RequestError(error.code, f"{error}; reset required") from None
        finally:
            instance.replaying = False


class EditLevel(Part):
    """``{"level": data or int, "seed": int >= 0, "n_edits": 1..64}``: a level, edited.

    The world's ``_edit_level`` hook (:meth:`rlenv.RLEnvWorld._edit_level`) edits the level
    with a generator seeded by ``seed``, so the same request gives the same level. It is built
    from the request's data, not from the live tree: nothing of the environment changes, with
    or without an episode. The request is checked whole first (its fields, the world's hook, a
    level beyond the hello's limits: its nodes, their depth); the edit is made when it is
    applied, once control was granted: it takes control (2.6), as an edit holds the server's
    loop as long as it builds, so an observer's is answered ``busy`` before it costs anything.
    A hook that refuses or raises leaves the episode alone; the answer's ``info["level"]``
    holds the edited data, as it travels.
    """

    name = "edit_level"
    takes_control = True
    alone = True
    _KEYS = frozenset({"level", "seed", "n_edits"})

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        edit = _map(parts["edit_level"], "edit_level", where)
        check_keys(edit, self._KEYS, "edit_level")
        if "level" not in edit:
            raise _bad("edit_level needs a 'level' (a level's data or an int seed)")
        seed, n_edits = edit.get("seed"), edit.get("n_edits", 1)
        if type(seed) is not int or seed < 0:
            raise _bad(f"edit_level.seed must be an integer >= 0, got {seed!r:.40}")
        if type(n_edits) is not int or not 1 <= n_edits <= MAX_LEVEL_EDITS:
            raise _bad(f"edit_level.n_edits must be an integer in [1, {MAX_LEVEL_EDITS}], "
                       f"got {n_edits!r:.40}")
        world: RLEnvWorld = instance.environment.world  # type: ignore[assignment]  # has one
        if type(world)._edit_level is RLEnvWorld._edit_level:
            raise _bad(f"edit_level: {type(world).__name__} has no _edit_level: "
                       f"{type(instance.environment).__name__} offers no edits of its levels")
        try:
            check_size(edit["level"])
        except PackedSceneError as error:
            raise _bad(f"edit_level.level: {error}") from None
        return edit["level"], seed, n_edits

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        level, seed, n_edits = value
        world: RLEnvWorld = instance.environment.world  # type: ignore[assignment]  # has one
        hook = f"{type(world).__name__}._edit_level"
        try:
            edited = world._edit_level(level, np.random.default_rng(seed), n_edits)
        except RequestError:
            raise
        except ValueError as error:
            raise _bad(f"edit_level: {hook} refused the level: {error}") from None
        except Exception as error:  # user code raised: nothing changed, the episode goes on
            logger.error("%s raised", hook, exc_info=error)
            detail = "".join(traceback.format_exception(error)).rstrip()
            raise RequestError(ErrorCode.ENVIRONMENT_ERROR,
                               f"{hook} raised {type(error).__name__}: {error}; nothing "
                               f"changed\n{detail}") from None
        instance.answer.info = {"level": _travelled(edited, hook)}  # type: ignore[union-attr]


def _travelled(level: Any, hook: str) -> Any:
    """``level`` as it arrives on the other end (plain msgpack data, checked and bounded).

    Raises:
        RequestError: ``environment_error``: ``hook`` returned nothing, data that cannot
            travel, or more than an answer may carry.
    """
    why = ""
    if level is None:
        why = "None, not a level"
    else:
        try:
            body = pack(level)
            if len(body) > _MAX_LEVEL_SIZE:
                why = f"{len(body)} bytes of data, more than an answer may carry"
            else:
                return unpack(body)
        except (TypeError, ValueError, RemoteProtocolError) as error:
            why = f"data that cannot travel: {error}"
    raise RequestError(ErrorCode.ENVIRONMENT_ERROR, f"{hook} returned {why}")


def _prefixed(where: str, call: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
    """``call``; a refusal it raises names ``where`` first."""
    try:
        call(*args, **kwargs)
    except RequestError as error:
        raise RequestError(error.code, f"{where}{error}") from None


class Inspect(Part):
    """An inspector's request (:mod:`rlenv.serving._inspector`): read, or change a property.

    It reads the tree, a node, a property or the statistics, or changes a property or a
    setting.

    It never takes control: a change from an observer applies between two of the controller's
    requests, at a tick boundary, and is logged as the controller's own would be.
    """

    name = "inspect"
    alone = True

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        operation, arguments = inspector.check_inspect(parts["inspect"])
        environment = instance.environment
        if operation == "get":
            inspector.get_property(environment, arguments["path"], arguments["property"])
        elif operation == "node":
            inspector.node_at(environment, arguments["path"])
        elif operation == "set":
            inspector.set_property(environment, arguments["path"], arguments["property"],
                                   arguments["value"], dry_run=True)
        elif operation == "configure":
            instance.settings.check(arguments)
        return operation, arguments

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        operation, arguments = value
        environment = instance.environment
        answer: Answer = instance.answer  # type: ignore[assignment]
        if operation == "tree":
            answer.info = {"tree": inspector.tree(environment)}
        elif operation == "node":
            answer.info = {"node": inspector.node_of(environment, arguments["path"])}
        elif operation == "get":
            answer.info = {"value": inspector.get_property(environment, arguments["path"],
                                                           arguments["property"])}
        elif operation == "set":
            instance.set_property(arguments["path"], arguments["property"], arguments["value"])
        elif operation == "configure":
            instance.settings.configure(arguments)
        else:
            answer.info = {"stats": instance.stats.since(arguments.get("since", 0))}


class Claim(Part):
    """``{"agent": NAME, "action": A}`` or ``nil`` (2.6): an observer plays one agent.

    The observer claims agent ``NAME`` of several (or changes the action it holds for the agent
    it claimed) and holds ``A`` until changed; the controller's steps then act for the agent
    with ``A`` (:mod:`rlenv.serving._claims`). ``nil`` releases the observer's claim. It takes
    no control: the controller may not send it.
    """

    name = "claim"
    alone = True
    _KEYS = frozenset({"agent", "action"})

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool,
              where: str) -> Any:
        claim, owner = parts["claim"], instance.requester.peer
        if owner is None:
            raise _bad(f"{where}claim: a claim comes from a client's connection")
        if claim is None:  # release
            return None
        claim = _map(claim, "claim", where)
        check_keys(claim, self._KEYS, f"{where}claim")
        agents = [agent.name for agent in instance.agents]
        if not instance.multi_agent:
            raise _bad(f"{where}claim: this environment has one agent ({agents[0]}), and the "
                       "client that controls the environment owns it: claims are for "
                       "environments of several agents")
        name = claim.get("agent")
        if name not in agents:
            raise _bad(f"{where}claim.agent: no agent {name!r:.40}; the agents: "
                       f"{', '.join(agents)}")
        if instance.driven is not None and name in instance.driven.names:
            raise _bad(f"{where}claim: agent {name!r} is driven by the server (rlenv serve "
                       "--policy); claim another")
        claims = instance.claims
        if claims is not None:
            holder = claims.owners.get(name)
            if holder is not None and holder is not owner:
                raise RequestError(ErrorCode.BUSY, f"{where}claim: agent {name!r} is claimed "
                                   f"by another client ({getattr(holder, 'address', '?')}): "
                                   "one claim per agent")
            mine = claims.of(owner)
            if mine is not None and mine != name:
                raise _bad(f"{where}claim: this client plays {mine!r} already (one claim per "
                           f"client): release it first (claim: nil) to play {name!r}")
        if "action" not in claim:
            raise _bad(f"{where}claim.action: the action to hold for {name!r} is missing")
        return name, instance.checked_action.of_agent(name, claim["action"],
                                                      f"{where}claim.")

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        owner = instance.requester.peer
        if instance.answer.reports:  # type: ignore[union-attr]
            raise _bad("claim: this client controls the environment and acts for every agent "
                       "itself; claims are for the clients that observe it")
        if value is None:
            instance.release_claim(owner)
        else:
            instance.claim(owner, *value)


def _need_lockstep(instance: Instance) -> None:
    if instance.tree.real_time:
        raise _bad("snapshots need lockstep mode: configure real_time=False first")


# --- parts that address every instance --------------------------------------------------------


class Host(Protocol):
    """What the parts that address every instance need of the host (:mod:`.host`)."""

    instances: list[Instance]
    steps_action_space: spaces.Space
    steps_action: Callable[[Any], Any]
    columns: Columns
    lean: LeanSteps | None


class HostPart:
    """One kind of part that addresses every instance of the host; it goes alone.

    Attributes:
        name: the part's key in a request.
    """

    name: ClassVar[str]

    def controls(self, value: Any) -> bool:
        """Whether this part, with this value, takes control."""
        return True

    def takes_control(self, request: Request, checked: Any) -> bool:
        """Whether the checked request takes control (refused parts of it take none)."""
        return self.controls(request.parts[self.name])

    def check(self, host: Host, request: Request) -> Any:
        """Check the whole request before any instance moves; what :meth:`run` needs.

        Raises:
            RequestError: the refusal of the whole request.
        """
        raise NotImplementedError

    def run(self, host: Host, request: Request, checked: Any, reports: bool) -> Reply:
        """Serve every instance its share of a checked request; the one answer.

        See :meth:`Instance.serve` for ``reports``.
        """
        raise NotImplementedError

    def served(self, host: Host, checked: Any) -> list[Instance]:
        """The instances a checked request is served to (those to tell of its answer)."""
        raise NotImplementedError


class Batch(HostPart):
    """One request per instance (``nil`` leaves one alone), each answered on its own."""

    name = "batch"

    def controls(self, value: Any) -> bool:
        return isinstance(value, list) and any(
            isinstance(part, Mapping) and takes_control(part) for part in value)

    def takes_control(self, request: Request, checked: Any) -> bool:
        return any(plan.__class__ is dict and takes_control(parts)
                   for parts, plan in zip(request.parts["batch"], checked, strict=False))

    def check(self, host: Host, request: Request) -> Any:
        batch = request.parts["batch"]
        count = len(host.instances)
        if not isinstance(batch, list) or not batch:
            raise _bad("'batch' must be a non-empty list of requests or nil")
        if len(batch) > count:
            raise _bad(f"a batch of {len(batch)} requests for {count} instances")
        for index, parts in enumerate(batch):
            if parts is not None:
                if not isinstance(parts, Mapping):
                    raise _bad(f"batch[{index}] must be a map or nil")
        shapes = [None if parts is None else shape_of(parts, f"batch[{index}].")
                  for index, parts in enumerate(batch)]
        return [None if shape is None else _plan_or_refusal(instance, parts, shape, request.id)
                for instance, parts, shape in zip(host.instances, batch, shapes, strict=False)]

    def served(self, host: Host, checked: Any) -> list[Instance]:
        return [instance for instance, plan in zip(host.instances, checked, strict=False)
                if plan.__class__ is dict]  # a refusal or a gap served nothing

    def run(self, host: Host, request: Request, checked: Any, reports: bool) -> Reply:
        return BatchResponse(request.id, tuple(
            plan if plan is None or plan.__class__ is ErrorReply else
            instance.serve(plan, request.id, reports)
            for instance, plan in zip(host.instances, checked, strict=False)))


def _plan_or_refusal(instance: Instance, parts: Mapping[str, Any], shape: Shape,
                     reply_id: int) -> Plan | ErrorReply:
    try:
        return plan_for(instance, parts, shape)
    except RequestError as error:
        return ErrorReply(reply_id, error.code, str(error))


class StepsPlan:
    """A checked ``steps`` request, in columns: what each instance does, and for how long.

    Attributes:
        actions: each instance's checked action (its row of the batch); ignored where it resets.
        resets: whether each instance resets instead of acting.
        repeat: ``repeat_action`` for every acting instance, or ``None`` for each one's own.
        starts: ``None`` when every resetting instance resets without a seed or options (the
            lean path serves only these); else each instance's checked ``config`` and ``reset``
            parts (``None`` where it acts, or resets as the others do).
    """

    __slots__ = ("actions", "repeat", "resets", "starts")

    def __init__(self, actions: list[Any], resets: list[bool], repeat: int | None,
                 starts: list[Plan | None] | None = None) -> None:
        self.actions, self.resets, self.repeat = actions, resets, repeat
        self.starts = starts

    def plans(self) -> list[Plan]:
        """Each instance's plan, as a request to it alone would have it."""
        repeat = self.repeat
        starts = self.starts or [None] * len(self.resets)
        return [({**start, "observation": AGENT_ONLY} if start is not None else
                 {"reset": {"seed": None, "options": {}}, "observation": AGENT_ONLY}) if resets
                else {"action": action, "observation": AGENT_ONLY} if repeat is None
                else {"repeat_action": repeat, "action": action, "observation": AGENT_ONLY}
                for action, resets, start in zip(self.actions, self.resets, starts,
                                                 strict=True)]


class Steps(HostPart):
    """Every instance steps (or resets, where the mask says so), in columns.

    ``{"action": <K actions>, "reset": <K bools>, "repeat_action": r, "reset_with": [...]}``;
    the actions stack as gymnasium's ``batch_space`` lays them out, in packed form or as
    arrays. ``reset_with`` (protocol 2.4) gives resetting instances a ``reset`` part (seed,
    options) and a ``config`` part of their own. Everything is checked before any instance
    moves; an instance whose user code raises fails alone.
    """

    name = "steps"
    _KEYS = frozenset({"action", "reset", "repeat_action", "reset_with"})

    def check(self, host: Host, request: Request) -> Any:
        steps = request.parts["steps"]
        if not isinstance(steps, Mapping):
            raise _bad("'steps' must be a map")
        check_keys(steps, self._KEYS, "steps")
        if steps.get("action") is None:
            raise _bad("'steps' needs an 'action' (one per instance)")
        count = len(host.instances)
        reset = _reset_mask(steps.get("reset"), count)
        repeat = steps.get("repeat_action")
        if repeat is not None:
            check_repeat_action(repeat, "steps.repeat_action")
        for index, (instance, resets) in enumerate(zip(host.instances, reset, strict=True)):
            if not resets and instance.state is not _RUNNING:  # running: it can act
                try:
                    instance.check_can_act()
                except RequestError as error:
                    raise RequestError(error.code, f"steps: instance {index}: {error}") from None
        try:
            checked = host.steps_action(steps["action"])
        except SpaceMismatch as error:
            raise RequestError(ErrorCode.INVALID_ACTION, str(error)) from None
        actions = list(checked) if checked.__class__ is np.ndarray else \
            list(iterate(host.steps_action_space, checked))
        starts = steps.get("reset_with")
        return StepsPlan(actions, reset, repeat,
                         None if starts is None else _starts(host, starts, reset))

    def served(self, host: Host, checked: Any) -> list[Instance]:
        return host.instances

    def run(self, host: Host, request: Request, checked: Any, reports: bool) -> Reply:
        lean = host.lean
        if lean is not None and reports and checked.starts is None and \
                not any(i.tree.real_time for i in host.instances):
            return lean.run(request.id, checked)
        return host.columns.stack(request.id, [
            instance.serve(plan, request.id, reports)
            for instance, plan in zip(host.instances, checked.plans(), strict=True)])


_START_KEYS = frozenset({"config", "reset"})


def _starts(host: Host, entries: Any, flags: list[bool]) -> list[Plan | None]:
    """The checked ``reset_with`` entries of a steps request: each flagged instance's start.

    Raises:
        RequestError: ``bad_request``: not a list of K maps or nils, an entry for an instance
            that does not reset, an unknown key; any refusal of its ``config`` or ``reset``.
    """
    count = len(host.instances)
    if not isinstance(entries, list) or len(entries) != count:
        raise _bad(f"steps.reset_with must be a list of {count} entries (a map or nil each)")
    starts: list[Plan | None] = []
    for index, (instance, entry, resets) in enumerate(zip(host.instances, entries, flags,
                                                          strict=True)):
        if entry is None:
            starts.append(None)
            continue
        where = f"steps.reset_with[{index}]"
        if not isinstance(entry, Mapping):
            raise _bad(f"{where} must be a map or nil")
        if not resets:
            raise _bad(f"{where} is given, but instance {index} does not reset (steps.reset)")
        check_keys(entry, _START_KEYS, where)
        parts = {"reset": entry.get("reset") or {}}
        if "config" in entry:
            parts["config"] = entry["config"]
        try:
            starts.append(plan_for(instance, parts, shape_of(parts)))
        except RequestError as error:
            raise RequestError(error.code, f"{where}: {error}") from None
    return starts


def _reset_mask(mask: Any, count: int) -> list[bool]:
    """The ``reset`` flags of a steps request: a list of booleans, bytes of 0/1, or an array."""
    if mask is None:
        return [False] * count
    flags = None
    if isinstance(mask, bytes):
        if not mask.translate(None, b"\x00\x01"):  # every byte is 0 or 1
            flags = list(map(bool, mask))
    elif isinstance(mask, np.ndarray):
        if mask.ndim == 1 and (mask.dtype == np.bool_ or (
                mask.dtype == np.uint8 and bool(np.all(mask <= 1)))):
            flags = mask.astype(bool).tolist()
    elif isinstance(mask, list) and all(type(flag) is bool for flag in mask):
        flags = mask
    if flags is None:
        raise _bad("steps.reset must be a list of booleans, one per instance")
    if len(flags) != count:
        raise _bad(f"steps.reset has {len(flags)} flags for {count} instances")
    return flags


# --- the table --------------------------------------------------------------------------------

PARTS: dict[str, Part | HostPart] = {
    part.name: part for part in (
        Restore(), Inspect(), Snapshot(), Episodes(), EditLevel(), Claim(), Config(), Reset(),
        RepeatAction(), Heuristic(), Action(), Observation(), Batch(), Steps())
}
"""Every kind of request part, in the order they apply."""

_ORDER = {name: index for index, name in enumerate(PARTS)}
_INSTANCE_KEYS = ", ".join(name for name, part in PARTS.items() if isinstance(part, Part))
_REQUEST_KEYS = ", ".join([_INSTANCE_KEYS, "token", "shared_memory"] + [
    name for name, part in PARTS.items() if isinstance(part, HostPart)])
_MAX_SHAPES = 512


class Shape:
    """What a request's keys say, once their combination is known to be valid (cached).

    Attributes:
        host_part: the part that addresses every instance (``batch``, ``steps``), or ``None``.
        parts: the parts to one instance, in the order they apply.
        fresh: whether the request starts an episode (``reset`` or ``restore``) before it
            acts or observes.
    """

    __slots__ = ("fresh", "host_part", "parts")

    def __init__(self, keys: tuple[str, ...], where: str) -> None:
        records = []
        for key in keys:
            record = PARTS.get(key)
            if record is None or (where and isinstance(record, HostPart)):
                expected = _INSTANCE_KEYS if where else _REQUEST_KEYS
                raise _bad(f"unknown request key {where}{str(key)!r}; expected any of "
                           f"{expected}")
            records.append(record)
        host_parts = [r for r in records if isinstance(r, HostPart)]
        if host_parts and len(records) > 1:
            raise _bad(f"a {host_parts[0].name!r} request carries nothing else but its id")
        alone = [r.name for r in records if isinstance(r, Part) and r.alone]
        if len(alone) > 1:
            raise _bad(f"{alone[0]} or {alone[1]}, not both")
        if alone and any(r.name not in (alone[0], "observation") for r in records):
            raise _bad(f"{alone[0]} goes alone (with an observation at most)")
        self.host_part: HostPart | None = host_parts[0] if host_parts else None
        self.parts: tuple[Part, ...] = tuple(sorted(
            (r for r in records if isinstance(r, Part)), key=lambda r: _ORDER[r.name]))
        self.fresh = "reset" in keys or "restore" in keys


_shapes: dict[tuple[str, ...], Shape] = {}


def shape_of(parts: Mapping[str, Any], where: str = "") -> Shape:
    """The :class:`Shape` of a request with these parts (``where`` names a batch's slot).

    Raises:
        RequestError: ``bad_request``: an unknown key, a part that goes alone in company.
    """
    keys = tuple(parts)
    shape = _shapes.get(keys) if not where else None
    if shape is None:
        shape = Shape(keys, where)
        if not where and len(_shapes) < _MAX_SHAPES:
            _shapes[keys] = shape
    return shape


def plan_for(instance: Instance, parts: Mapping[str, Any], shape: Shape,
             where: str = "") -> Plan:
    """Check every part of a request to ``instance``; the plan that applies them.

    Raises:
        RequestError: the request is refused (nothing was applied).
    """
    fresh = shape.fresh
    return {record.name: record.check(instance, parts, fresh, where) for record in shape.parts}


def dispatch(instance: Instance, request: Plan) -> None:
    """Apply every part of a checked request to ``instance``, in the request's order.

    ``RLEnvironment._on_got_connection`` does this by default (through its communication).

    Raises:
        RuntimeError: the request names a part that does not exist (an override of
            ``_on_got_connection`` added it).
    """
    for name, value in request.items():
        record = PARTS.get(name)
        if record is None or not isinstance(record, Part):
            raise RuntimeError(f"_on_got_connection passed on a request with an unknown part "
                               f"{name!r:.40}")
        record.apply(instance, value, request)


def takes_control(parts: Mapping[str, Any]) -> bool:
    """Whether a request with these parts changes the environment (see :class:`Part`)."""
    for key, value in parts.items():
        record = PARTS.get(key)
        if record is not None and record.controls(value):
            return True
    return False
