"""The register-bus interface every register device is driven through (I2C or SPI).

A :class:`RegisterBus` addresses one device. ``read(reg, n)`` returns ``n`` bytes starting at
register ``reg`` as one bus transaction (a burst; how the device increments — or does not,
for a FIFO data port — is the device's business); ``write(reg, data)`` writes bytes starting
at ``reg``. Failures raise :class:`gyrostar.errors.DeviceError` naming the bus, the device
and the register, never a bare ``OSError``.
"""

from __future__ import annotations

import errno
from typing import Protocol, runtime_checkable

from ..errors import DeviceError


@runtime_checkable
class RegisterBus(Protocol):
    def read(self, reg: int, n: int) -> bytes: ...

    def write(self, reg: int, data: bytes) -> None: ...

    def describe(self) -> str: ...


def bus_error(where: str, action: str, exc: OSError) -> DeviceError:
    """A :class:`DeviceError` for an ``OSError`` raised by a bus call, with a clear message."""
    code = getattr(exc, "errno", None)
    if code == errno.EREMOTEIO:
        why = "NACK (errno 121, EREMOTEIO): the device did not acknowledge"
    elif code == errno.ENXIO:
        why = "no device answers at this address (errno 6, ENXIO)"
    elif code == errno.ETIMEDOUT:
        why = "bus timeout (errno 110)"
    elif code is not None:
        why = f"errno {code} ({errno.errorcode.get(code, '?')}): {exc.strerror or exc}"
    else:
        why = str(exc) or type(exc).__name__
    err = DeviceError(f"{where}: {action} failed: {why}")
    err.errno = code
    return err
