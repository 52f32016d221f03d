"""ST L3GD20H three-axis gyro behind the same :class:`~gyrostar.gyro.base.GyroDevice` interface.

Different in every detail from the BMI088, which is the point: WHO_AM_I 0x0F = 0xD7;
CTRL1 0x20 (bits 7:6 ODR with LOW_ODR=0: 100/200/400/800 Hz, bit 3 power, bits 2:0 axes);
CTRL4 0x23 bits 5:4 full scale (±245/500/2000 °/s at 8.75/17.5/70 m°/s per LSB), bit 7 BDU
(block data update: the MSBs latch with their LSBs); CTRL5 0x24 bit 6 FIFO enable;
FIFO_CTRL 0x2E (bits 7:5 mode, 0x40 = stream; bits 4:0 threshold); FIFO_SRC 0x2F (bit 7
threshold, bit 6 OVRN = FIFO completely filled, bit 5 empty, bits 4:0 level); 32 levels;
OUT_X_L..OUT_Z_H 0x28..0x2D, multi-byte reads need bit 7 of the address on I2C (0xA8) and
bit 6 on SPI; LOW_ODR 0x39 bit 2 software reset.

OVRN means "full", not "data lost": whether frames were overwritten is decided from the
time base, and no clearing is needed (unlike the BMI088's sticky overrun flag).
"""

from __future__ import annotations

import struct

from ..errors import DeviceError
from ..transport.spi import SPIRegisters
from .base import DPS, FifoGyro
from .registers import ROByte, RWByte
from .regtable import RegisterSetting

WHO_AM_I = 0xD7
I2C_ADDRESSES = (0x6A, 0x6B)
I2C_AUTOINCREMENT = 0x80
ODR_BITS = {100: 0b00, 200: 0b01, 400: 0b10, 800: 0b11}
FULL_SCALE = {245: (0b00, 8.75e-3), 500: (0b01, 17.5e-3), 2000: (0b10, 70e-3)}  # code, °/s per LSB
FIFO_LEVELS = 32
RESET_WAIT_S = 0.010


def register_table(odr_code: int, fs_code: int, watermark: int) -> tuple[RegisterSetting, ...]:
    """The L3GD20H's configuration, entry by entry (applied, verified, re-checked in flight)."""
    ctrl1 = odr_code << 6 | 0x0F   # ODR, bandwidth 00, power on, X/Y/Z on
    ctrl4 = 0x80 | fs_code << 4    # BDU, full scale, no self test, 4-wire SPI
    fifo = 0x40 | watermark        # stream mode, threshold
    return (
        RegisterSetting("LOW_ODR", 0x39, 0x00, 0x01),
        RegisterSetting("CTRL4", 0x23, ctrl4, 0xFF & ~ctrl4),
        RegisterSetting("CTRL1", 0x20, ctrl1, 0xFF & ~ctrl1),
        RegisterSetting("CTRL5", 0x24, 0x40, 0xBF),      # FIFO on (no reboot, no high-pass)
        RegisterSetting("FIFO_CTRL", 0x2E, fifo, 0xFF & ~fifo),
    )


def spi_registers(spi, name: str = "spi") -> SPIRegisters:
    """L3GD20H SPI access: read bit 0x80, auto-increment bit 0x40."""
    return SPIRegisters(spi, read_bit=0x80, multi_bit=0x40, dummy=0, name=name)


class L3gd20hGyro(FifoGyro):
    name = "L3GD20H"
    fifo_capacity = FIFO_LEVELS

    who_am_i = ROByte(0x0F)
    ctrl1 = RWByte(0x20)
    ctrl4 = RWByte(0x23)
    ctrl5 = RWByte(0x24)
    fifo_ctrl = RWByte(0x2E)
    fifo_src = ROByte(0x2F)
    low_odr = RWByte(0x39)

    def probe(self) -> None:
        got = self.who_am_i
        if got != WHO_AM_I:
            raise DeviceError(f"{self.describe()}: WHO_AM_I 0x{got:02X}, expected 0x{WHO_AM_I:02X} (not an L3GD20H)")

    def configure(self, odr_hz: float = 400, range_dps: float = 2000, watermark: int = 10) -> None:
        if odr_hz not in ODR_BITS:
            raise ValueError(f"L3GD20H ODR must be one of {sorted(ODR_BITS)} Hz, got {odr_hz}")
        if range_dps not in FULL_SCALE:
            raise ValueError(f"L3GD20H range must be one of {sorted(FULL_SCALE)} °/s, got {range_dps}")
        if not 1 <= watermark < FIFO_LEVELS:
            raise ValueError(f"watermark must be 1..{FIFO_LEVELS - 1} frames, got {watermark}")
        self.probe()
        self.low_odr = 0x04          # software reset
        self.clock.sleep(RESET_WAIT_S)
        self.probe()
        fs_code, dps_per_lsb = FULL_SCALE[range_dps]
        self._configure_table(register_table(ODR_BITS[odr_hz], fs_code, watermark))
        self.odr_hz = float(odr_hz)
        self.range_dps = float(range_dps)
        self.watermark = watermark
        self.scale = dps_per_lsb * DPS

    def self_test(self, samples: int = 16, min_shift_dps: float = 20.0) -> bool:
        """Electrostatic self test: CTRL4 ST bits (2:1) = 01 deflects the proof masses one way,
        11 the other way. Averages ``samples`` output samples in each state (the part kept
        still), passes when every axis moves by at least ``min_shift_dps`` with the sign
        ST0 − ST1 > 0. Leaves the part reset (call :meth:`configure` again)."""
        self.configure(400, 2000, 1)
        self.regs.write(0x24, bytes([0x00]))  # FIFO off: read the output registers directly
        means = []
        for st_bits in (0b01, 0b11):
            self.regs.write(0x23, bytes([0x80 | FULL_SCALE[2000][0] << 4 | st_bits << 1]))
            self.clock.sleep(0.05)  # let the output settle in the new state
            acc = [0.0, 0.0, 0.0]
            for _ in range(samples):
                self.clock.sleep(1.0 / self.odr_hz)
                raw = struct.unpack("<3h", self.regs.read(0x28, 6))
                for i in range(3):
                    acc[i] += raw[i] / samples
            means.append(acc)
        self.regs.write(0x23, bytes([0x80 | FULL_SCALE[2000][0] << 4]))
        self.low_odr = 0x04  # software reset
        self.clock.sleep(RESET_WAIT_S)
        self.odr_hz = 0.0
        lsb = FULL_SCALE[2000][1]
        shift = [(means[0][i] - means[1][i]) * lsb for i in range(3)]
        self.last_self_test_dps = shift
        return all(d >= min_shift_dps for d in shift)

    # --- FIFO hooks ---------------------------------------------------------------------
    def _fifo_level(self):
        src = self.regs.read(0x2F, 1)[0]
        if src & 0x20:
            return 0, False
        full = bool(src & 0x40)
        return (FIFO_LEVELS if full else src & 0x1F), full

    def _fifo_burst(self, n: int) -> bytes:
        return self.regs.read(0x28, 6 * n)

    def _after_overrun(self) -> bool:
        return False

    def _fifo_restart(self) -> None:
        self.regs.write(0x2E, bytes([0x00]))                   # bypass empties the FIFO
        self.regs.write(0x2E, bytes([0x40 | self.watermark]))  # stream mode, threshold
