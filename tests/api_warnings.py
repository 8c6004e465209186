"""The warnings of the libraries' own API checks (gymnasium's ``check_env``, PettingZoo's
``parallel_api_test``) on an adaptor."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any


def warnings_of(check: Callable[[], object]) -> list[str]:
    """The message of every warning ``check()`` raised (each shown: none filtered out)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check()
    return [str(warning.message) for warning in caught]


def parallel_api_complaints(env: Any, num_cycles: int) -> set[str]:
    """PettingZoo's ``parallel_api_test`` on ``env``: its warnings of an agent's entry that was
    not given or of an agent dead last turn (pettingzoo must be installed)."""
    from pettingzoo.test import parallel_api_test

    messages = warnings_of(lambda: parallel_api_test(env, num_cycles=num_cycles))
    return {m for m in messages if "was not given" in m or "dead last turn" in m}
