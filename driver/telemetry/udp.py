"""The non-blocking UDP socket every network output uses, loopback-only unless allowed, its
destination resolved once when it is opened (never in the loop)."""

from __future__ import annotations

import socket

from ..errors import ConfigError

LOOPBACK = ("127.0.0.1", "localhost", "::1")


def check_destination(host: str, port: int, allow_remote: bool, what: str) -> None:
    """``ConfigError`` unless ``what`` may be sent to ``host:port``: another host than the
    loopback needs ``allow_remote`` (config ``outputs.allow_remote = true``)."""
    if not allow_remote and host not in LOOPBACK:
        raise ConfigError(f"{what} to {host} refused: set outputs.allow_remote = true to send it off this machine")
    if not 0 < port < 65536:
        raise ConfigError(f"{what} port {port} out of range 1..65535")


def resolve(host: str, port: int, key: str, what: str):
    """``(family, sockaddr)`` of ``host:port`` for UDP, looked up once: ``ConfigError`` naming
    the config ``key`` when the name does not resolve. A socket given the address sends without
    a lookup, so a name lookup (which can wait seconds on DNS) never runs in the loop."""
    try:
        # an IPv6 literal (a colon) as IPv6, any other name or address as IPv4 ("localhost": 127.0.0.1)
        infos = socket.getaddrinfo(host, port, socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as exc:
        why = exc.strerror if isinstance(exc, socket.gaierror) and exc.strerror else str(exc)
        raise ConfigError(f"{key} = '{host}' does not resolve ({why}): {what} needs a host name or address "
                          "this machine can look up") from None
    family, _type, _proto, _name, sockaddr = infos[0]
    return family, sockaddr


def open_udp(host: str, port: int, allow_remote: bool, what: str, key: str = "host"):
    """``(socket, sockaddr)`` for sending ``what`` (:func:`check_destination` first; the name
    resolved once, here: :func:`resolve`, ``key`` is its config key)."""
    check_destination(host, port, allow_remote, what)
    family, addr = resolve(host, port, key, what)
    sock = socket.socket(family, socket.SOCK_DGRAM)
    sock.setblocking(False)
    return sock, addr
