"""The parts of a step: ``config``, ``reset``, ``action``, ``repeat_action``, ``observation``.

Records of :data:`rlenv.serving._parts.PARTS`, and :func:`check_options`, the check of a
reset's options (a ``restore`` checks its snapshot's with it too).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rlenv.protocol.messages import MAX_RENDER_SIZE
from rlenv.scene2d.packed_scene import PackedSceneError, check_size
from rlenv.serving._actions import check_repeat_action
from rlenv.serving._instance import Episode, Instance, Plan
from rlenv.serving._part_record import Part, as_map, bad
from rlenv.serving._settings import check_keys

__all__ = ["Action", "Config", "Observation", "RepeatAction", "Reset", "check_options"]

_RUNNING = Episode.RUNNING


class Config(Part):
    """``{"environment": {...}, "agent": {...}, "world": {...}}``: settings of each node."""

    name = "config"
    takes_control = True

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
        config = as_map(parts["config"], "config", where)
        instance.settings.check(config)
        return config

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        instance.settings.configure(value)


class Reset(Part):
    """``{"seed": int >= 0, "options": {...}}``, both optional: start an episode."""

    name = "reset"
    takes_control = True
    _KEYS = frozenset({"seed", "options"})

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
        reset = as_map(parts["reset"], "reset", where)
        check_keys(reset, self._KEYS, "reset")
        seed, options = reset.get("seed"), reset.get("options")
        if seed is not None and (type(seed) is not int or seed < 0):
            raise bad(f"reset.seed must be an integer >= 0, got {seed!r:.40}")
        if options is not None and not isinstance(options, Mapping):
            raise bad("reset.options must be a map")
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
                raise bad(
                    f"{where}: {type(environment).__name__} has no reset option "
                    f"{str(key)!r:.60}; it accepts {accepted}"
                )
    if "level" in options:
        try:
            check_size(options["level"])
        except PackedSceneError as error:
            raise bad(f"{where}.level: {error}") from None
    world = environment.world
    if world is not None:
        try:
            world.check_options(options)
        except ValueError as error:  # refused before anything changed: the episode goes on
            raise bad(f"{where}: {error}") from None


class Action(Part):
    """A member of the action space: run it for ``repeat_action`` ticks."""

    name = "action"
    takes_control = True

    def controls(self, value: Any) -> bool:
        return value is not None  # nil: no action

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
        action = parts["action"]
        if action is None:  # nil: no action
            return None
        if not fresh and instance.state is not _RUNNING:
            instance.check_can_act()  # refuses
        return instance.checked_action(
            action, fresh, heuristic=frozenset(parts.get("heuristic") or ())
        )

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        if value is not None:
            instance.act(
                value,
                request.get("repeat_action") or instance.environment.repeat_action,
                request.get("heuristic") or frozenset(),
            )
            instance.answer.acted = True  # type: ignore[union-attr]


class RepeatAction(Part):
    """How many ticks this request's action runs (instead of the configured number)."""

    name = "repeat_action"

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
        repeat = check_repeat_action(parts["repeat_action"], f"{where}'repeat_action'")
        if parts.get("action") is None:
            raise bad(f"{where}'repeat_action' given without an 'action'")
        return repeat


class Observation(Part):
    """``{"agent": {}, "world": {}, "render": {"width", "height"}, "draw": {}}``, any of them."""

    name = "observation"
    _KEYS = frozenset({"agent", "world", "render", "draw"})
    _RENDER_KEYS = frozenset({"width", "height"})

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
        observation = parts["observation"]
        if observation.__class__ is not dict:
            observation = as_map(observation, "observation", where)
        if not observation.keys() <= self._KEYS:
            check_keys(observation, self._KEYS, "observation")
        for key in ("agent", "world"):
            if key in observation and observation[key].__class__ is not dict:
                as_map(observation[key], f"observation.{key}", where)
        if "render" in observation:
            self._check_render(observation["render"])
        if "draw" in observation and as_map(observation["draw"], "observation.draw", where):
            raise bad("observation.draw takes an empty map")
        if instance.state is Episode.NOT_STARTED and not fresh:
            instance.refuse_without_episode()
        return observation

    def _check_render(self, size: Any) -> None:
        if not isinstance(size, Mapping):
            raise bad("observation.render must be a map")
        check_keys(size, self._RENDER_KEYS, "observation.render")
        for key, value in size.items():
            if type(value) is not int or not 1 <= value <= MAX_RENDER_SIZE:
                raise bad(
                    f"observation.render.{key} must be an integer in "
                    f"[1, {MAX_RENDER_SIZE}], got {value!r:.40}"
                )

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        instance.send_response(value)
