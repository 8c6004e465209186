"""The ``edit_level`` part: a level edited by the world's ``_edit_level`` hook, as data.

A record of :data:`rlenv.serving._parts.PARTS`; the answer carries the edited level as it
travels (plain msgpack data, checked and bounded).
"""

from __future__ import annotations

import logging
import traceback
from collections.abc import Mapping
from typing import Any

import numpy as np

from rlenv.protocol.codec import DEFAULT_MAX_FRAME_SIZE, pack, unpack
from rlenv.protocol.errors import ErrorCode, RemoteProtocolError, RequestError
from rlenv.scene2d.packed_scene import PackedSceneError, check_size
from rlenv.serving._instance import Instance, Plan
from rlenv.serving._part_record import Part, as_map, bad
from rlenv.serving._settings import check_keys
from rlenv.world import MAX_LEVEL_EDITS, RLEnvWorld

__all__ = ["EditLevel"]

logger = logging.getLogger(__name__)

_MAX_LEVEL_SIZE = DEFAULT_MAX_FRAME_SIZE - 4096  # an edited level, with room for its answer


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

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
        edit = as_map(parts["edit_level"], "edit_level", where)
        check_keys(edit, self._KEYS, "edit_level")
        if "level" not in edit:
            raise bad("edit_level needs a 'level' (a level's data or an int seed)")
        seed, n_edits = edit.get("seed"), edit.get("n_edits", 1)
        if type(seed) is not int or seed < 0:
            raise bad(f"edit_level.seed must be an integer >= 0, got {seed!r:.40}")
        if type(n_edits) is not int or not 1 <= n_edits <= MAX_LEVEL_EDITS:
            raise bad(
                f"edit_level.n_edits must be an integer in [1, {MAX_LEVEL_EDITS}], "
                f"got {n_edits!r:.40}"
            )
        world: RLEnvWorld = instance.environment.world  # type: ignore[assignment]  # has one
        if type(world)._edit_level is RLEnvWorld._edit_level:
            raise bad(
                f"edit_level: {type(world).__name__} has no _edit_level: "
                f"{type(instance.environment).__name__} offers no edits of its levels"
            )
        try:
            check_size(edit["level"])
        except PackedSceneError as error:
            raise bad(f"edit_level.level: {error}") from None
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
            raise bad(f"edit_level: {hook} refused the level: {error}") from None
        except Exception as error:  # user code raised: nothing changed, the episode goes on
            logger.error("%s raised", hook, exc_info=error)
            detail = "".join(traceback.format_exception(error)).rstrip()
            raise RequestError(
                ErrorCode.ENVIRONMENT_ERROR,
                f"{hook} raised {type(error).__name__}: {error}; nothing changed\n{detail}",
            ) from None
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
