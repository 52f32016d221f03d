"""Declarative register definitions, in the spirit of Adafruit's ``adafruit_register``.

A device class declares its registers as class attributes; reading or assigning the
attribute performs the bus transaction through the instance's ``regs``
(a :class:`gyrostar.transport.RegisterBus`)::

    class Bmi088Gyro:
        chip_id = ROByte(0x00)
        fifo_mode = RWBits(2, 0x3E, 6)      # bits 7:6 of FIFO_CONFIG_1

Every access is one bus transaction (read-modify-write for :class:`RWBits`), so errors
surface as :class:`gyrostar.errors.DeviceError` from the bus.
"""

from __future__ import annotations

import struct


class ROByte:
    """A read-only 8-bit register (value 0..255)."""

    def __init__(self, address: int):
        self.address = address

    def __get__(self, obj, objtype=None):
        if obj is None:
            return self
        return obj.regs.read(self.address, 1)[0]

    def __set__(self, obj, value):
        raise AttributeError(f"register 0x{self.address:02X} is read-only")


class RWByte(ROByte):
    """A read/write 8-bit register."""

    def __set__(self, obj, value: int):
        if not 0 <= int(value) <= 0xFF:
            raise ValueError(f"register 0x{self.address:02X}: value {value} is not a byte")
        obj.regs.write(self.address, bytes([int(value)]))


class WOByte(RWByte):
    """A write-only 8-bit register (a command register such as a soft reset)."""

    def __get__(self, obj, objtype=None):
        if obj is None:
            return self
        raise AttributeError(f"register 0x{self.address:02X} is write-only")


class ROBits:
    """``num_bits`` bits starting at bit ``lowest_bit`` of the register at ``address``."""

    def __init__(self, num_bits: int, address: int, lowest_bit: int):
        self.address = address
        self.shift = lowest_bit
        self.mask = ((1 << num_bits) - 1) << lowest_bit

    def __get__(self, obj, objtype=None):
        if obj is None:
            return self
        return (obj.regs.read(self.address, 1)[0] & self.mask) >> self.shift

    def __set__(self, obj, value):
        raise AttributeError(f"bits of register 0x{self.address:02X} are read-only")


class RWBits(ROBits):
    """Read/write bit field (read-modify-write, one read then one write)."""

    def __set__(self, obj, value: int):
        value = int(value)
        if value << self.shift & ~self.mask:
            raise ValueError(f"register 0x{self.address:02X}: {value} does not fit the bit field")
        old = obj.regs.read(self.address, 1)[0]
        obj.regs.write(self.address, bytes([(old & ~self.mask) | (value << self.shift)]))


class ROBit(ROBits):
    """A single read-only flag bit (returns bool)."""

    def __init__(self, address: int, bit: int):
        super().__init__(1, address, bit)

    def __get__(self, obj, objtype=None):
        if obj is None:
            return self
        return bool(super().__get__(obj, objtype))


class ROStruct:
    """A read-only multi-byte register block decoded with a :mod:`struct` format in one burst
    (e.g. ``"<3h"`` for three little-endian int16 read LSB first, which latches the MSBs)."""

    def __init__(self, address: int, fmt: str):
        self.address = address
        self.fmt = struct.Struct(fmt)

    def __get__(self, obj, objtype=None):
        if obj is None:
            return self
        return self.fmt.unpack(obj.regs.read(self.address, self.fmt.size))
