"""SPI register access through spidev (optional: only present on Linux boards).

:class:`SPIRegisters` is a :class:`~.base.RegisterBus` over one ``spidev.SpiDev`` (or any
object with ``xfer2``, e.g. the mocks' fake). A read sends ``reg | read_bit | multi_bit``,
then ``dummy`` don't-care bytes, then clocks ``n`` data bytes in the same chip-select
window. Bosch gyro die: read_bit 0x80, no dummy byte (the accelerometer die needs one);
ST L3GD20H: read_bit 0x80, multi_bit 0x40 for auto-increment.
"""

from __future__ import annotations

import threading

from ..errors import NotAvailableError
from .base import bus_error

SPIDEV_BUFSIZ = 4096  # the spidev kernel module's default bufsiz per transfer


def open_spidev(bus: int, device: int, mode: int = 3, max_speed_hz: int = 5_000_000):
    """Open ``/dev/spidev<bus>.<device>`` with spidev; :class:`NotAvailableError` if missing."""
    try:
        import spidev
    except ImportError as exc:
        raise NotAvailableError("SPI needs the spidev package (pip install 'gyrostar[linux]'), "
                                "which only builds on Linux") from exc
    spi = spidev.SpiDev()
    try:
        spi.open(bus, device)
    except OSError as exc:
        raise bus_error(f"/dev/spidev{bus}.{device}", "open", exc) from exc
    spi.mode = mode
    spi.max_speed_hz = max_speed_hz
    return spi


class SPIRegisters:
    """The registers of one SPI device (one chip select)."""

    def __init__(self, spi, read_bit: int = 0x80, multi_bit: int = 0, dummy: int = 0,
                 name: str = "spi", lock: threading.Lock | None = None):
        self.spi = spi
        self.read_bit = read_bit
        self.multi_bit = multi_bit
        self.dummy = dummy
        self.name = name
        self.lock = lock or threading.Lock()

    def read(self, reg: int, n: int) -> bytes:
        if n <= 0:
            raise ValueError(f"read length must be positive, got {n}")
        total = 1 + self.dummy + n
        if total > SPIDEV_BUFSIZ:
            raise ValueError(f"SPI transfer of {total} bytes exceeds spidev bufsiz {SPIDEV_BUFSIZ}")
        cmd = (reg & 0x3F if self.multi_bit else reg & 0x7F) | self.read_bit | (self.multi_bit if n > 1 else 0)
        try:
            with self.lock:
                rx = self.spi.xfer2([cmd] + [0] * (self.dummy + n))
        except OSError as exc:
            raise bus_error(self.describe(), f"read of {n} byte(s) at reg 0x{reg:02X}", exc) from exc
        if len(rx) != total:
            raise bus_error(self.describe(), f"read at reg 0x{reg:02X}",
                            OSError(f"short transfer: {len(rx)} of {total} bytes"))
        return bytes(rx[1 + self.dummy:])

    def write(self, reg: int, data: bytes) -> None:
        cmd = (reg & 0x3F if self.multi_bit else reg & 0x7F) | (self.multi_bit if len(data) > 1 else 0)
        try:
            with self.lock:
                self.spi.xfer2([cmd] + list(bytes(data)))
        except OSError as exc:
            raise bus_error(self.describe(), f"write of {len(data)} byte(s) at reg 0x{reg:02X}", exc) from exc

    def describe(self) -> str:
        return self.name
