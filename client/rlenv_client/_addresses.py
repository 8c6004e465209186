"""Server addresses as text: ``HOST:PORT``, with IPv6 hosts in brackets (``[::1]:5000``)."""

from __future__ import annotations

from rlenv.transport.sockets import format_address

__all__ = ["format_address", "is_address", "parse_address"]


def parse_address(address: str) -> tuple[str, int]:
    """Split ``"HOST:PORT"`` (or ``"[IPV6]:PORT"``) into the host and the port.

    Raises:
        ValueError: ``address`` is not of that form, or its port is not a port (the message
            says which).
    """
    host, colon, port = address.rpartition(":")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    elif ":" in host:
        raise ValueError(
            f"expected HOST:PORT, got {address!r}: an IPv6 host goes in brackets, as in [::1]:5000"
        )
    if not colon or not host or not port.isdigit():
        raise ValueError(f"expected HOST:PORT, e.g. 127.0.0.1:5000, got {address!r}")
    if not 0 < int(port) <= 65535:
        raise ValueError(f"{address!r} has no port: ports run from 1 to 65535")
    return host, int(port)


def is_address(target: str) -> bool:
    """Whether a command line's ``target`` is ``HOST:PORT`` (else ``MODULE:CLASS`` or an id)."""
    host, _, port = target.rpartition(":")
    return bool(host) and port.isdigit()
