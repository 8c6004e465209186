"""The inspector page's errors for its timeline requests (:class:`InspectorError`, by status).

A key outside the agent's map and a policy the page does not have are refused (422, 404); a
timeline's own failures, while it computes what a request asks, become the page's errors: a
step it does not have 400, its environment failing 422.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from rlenv.protocol.errors import RemoteError
from rlenv_client.session import LOST
from rlenv_tools.inspector._recordings import Root, key_name
from rlenv_tools.inspector._watch import InspectorError

__all__ = ["chosen_policy", "key_action", "page_call"]

Policy = Callable[[Any], Any]


def page_call(compute: Callable[[], Any]) -> Any:
    """``compute()``, its timeline's failures as the page's errors."""
    try:
        return compute()
    except IndexError as error:
        raise InspectorError(400, str(error)) from None
    except (RuntimeError, RemoteError, *LOST) as error:
        raise InspectorError(422, f"the timeline's environment failed: {error}") from None


def key_action(root: Root, key: str) -> Any:
    """The action of the agent's ``key`` in ``root``'s key map.

    Raises:
        InspectorError: 422, a key outside the map (or no map, saying why).
    """
    if key not in root.keys:
        if not root.keys:
            raise InspectorError(422, f"no keys to branch with: {root.keys_error}")
        raise InspectorError(
            422,
            f"{key!r:.20} is none of the agent's keys ({', '.join(map(key_name, root.keys))})",
        )
    return root.keys[key]


def chosen_policy(
    policies: Mapping[str, Policy], unavailable: Mapping[str, str], name: str
) -> Policy:
    """The policy ``name`` of ``policies``.

    Raises:
        InspectorError: 422, one of the ``unavailable`` (saying why); 404, no such policy.
    """
    if name not in policies:
        if name in unavailable:
            raise InspectorError(422, f"policy {name} is unavailable: {unavailable[name]}")
        known = (
            ", ".join(sorted(policies))
            or "none (rlenv replay FILE --inspect --policy FILE.onnx gives one)"
        )
        raise InspectorError(404, f"no policy {name!r:.40}: the policies are {known}")
    return policies[name]
