"""Byte and register transports: serial links (pyserial), I2C (smbus2), SPI (spidev).

Each transport is a small interface that the mocks in :mod:`gyrostar.mocks` implement too:

* :class:`~gyrostar.transport.base.RegisterBus` — ``read(reg, n)``/``write(reg, data)`` on
  one device: :class:`~gyrostar.transport.i2c.I2CRegisters`,
  :class:`~gyrostar.transport.spi.SPIRegisters`.
* :class:`~gyrostar.transport.serial_link.SerialLink` — COBS packets (0x00-delimited) over
  any pyserial URL, read by a reader thread.
"""

from .base import RegisterBus
from .i2c import I2CBus, I2CRegisters
from .serial_link import SerialLink
from .spi import SPIRegisters, open_spidev

__all__ = ["RegisterBus", "I2CBus", "I2CRegisters", "SPIRegisters", "open_spidev", "SerialLink"]
