"""An SPI device with spidev.SpiDev's methods (``xfer2``, ``xfer``, ``readbytes``, mode,
speed), backed by one register model behind one chip select.

The model implements ``spi_decode(cmd) -> (reg, is_read, autoinc)``, ``read`` and ``write``
(see :mod:`.fake_smbus`). The byte clocked out during the command byte is 0xFF (MISO idle).
With ``clock`` set, each transfer advances it by its wire time at ``max_speed_hz`` (in real
time :class:`~.fake_smbus.SleepingWire` takes the clock's place and sleeps it).
"""

from __future__ import annotations


class FakeSpiDev:
    def __init__(self, model, clock=None):
        self.model = model
        self.clock = clock
        self.mode = 3
        self.max_speed_hz = 5_000_000
        self.bits_per_word = 8
        self.transfers = 0
        self.opened = True

    def open(self, bus, device):
        self.opened = True

    def close(self):
        self.opened = False

    def xfer2(self, values, speed_hz=0, delay_usecs=0, bits_per_word=0):
        if not self.opened:
            raise OSError(9, "Bad file descriptor (SPI device closed)")
        values = list(values)
        self.transfers += 1
        reg, is_read, inc = self.model.spi_decode(values[0])
        n = len(values) - 1
        if is_read:
            rx = [0xFF] + list(self.model.read(reg, n, inc)) if n else [0xFF]
        else:
            if n:
                self.model.write(reg, bytes(values[1:]), inc)
            rx = [0xFF] * len(values)
        if self.clock is not None and self.max_speed_hz:  # wire time, after the device answered
            self.clock.advance(8 * len(values) / float(self.max_speed_hz))
        return rx

    xfer = xfer2

    def readbytes(self, n):
        return [0xFF] * n
