"""What a kind of request part is: the record each kind derives from, and its refusals.

A kind of part of a request to one instance is a :class:`Part`; a kind that addresses every
instance of the host (:class:`Host`) at once is a :class:`HostPart`. Each kind is one subclass,
registered in :data:`rlenv.serving._parts.PARTS`; :func:`bad` and :func:`as_map` make the
refusals their checks share.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, ClassVar, Protocol

from gymnasium import spaces

from rlenv.protocol import Reply, Request
from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.serving._columns import Columns
from rlenv.serving._instance import Instance, Plan
from rlenv.serving._lean import LeanSteps

__all__ = ["Host", "HostPart", "Part", "as_map", "bad"]


def bad(message: str) -> RequestError:
    """A ``bad_request`` refusal that says ``message``."""
    return RequestError(ErrorCode.BAD_REQUEST, message)


def as_map(value: Any, name: str, where: str) -> Mapping[str, Any]:
    """``value``, refused unless it is a map (``where`` and ``name`` say which field)."""
    if not isinstance(value, Mapping):
        raise bad(f"request {where}{name!r} must be a map")
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

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
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


class Host(Protocol):
    """What the parts that address every instance need of the host (:mod:`._host`)."""

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
