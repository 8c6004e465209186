"""Which ``Host`` and ``Origin`` headers a web server on this machine answers.

The inspector (:mod:`rlenv_tools.inspector._web`) and the HTTP gateway (:mod:`rlenv_tools.http`)
share these rules:

- the ``Host`` header must name one of the server's own names with its port: a DNS name that
  an attacker rebound to 127.0.0.1 (DNS rebinding) names another host, and is refused;
- an ``Origin`` header, when a browser sends one, must be the server's own: a page on another
  site can neither read nor change anything (no CORS header is ever sent either).

A server bound to every interface (``0.0.0.0``, ``::``) cannot know every name it is reached
by; it accepts any ``Host`` (its token guards it) and requires the ``Origin``, when sent, to be
the request's own (``http://`` and its ``Host``).
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["LOCAL_HOSTS", "OriginPolicy", "host_names"]

LOCAL_HOSTS = ("127.0.0.1", "localhost", "[::1]")
"""The names of this machine's loopback interface, as a ``Host`` header spells them."""

_WILDCARDS = frozenset({"0.0.0.0", "::", ""})


def host_names(bound: str) -> tuple[str, ...] | None:
    """The names a server bound to ``bound`` answers to; ``None`` when it is every interface.

    The loopback names always; a specific address or name besides (an IPv6 address in
    brackets, as a ``Host`` header spells it).
    """
    if bound in _WILDCARDS:
        return None
    name = f"[{bound}]" if ":" in bound and not bound.startswith("[") else bound
    return LOCAL_HOSTS if name in LOCAL_HOSTS else (*LOCAL_HOSTS, name)


class OriginPolicy:
    """The ``Host`` and ``Origin`` headers a server on ``port`` accepts (module docstring).

    Args:
        port: the port the server listens on.
        hosts: the names it answers to (see :func:`host_names`), or ``None`` for any (a
            server bound to every interface, which a token must guard).
    """

    def __init__(self, port: int, hosts: Iterable[str] | None = LOCAL_HOSTS) -> None:
        self.names = None if hosts is None else tuple(hosts)
        names = self.names or ()
        self.hosts = frozenset(name for host in names for name in (host, f"{host}:{port}"))
        self.origins = frozenset(f"http://{host}:{port}" for host in names)

    def refusal(self, host: str | None, origin: str | None) -> str | None:
        """Why a request with these headers is refused, or ``None`` when it is not."""
        if self.names is None:
            if origin is not None and origin != f"http://{host}":
                return "refused: a request from another origin"
            return None
        if host not in self.hosts:
            *first, last = self.names
            listed = f"{', '.join(first)} or {last}" if first else last
            return f"refused: the Host header must be {listed} with this port"
        if origin is not None and origin not in self.origins:
            return "refused: a request from another origin"
        return None
