"""I2C register access through smbus2, one shared ``SMBus`` per bus behind a lock.

:class:`I2CBus` owns one ``smbus2.SMBus`` (or any object with its methods, e.g. the mocks'
fake bus) and serialises transactions with a lock; :meth:`I2CBus.open` returns the one
instance per Linux bus number. :class:`I2CRegisters` is a :class:`~.base.RegisterBus` for one
device address. Reads up to 32 bytes use ``read_i2c_block_data``; longer bursts (FIFO
reads) use one ``i2c_rdwr`` with a write message (the register) and a read message, since
SMBus block transfers stop at 32 bytes (the kernel allows 8192 bytes per message).
"""

from __future__ import annotations

import threading

from ..errors import NotAvailableError
from .base import bus_error

SMBUS_BLOCK_MAX = 32
I2C_MSG_MAX = 8192


class I2CBus:
    """One I2C adapter shared by every device on it; every call holds the bus lock."""

    _open: dict[int, I2CBus] = {}
    _open_lock = threading.Lock()

    def __init__(self, smbus, name: str = "i2c"):
        self.smbus = smbus
        self.name = name
        self.lock = threading.Lock()
        from smbus2 import i2c_msg

        self._msg = i2c_msg

    @classmethod
    def open(cls, bus: int) -> I2CBus:
        """The shared :class:`I2CBus` for ``/dev/i2c-<bus>`` (opened on first use)."""
        with cls._open_lock:
            found = cls._open.get(bus)
            if found is None:
                try:
                    from smbus2 import SMBus
                except ImportError as exc:  # pragma: no cover - smbus2 is a hard dependency
                    raise NotAvailableError("smbus2 is not installed (pip install smbus2)") from exc
                try:
                    found = cls(SMBus(bus), name=f"/dev/i2c-{bus}")
                except (OSError, FileNotFoundError) as exc:
                    raise bus_error(f"/dev/i2c-{bus}", "open", exc) from exc
                cls._open[bus] = found
            return found

    def read(self, addr: int, reg: int, n: int) -> bytes:
        if n <= 0:
            raise ValueError(f"read length must be positive, got {n}")
        if n > I2C_MSG_MAX:
            raise ValueError(f"an I2C message carries at most {I2C_MSG_MAX} bytes, asked {n}")
        try:
            with self.lock:
                if n <= SMBUS_BLOCK_MAX:
                    return bytes(self.smbus.read_i2c_block_data(addr, reg, n))
                wr = self._msg.write(addr, [reg])
                rd = self._msg.read(addr, n)
                self.smbus.i2c_rdwr(wr, rd)
                return bytes(rd)
        except OSError as exc:
            raise bus_error(f"{self.name} addr 0x{addr:02X}", f"read of {n} byte(s) at reg 0x{reg:02X}",
                            exc) from exc

    def write(self, addr: int, reg: int, data: bytes) -> None:
        data = bytes(data)
        try:
            with self.lock:
                if len(data) == 1:
                    self.smbus.write_byte_data(addr, reg, data[0])
                elif len(data) <= SMBUS_BLOCK_MAX:
                    self.smbus.write_i2c_block_data(addr, reg, list(data))
                else:
                    self.smbus.i2c_rdwr(self._msg.write(addr, bytes([reg]) + data))
        except OSError as exc:
            raise bus_error(f"{self.name} addr 0x{addr:02X}",
                            f"write of {len(data)} byte(s) at reg 0x{reg:02X}", exc) from exc


class I2CRegisters:
    """The registers of one I2C device.

    ``autoincrement`` is OR-ed into the register address of multi-byte reads (ST parts such
    as the L3GD20H need bit 7 set to auto-increment; Bosch parts increment on their own).
    """

    def __init__(self, bus: I2CBus, address: int, autoincrement: int = 0):
        if not 0x03 <= address <= 0x77:
            raise ValueError(f"7-bit I2C address out of range: 0x{address:02X}")
        self.bus = bus
        self.address = address
        self.autoincrement = autoincrement

    def read(self, reg: int, n: int) -> bytes:
        return self.bus.read(self.address, reg | (self.autoincrement if n > 1 else 0), n)

    def write(self, reg: int, data: bytes) -> None:
        self.bus.write(self.address, reg | (self.autoincrement if len(data) > 1 else 0), data)

    def describe(self) -> str:
        return f"{self.bus.name} addr 0x{self.address:02X}"
