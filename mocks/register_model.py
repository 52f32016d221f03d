"""What every gyro register model shares: its truth log and its wiring onto fake buses.

A model keeps ``_popped`` (arrays of the global sample indices delivered through its FIFO
data port, in order) and ``_t_next``/``_k_next``/``period`` (time and index of the next sample).
The truth log (and the BMI088 model's list of watermark edges) grows with every FIFO read
(≈ 80 kB/s and 13 kB/s at 400 Hz): long runs that do not need it (a soak) set
``truth_log = False``.
"""

from __future__ import annotations

import numpy as np

from .fake_smbus import FakeSMBus
from .fake_spidev import FakeSpiDev


class RegisterModelBase:
    default_address = 0x68
    truth_log = True      # keep the delivered-frame log that popped_indices() returns

    def popped_indices(self) -> np.ndarray:
        """Global indices of every frame delivered through the FIFO data port, in order."""
        return np.concatenate(self._popped) if self._popped else np.zeros(0, np.int64)

    @property
    def next_sample_index(self) -> int:
        """Global index of the next sample the part will produce (e.g. the first frame a
        FIFO started now will hold)."""
        with self.lock:
            self._advance()
            return self._k_next

    def sample_time(self, k) -> np.ndarray:
        """Model time (s) of global sample(s) ``k``, valid since the last ODR (re)start."""
        return self._t_next - self.period * (self._k_next - np.asarray(k, np.float64))

    def smbus(self, address: int | None = None, bus_hz: float | None = 400e3, wire=None) -> FakeSMBus:
        """A fresh fake I2C adapter (smbus2.SMBus methods) with this model at ``address``;
        ``wire``: what spends each transfer's time at ``bus_hz`` (an object with
        ``advance(s)``; default the model's clock, which must then be a simulated one)."""
        return FakeSMBus({address or self.default_address: self}, clock=wire or self.clock, bus_hz=bus_hz)

    def spidev(self, speed_hz: int = 5_000_000) -> FakeSpiDev:
        """A fake spidev device (SPI mode 3) with this model on its chip select."""
        spi = FakeSpiDev(self, clock=self.clock)
        spi.max_speed_hz = speed_hz
        return spi
