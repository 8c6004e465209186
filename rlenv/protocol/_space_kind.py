"""What every kind of space implements: :class:`SpaceKind`, its :class:`Codec`, and the error.

The records themselves, and the functions that use them, are :mod:`rlenv.protocol.spaces`'
(which documents and exports these three names); the array kinds are
:mod:`rlenv.protocol._array_spaces`'.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

from gymnasium import spaces

__all__ = ["Checker", "Codec", "SpaceKind", "SpaceMismatch", "Spec"]

Spec = dict[str, Any]
Checker = Callable[[Any], Any]


class SpaceMismatch(ValueError):
    """A value does not belong to a space; the message names the offending field."""


class Codec:
    """Packs and unpacks the values of one space (see :mod:`rlenv.protocol.spaces`).

    Built by :func:`~rlenv.protocol.spaces.codec_for`; each kind of space has its own.
    """

    def pack(self, value: Any) -> Any:
        """``value`` in packed form, converted to the space's dtype.

        Raises:
            SpaceMismatch: the value does not have the space's structure or shape, or holds NaN
                or infinity (the message starts with where: ``"[1] is not finite"``).
        """
        raise NotImplementedError

    def pack_exact(self, value: Any) -> Any:
        """``value`` in packed form if it already has the space's exact dtype and shape.

        Anything else is returned as it is, for the receiver to check (and refuse with a
        precise message, or convert).
        """
        raise NotImplementedError

    def unpack(self, wire: Any, writable: bool = True) -> Any:
        """A packed value (or an array-like, for robustness) in the space's native form.

        With ``writable`` arrays are the caller's own (as gymnasium environments return them);
        otherwise they may be read-only views of the received bytes.
        """
        raise NotImplementedError

    def join(self, packed: list[Any]) -> Any:
        """K packed values of this space as one packed value of ``batch_space(space, K)``."""
        raise NotImplementedError


class SpaceKind:
    """Everything rlenv does with one class of gymnasium space; see :mod:`rlenv.protocol.spaces`."""

    space_class: ClassVar[type[spaces.Space]]

    def to_spec(self, space: Any) -> Spec:
        """Describe ``space`` as a plain map that msgpack can carry."""
        raise NotImplementedError

    def from_spec(self, spec: Spec) -> spaces.Space:
        """Rebuild the space :meth:`to_spec` described (the spec's ``type`` is this kind)."""
        raise NotImplementedError

    def check(self, space: Any, value: Any, path: str) -> Any:
        """The general check (see :func:`~rlenv.protocol.spaces.check`)."""
        raise NotImplementedError

    def checker(self, space: Any, path: str) -> Checker:
        """A check prepared for ``space`` (see :func:`~rlenv.protocol.spaces.compile_check`)."""
        return lambda value: self.check(space, value, path)

    def codec(self, space: Any) -> Codec:
        """The codec of ``space``'s packed form."""
        raise NotImplementedError
