"""The non-blocking UDP socket every network output uses, loopback-only unless allowed."""

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


def open_udp(host: str, port: int, allow_remote: bool, what: str):
    """``(socket, (host, port))`` for sending ``what`` (:func:`check_destination` first)."""
    check_destination(host, port, allow_remote, what)
    sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_DGRAM)
    sock.setblocking(False)
    return sock, (host, port)
