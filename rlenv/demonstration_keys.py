"""Which keys a person presses to act for an agent: :attr:`RLAgent.demonstration_keys`.

The inspector's page (:mod:`rlenv_tools.inspector`) lets a person take control of an
environment and play it from the keyboard. Key names are those of the browser's
``KeyboardEvent.key`` (``"ArrowLeft"``, ``"a"``, ``" "``); each maps to an action of the
agent's space. An agent without a map of its own gets :func:`default_keys` of its space.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

__all__ = ["default_keys", "keys_of"]

_ARROWS = (("ArrowLeft", "ArrowRight"), ("ArrowDown", "ArrowUp"))  # per axis: (-, +)


def default_keys(space: spaces.Space) -> dict[str, Any]:
    """The keys a person acts with in ``space`` when its agent names none.

    - ``Discrete(n)``: ``"1"`` .. ``"9"`` for its first nine actions; with 2 or 3 actions also
      ``ArrowLeft`` (the first), ``ArrowRight`` (the last) and ``ArrowDown`` (the middle one).
    - ``Box`` of one or two values: ``ArrowLeft`` / ``ArrowRight`` set the first to its lower /
      upper bound, ``ArrowDown`` / ``ArrowUp`` the second (an unbounded side: -1 / +1); the
      other value stays at 0 (or the bound nearest to 0).
    - any other space: none (the agent must name its own keys).
    """
    if isinstance(space, spaces.Discrete):
        start, n = int(space.start), int(space.n)
        keys: dict[str, Any] = {str(digit + 1): start + digit for digit in range(min(n, 9))}
        if n in (2, 3):
            keys.update(ArrowLeft=start, ArrowRight=start + n - 1)
        if n == 3:
            keys["ArrowDown"] = start + 1
        return keys
    if isinstance(space, spaces.Box) and space.shape in ((1,), (2,)):
        idle = np.clip(np.zeros(space.shape), space.low, space.high)
        keys = {}
        for axis in range(space.shape[0]):
            for key, bound, fallback in (
                (_ARROWS[axis][0], space.low[axis], -1.0),
                (_ARROWS[axis][1], space.high[axis], 1.0),
            ):
                action = idle.copy()
                action[axis] = bound if np.isfinite(bound) else fallback
                keys[key] = action.astype(space.dtype)
        return keys
    return {}


def keys_of(agent: Any) -> dict[str, Any]:
    """The key map of ``agent``: its ``demonstration_keys``, else :func:`default_keys`.

    Raises:
        TypeError: its ``demonstration_keys`` is not a mapping with text keys.
    """
    keys = getattr(type(agent), "demonstration_keys", None)
    if keys is None:
        return default_keys(agent.action_space)
    if not isinstance(keys, Mapping) or not all(isinstance(key, str) for key in keys):
        raise TypeError(
            f"{type(agent).__name__}.demonstration_keys must map key names "
            f"(text, as KeyboardEvent.key gives them) to actions, got {keys!r:.80}"
        )
    return dict(keys)
