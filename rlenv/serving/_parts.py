"""The request parts: one record per kind, registered in one table, :data:`PARTS`.

A request is a map of parts (``config``, ``reset``, ``action`` ...). Each kind of part is one
record (:mod:`rlenv.serving._part_record`) that says

- whether it **takes control** of the environment (only the controlling client may send it);
- how it is **checked** against an instance, before anything is applied: every part of a
  request is checked first, so a refused request changes nothing;
- how it is **applied**, in the table's order (``config`` before ``reset`` before ``action``...).

Most parts concern one instance (:class:`Part`); their records live in modules by job: a step's
parts (:mod:`~rlenv.serving._step_parts`), who acts for an agent beside the controller
(:mod:`~rlenv.serving._agent_parts`), episodes as data (:mod:`~rlenv.serving._episode_parts`),
the inspector's (:mod:`~rlenv.serving._inspect_part`) and level edits
(:mod:`~rlenv.serving._level_edit_part`). ``batch`` and ``steps`` address every instance of the
host at once (:class:`HostPart`) and go alone: their records are here, beside the table and what
combines a request's parts (:class:`Shape`, :func:`plan_for`, :func:`dispatch`). To add a kind of
request: write its record in the module of its job, add it to :data:`PARTS`, and give the client
a method that sends it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium.vector.utils import iterate

from rlenv.protocol import BatchResponse, ErrorReply, Reply, Request
from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.protocol.spaces import SpaceMismatch
from rlenv.serving._actions import check_repeat_action
from rlenv.serving._agent_parts import Claim, Heuristic
from rlenv.serving._episode_parts import Episodes, Restore, Snapshot
from rlenv.serving._inspect_part import Inspect
from rlenv.serving._instance import Episode, Instance, Plan
from rlenv.serving._level_edit_part import EditLevel
from rlenv.serving._part_record import Host, HostPart, Part, bad
from rlenv.serving._settings import check_keys
from rlenv.serving._step_parts import Action, Config, Observation, RepeatAction, Reset

__all__ = [
    "PARTS",
    "HostPart",
    "Part",
    "Shape",
    "StepsPlan",
    "dispatch",
    "plan_for",
    "shape_of",
    "takes_control",
]

AGENT_ONLY: Mapping[str, Any] = {"agent": {}}
_RUNNING = Episode.RUNNING


# --- parts that address every instance --------------------------------------------------------


class Batch(HostPart):
    """One request per instance (``nil`` leaves one alone), each answered on its own."""

    name = "batch"

    def controls(self, value: Any) -> bool:
        return isinstance(value, list) and any(
            isinstance(part, Mapping) and takes_control(part) for part in value
        )

    def takes_control(self, request: Request, checked: Any) -> bool:
        return any(
            plan.__class__ is dict and takes_control(parts)
            for parts, plan in zip(request.parts["batch"], checked, strict=False)
        )

    def check(self, host: Host, request: Request) -> Any:
        batch = request.parts["batch"]
        count = len(host.instances)
        if not isinstance(batch, list) or not batch:
            raise bad("'batch' must be a non-empty list of requests or nil")
        if len(batch) > count:
            raise bad(f"a batch of {len(batch)} requests for {count} instances")
        for index, parts in enumerate(batch):
            if parts is not None:
                if not isinstance(parts, Mapping):
                    raise bad(f"batch[{index}] must be a map or nil")
        shapes = [
            None if parts is None else shape_of(parts, f"batch[{index}].")
            for index, parts in enumerate(batch)
        ]
        return [
            None if shape is None else _plan_or_refusal(instance, parts, shape, request.id)
            for instance, parts, shape in zip(host.instances, batch, shapes, strict=False)
        ]

    def served(self, host: Host, checked: Any) -> list[Instance]:
        return [
            instance
            for instance, plan in zip(host.instances, checked, strict=False)
            if plan.__class__ is dict
        ]  # a refusal or a gap served nothing

    def run(self, host: Host, request: Request, checked: Any, reports: bool) -> Reply:
        return BatchResponse(
            request.id,
            tuple(
                plan
                if plan is None or plan.__class__ is ErrorReply
                else instance.serve(plan, request.id, reports)
                for instance, plan in zip(host.instances, checked, strict=False)
            ),
        )


def _plan_or_refusal(
    instance: Instance, parts: Mapping[str, Any], shape: Shape, reply_id: int
) -> Plan | ErrorReply:
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

    def __init__(
        self,
        actions: list[Any],
        resets: list[bool],
        repeat: int | None,
        starts: list[Plan | None] | None = None,
    ) -> None:
        self.actions, self.resets, self.repeat = actions, resets, repeat
        self.starts = starts

    def plans(self) -> list[Plan]:
        """Each instance's plan, as a request to it alone would have it."""
        repeat = self.repeat
        starts = self.starts or [None] * len(self.resets)
        return [
            (
                {**start, "observation": AGENT_ONLY}
                if start is not None
                else {"reset": {"seed": None, "options": {}}, "observation": AGENT_ONLY}
            )
            if resets
            else {"action": action, "observation": AGENT_ONLY}
            if repeat is None
            else {"repeat_action": repeat, "action": action, "observation": AGENT_ONLY}
            for action, resets, start in zip(self.actions, self.resets, starts, strict=True)
        ]


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
            raise bad("'steps' must be a map")
        check_keys(steps, self._KEYS, "steps")
        if steps.get("action") is None:
            raise bad("'steps' needs an 'action' (one per instance)")
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
        actions = (
            list(checked)
            if checked.__class__ is np.ndarray
            else list(iterate(host.steps_action_space, checked))
        )
        starts = steps.get("reset_with")
        return StepsPlan(
            actions, reset, repeat, None if starts is None else _starts(host, starts, reset)
        )

    def served(self, host: Host, checked: Any) -> list[Instance]:
        return host.instances

    def run(self, host: Host, request: Request, checked: Any, reports: bool) -> Reply:
        lean = host.lean
        if (
            lean is not None
            and reports
            and checked.starts is None
            and not any(i.tree.real_time for i in host.instances)
        ):
            return lean.run(request.id, checked)
        return host.columns.stack(
            request.id,
            [
                instance.serve(plan, request.id, reports)
                for instance, plan in zip(host.instances, checked.plans(), strict=True)
            ],
        )


_START_KEYS = frozenset({"config", "reset"})


def _starts(host: Host, entries: Any, flags: list[bool]) -> list[Plan | None]:
    """The checked ``reset_with`` entries of a steps request: each flagged instance's start.

    Raises:
        RequestError: ``bad_request``: not a list of K maps or nils, an entry for an instance
            that does not reset, an unknown key; any refusal of its ``config`` or ``reset``.
    """
    count = len(host.instances)
    if not isinstance(entries, list) or len(entries) != count:
        raise bad(f"steps.reset_with must be a list of {count} entries (a map or nil each)")
    starts: list[Plan | None] = []
    for index, (instance, entry, resets) in enumerate(
        zip(host.instances, entries, flags, strict=True)
    ):
        if entry is None:
            starts.append(None)
            continue
        where = f"steps.reset_with[{index}]"
        if not isinstance(entry, Mapping):
            raise bad(f"{where} must be a map or nil")
        if not resets:
            raise bad(f"{where} is given, but instance {index} does not reset (steps.reset)")
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
        if mask.ndim == 1 and (
            mask.dtype == np.bool_ or (mask.dtype == np.uint8 and bool(np.all(mask <= 1)))
        ):
            flags = mask.astype(bool).tolist()
    elif isinstance(mask, list) and all(type(flag) is bool for flag in mask):
        flags = mask
    if flags is None:
        raise bad("steps.reset must be a list of booleans, one per instance")
    if len(flags) != count:
        raise bad(f"steps.reset has {len(flags)} flags for {count} instances")
    return flags


# --- the table --------------------------------------------------------------------------------

PARTS: dict[str, Part | HostPart] = {
    part.name: part
    for part in (
        Restore(),
        Inspect(),
        Snapshot(),
        Episodes(),
        EditLevel(),
        Claim(),
        Config(),
        Reset(),
        RepeatAction(),
        Heuristic(),
        Action(),
        Observation(),
        Batch(),
        Steps(),
    )
}
"""Every kind of request part, in the order they apply."""

_ORDER = {name: index for index, name in enumerate(PARTS)}
_INSTANCE_KEYS = ", ".join(name for name, part in PARTS.items() if isinstance(part, Part))
_REQUEST_KEYS = ", ".join(
    [_INSTANCE_KEYS, "token", "shared_memory"]
    + [name for name, part in PARTS.items() if isinstance(part, HostPart)]
)
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
                raise bad(f"unknown request key {where}{str(key)!r}; expected any of {expected}")
            records.append(record)
        host_parts = [r for r in records if isinstance(r, HostPart)]
        if host_parts and len(records) > 1:
            raise bad(f"a {host_parts[0].name!r} request carries nothing else but its id")
        alone = [r.name for r in records if isinstance(r, Part) and r.alone]
        if len(alone) > 1:
            raise bad(f"{alone[0]} or {alone[1]}, not both")
        if alone and any(r.name not in (alone[0], "observation") for r in records):
            raise bad(f"{alone[0]} goes alone (with an observation at most)")
        self.host_part: HostPart | None = host_parts[0] if host_parts else None
        self.parts: tuple[Part, ...] = tuple(
            sorted((r for r in records if isinstance(r, Part)), key=lambda r: _ORDER[r.name])
        )
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


def plan_for(instance: Instance, parts: Mapping[str, Any], shape: Shape, where: str = "") -> Plan:
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
            raise RuntimeError(
                f"_on_got_connection passed on a request with an unknown part {name!r:.40}"
            )
        record.apply(instance, value, request)


def takes_control(parts: Mapping[str, Any]) -> bool:
    """Whether a request with these parts changes the environment (see :class:`Part`)."""
    for key, value in parts.items():
        record = PARTS.get(key)
        if record is not None and record.controls(value):
            return True
    return False
