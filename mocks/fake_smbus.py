"""An I2C adapter with smbus2.SMBus's methods, backed by register models (no kernel needed).

:class:`FakeSMBus` routes each transaction to the register model at the addressed 7-bit
address; an address with no model raises ``OSError(errno.EREMOTEIO)`` (a NACK), as the
i2c-dev driver does. It honours smbus2's limits (block transfers ≤ 32 bytes) and implements
``i2c_rdwr`` with real :class:`smbus2.i2c_msg` objects: a write message sets the register
pointer (and writes any further bytes), a read message reads from the pointer.

A model implements ``i2c_decode(reg_byte) -> (reg, autoinc)``, ``read(reg, n, autoinc)`` and
``write(reg, data, autoinc)``. With ``clock`` and ``bus_hz`` set, every transaction advances
the simulated clock by its wire time (9 clocks per byte plus start/stop) after the device
has answered from its state at the start of the transfer, so bursts take time as on a real bus;
in real time :class:`SleepingWire` takes the clock's place and spends that time asleep.
"""

from __future__ import annotations

import ctypes
import errno
import threading
import time

from smbus2 import i2c_msg

I2C_M_RD = 0x0001
BLOCK_MAX = 32


def nack(addr: int) -> OSError:
    return OSError(errno.EREMOTEIO, f"Remote I/O error (no ACK from 0x{addr:02X})")


class SleepingWire:
    """A transfer's wire time spent in real time: :meth:`advance` sleeps it with the
    interpreter lock released, as a thread blocked in i2c-dev's or spidev's ioctl waits for
    the bus (a real-time run's emulated gyro, on either bus; a simulated clock advances
    instead)."""

    def advance(self, dt: float) -> float:
        time.sleep(dt)
        return dt


class FakeSMBus:
    def __init__(self, devices: dict | None = None, clock=None, bus_hz: float | None = None):
        self.devices = dict(devices or {})
        self.clock = clock
        self.bus_hz = bus_hz
        self._pointer: dict[int, int] = {}
        self.transactions = 0
        self.lock = threading.Lock()

    def attach(self, addr: int, model) -> None:
        self.devices[addr] = model

    # --- plumbing ---------------------------------------------------------------------------
    def _dev(self, addr: int):
        dev = self.devices.get(addr)
        if dev is None:
            raise nack(addr)
        return dev

    def _wire(self, nbytes: int) -> None:
        self.transactions += 1
        if self.clock is not None and self.bus_hz:
            self.clock.advance((9 * (nbytes + 1) + 2) / self.bus_hz)

    def _read(self, addr, reg, n):
        dev = self._dev(addr)
        r, inc = dev.i2c_decode(reg)
        data = dev.read(r, n, inc)  # the device answers from the state at the start of the transfer
        self._wire(2 + n)
        return data

    def _write(self, addr, reg, data):
        dev = self._dev(addr)
        r, inc = dev.i2c_decode(reg)
        self._wire(2 + len(data))
        dev.write(r, bytes(data), inc)

    # --- smbus2.SMBus methods ---------------------------------------------------------------
    def open(self, bus):
        return None

    def close(self):
        return None

    def read_byte_data(self, i2c_addr, register, force=None):
        return self._read(i2c_addr, register, 1)[0]

    def write_byte_data(self, i2c_addr, register, value, force=None):
        self._write(i2c_addr, register, [value & 0xFF])

    def read_word_data(self, i2c_addr, register, force=None):
        b = self._read(i2c_addr, register, 2)
        return b[0] | b[1] << 8

    def read_i2c_block_data(self, i2c_addr, register, length, force=None):
        if length > BLOCK_MAX:
            raise ValueError(f"Desired block length over {BLOCK_MAX} bytes")
        return list(self._read(i2c_addr, register, length))

    def write_i2c_block_data(self, i2c_addr, register, data, force=None):
        if len(data) > BLOCK_MAX:
            raise ValueError(f"Data length cannot exceed {BLOCK_MAX} bytes")
        self._write(i2c_addr, register, data)

    def i2c_rdwr(self, *i2c_msgs):
        with self.lock:
            for msg in i2c_msgs:
                addr = msg.addr
                if msg.flags & I2C_M_RD:
                    dev = self._dev(addr)
                    reg = self._pointer.get(addr, 0)
                    r, inc = dev.i2c_decode(reg)
                    data = dev.read(r, msg.len, inc)
                    self._wire(1 + msg.len)
                    ctypes.memmove(msg.buf, data, msg.len)
                else:
                    raw = bytes(msg)
                    dev = self._dev(addr)
                    if not raw:
                        continue
                    self._pointer[addr] = raw[0]
                    if len(raw) > 1:
                        r, inc = dev.i2c_decode(raw[0])
                        self._wire(1 + len(raw))
                        dev.write(r, raw[1:], inc)
                    else:
                        self._wire(len(raw))       # the register pointer alone: address and one byte


__all__ = ["FakeSMBus", "i2c_msg", "nack"]
