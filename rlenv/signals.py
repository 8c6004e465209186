"""Signals: a node announces something, any number of callables listen.

Declare a signal as a class attribute of a :class:`~rlenv.node.Node` subclass and use it
through an instance, as in Godot 4::

    class Apple(Node):
        caught = Signal("by")           # argument names, for documentation and introspection

    apple.caught.connect(on_caught)     # on_caught(by) is called by ...
    apple.caught.emit(agent)

A connected callable is called with exactly the arguments the signal is emitted with, in the
order they are declared (``Signal("by")``: one argument). The built-in nodes document their
signals in the same form, e.g. ``body_entered(body)`` on a physics body.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["BoundSignal", "Signal", "SignalOwner"]


class Signal:
    """Declares a signal on a class; reading it from an instance gives a :class:`BoundSignal`.

    Args:
        *arguments: names of the arguments the signal is emitted with (documentation and
            introspection: emitting does not check them).

    Attributes:
        arguments: the argument names.
        name: the attribute name the signal was declared under.
    """

    def __init__(self, *arguments: str) -> None:
        self.arguments = arguments
        self.name = ""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, instance: Any, owner: type | None = None) -> Any:
        if instance is None:
            return self
        return instance.get_signal(self.name)

    def __repr__(self) -> str:
        return f"Signal({self.name}({', '.join(self.arguments)}))"


class BoundSignal:
    """One object's signal: its connections, and :meth:`emit` to call them in connection order.

    The connections are an immutable tuple, replaced (never changed in place) by
    :meth:`connect`, :meth:`disconnect` and the firing of one-shot connections: an emission goes
    through the tuple that was current when it started, without copying it, and a change made
    while it runs applies from the next emission.
    """

    __slots__ = ("_connections", "_one_shots", "name", "owner")

    def __init__(self, owner: object, name: str) -> None:
        self.owner = owner
        self.name = name
        self._connections: tuple[tuple[Callable[..., Any], bool], ...] = ()
        self._one_shots = 0

    def connect(self, callback: Callable[..., Any], *, one_shot: bool = False) -> None:
        """Call ``callback`` on every emission (only the next one if ``one_shot``).

        Raises:
            ValueError: ``callback`` is already connected to this signal.
        """
        if self.is_connected(callback):
            raise ValueError(f"{callback!r} is already connected to signal {self.name!r}")
        self._connections += ((callback, one_shot),)
        self._one_shots += one_shot

    def disconnect(self, callback: Callable[..., Any]) -> None:
        """Stop calling ``callback``.

        Raises:
            ValueError: ``callback`` is not connected to this signal.
        """
        connections = self._connections
        for index, (connected, one_shot) in enumerate(connections):
            if connected == callback:
                self._connections = connections[:index] + connections[index + 1 :]
                self._one_shots -= one_shot
                return
        raise ValueError(f"{callback!r} is not connected to signal {self.name!r}")

    def is_connected(self, callback: Callable[..., Any]) -> bool:
        """Whether ``callback`` is connected to this signal."""
        return any(connected == callback for connected, _ in self._connections)

    def get_connections(self) -> list[Callable[..., Any]]:
        """The connected callables, in the order they are called."""
        return [connected for connected, _ in self._connections]

    def emit(self, *args: Any) -> None:
        """Call every connected callable with ``args``, in connection order.

        Callables connected or disconnected while the signal is being emitted take effect from
        the next emission.
        """
        connections = self._connections
        if self._one_shots:
            self._connections = tuple(c for c in connections if not c[1])
            self._one_shots = 0
        for callback, _ in connections:
            callback(*args)

    def __repr__(self) -> str:
        return f"<signal {self.name!r} of {self.owner!r}, {len(self._connections)} connections>"


class SignalOwner:
    """Mixin for classes that declare signals (:class:`Signal`): lookup by name, user signals.

    Subclasses set ``self._signals = {}`` in their ``__init__``.
    """

    _signals: dict[str, BoundSignal]

    def get_signal(self, name: str) -> BoundSignal:
        """The signal called ``name`` (declared with :class:`Signal` or added as a user signal).

        Raises:
            KeyError: there is no such signal.
        """
        signal = self._signals.get(name)
        if signal is None:
            if not isinstance(getattr(type(self), name, None), Signal):
                raise KeyError(f"{type(self).__name__} has no signal {name!r}")
            signal = self._signals[name] = BoundSignal(self, name)
        return signal

    def has_signal(self, name: str) -> bool:
        """Whether there is a signal called ``name``."""
        return name in self._signals or isinstance(getattr(type(self), name, None), Signal)

    def add_user_signal(self, name: str) -> None:
        """Add a signal at run time (Godot's ``add_user_signal``).

        Raises:
            ValueError: a signal or attribute of that name exists already.
        """
        if self.has_signal(name) or hasattr(type(self), name):
            raise ValueError(f"{type(self).__name__} already has a member called {name!r}")
        self._signals[name] = BoundSignal(self, name)

    def connect(self, signal: str, callback: Callable[..., Any], *, one_shot: bool = False) -> None:
        """Connect ``callback`` to the signal called ``signal``."""
        self.get_signal(signal).connect(callback, one_shot=one_shot)

    def disconnect(self, signal: str, callback: Callable[..., Any]) -> None:
        """Disconnect ``callback`` from the signal called ``signal``."""
        self.get_signal(signal).disconnect(callback)

    def is_connected(self, signal: str, callback: Callable[..., Any]) -> bool:
        """Whether ``callback`` is connected to the signal called ``signal``."""
        return self.get_signal(signal).is_connected(callback)

    def emit_signal(self, signal: str, *args: Any) -> None:
        """Emit the signal called ``signal`` with ``args``."""
        self.get_signal(signal).emit(*args)

    def _emit(self, signal: str, *args: Any) -> None:
        """Emit a declared signal only if anything was ever connected (hot-path shortcut)."""
        bound = self._signals.get(signal)
        if bound is not None:
            bound.emit(*args)
