"""Bosch BMI088 gyroscope die over I2C or SPI (the same code; the bus is a RegisterBus).

Register facts: ``docs/hardware-facts`` (Bosch BMI08x Sensor API). Chip id 0x0F at 0x00;
range 0x0F (0 = ±2000 … 4 = ±125 °/s, sensitivity 32768/range LSB per °/s); bandwidth 0x10
(0x03 = 400 Hz ODR / 47 Hz; bit 7 reads back 1); soft reset 0xB6 → 0x14 then 30 ms; FIFO
status 0x0E (bit 7 overrun, bits 6:0 frames), FIFO_CONFIG_0 0x3D watermark, FIFO_CONFIG_1 0x3E
mode (0x80 stream, XYZ), FIFO_DATA 0x3F (6-byte frames, no header); FIFO interrupt 0x15/0x18,
watermark enable 0x1E; self test 0x3C (bit0 start, bit1 ready, bit2 fail).

SPI: read = address | 0x80 and no dummy byte for the gyro die (use ``spi_registers``).
The overrun flag is cleared by writing FIFO_CONFIG_1, which also empties the FIFO.
"""

from __future__ import annotations

import numpy as np

from ..errors import DeviceError
from ..transport.spi import SPIRegisters
from .base import DPS, FifoGyro
from .registers import ROBits, ROByte, ROStruct, RWByte, WOByte
from .regtable import RegisterSetting

CHIP_ID = 0x0F
I2C_ADDRESSES = (0x68, 0x69)
RANGES_DPS = {2000: 0x00, 1000: 0x01, 500: 0x02, 250: 0x03, 125: 0x04}
BANDWIDTHS = {  # code: (ODR Hz, filter bandwidth Hz)
    0x00: (2000, 532), 0x01: (2000, 230), 0x02: (1000, 116), 0x03: (400, 47),
    0x04: (200, 23), 0x05: (100, 12), 0x06: (200, 64), 0x07: (100, 32),
}
SOFTRESET_CMD = 0xB6
RESET_WAIT_S = 0.030
FIFO_STREAM = 0x80
FIFO_CAPACITY = 100
SELF_TEST_TIMEOUT_S = 0.1


def register_table(range_code: int, bandwidth_code: int, watermark: int) -> tuple[RegisterSetting, ...]:
    """The gyro die's configuration, entry by entry (applied, verified, re-checked in flight)."""
    return (
        RegisterSetting("GYRO_RANGE", 0x0F, range_code, 0x07 & ~range_code),
        RegisterSetting("GYRO_BANDWIDTH", 0x10, bandwidth_code, 0x0F & ~bandwidth_code),  # bit 7 reads 1
        RegisterSetting("GYRO_LPM1", 0x11, 0x00, 0xA0),                  # normal mode (not (deep) suspend)
        RegisterSetting("FIFO_WM_ENABLE", 0x1E, 0x80),
        RegisterSetting("INT3_INT4_IO_CONF", 0x16, 0x01, 0x0E),          # INT3 active high, push-pull
        RegisterSetting("INT3_INT4_IO_MAP", 0x18, 0x04, 0xA1),           # FIFO interrupt → INT3 only
        RegisterSetting("GYRO_INT_CTRL", 0x15, 0x40, 0x80),              # FIFO interrupt on, data-ready off
        RegisterSetting("FIFO_CONFIG_0", 0x3D, watermark, 0x7F & ~watermark),
        RegisterSetting("FIFO_CONFIG_1", 0x3E, FIFO_STREAM, 0x43),       # stream mode, XYZ frames
    )


def spi_registers(spi, name: str = "spi") -> SPIRegisters:
    """The gyro die's SPI register access: read bit 0x80, auto-increment, no dummy byte."""
    return SPIRegisters(spi, read_bit=0x80, multi_bit=0, dummy=0, name=name)


class Bmi088Gyro(FifoGyro):
    """BMI088 gyroscope die; ``regs`` is an I2C or SPI :class:`~gyrostar.transport.RegisterBus`."""

    name = "BMI088 gyro"
    fifo_capacity = FIFO_CAPACITY

    chip_id = ROByte(0x00)
    rate_raw = ROStruct(0x02, "<3h")  # RATE_X_LSB..RATE_Z_MSB in one burst (LSB reads latch the MSBs)
    int_status_1 = ROByte(0x0A)
    fifo_status = ROByte(0x0E)
    fifo_frames = ROBits(7, 0x0E, 0)
    gyro_range = RWByte(0x0F)
    bandwidth = RWByte(0x10)
    lpm1 = RWByte(0x11)
    softreset = WOByte(0x14)
    int_ctrl = RWByte(0x15)
    int3_int4_io_conf = RWByte(0x16)
    int3_int4_io_map = RWByte(0x18)
    fifo_wm_enable = RWByte(0x1E)
    self_test_reg = RWByte(0x3C)
    fifo_config_0 = RWByte(0x3D)
    fifo_config_1 = RWByte(0x3E)

    def probe(self) -> None:
        got = self.chip_id
        if got != CHIP_ID:
            raise DeviceError(f"{self.describe()}: chip id 0x{got:02X}, expected 0x{CHIP_ID:02X} "
                              "(not a BMI088 gyro die, wrong address/chip select, or a stuck bus)")

    def rate_now(self) -> np.ndarray:
        """The current output registers as body rates (rad/s), bypassing the FIFO."""
        if self.scale <= 0:
            raise DeviceError(f"{self.describe()}: configure() before reading rates")
        return self.mounting @ (np.array(self.rate_raw, np.float64) * self.scale)

    def soft_reset(self) -> None:
        self.softreset = SOFTRESET_CMD
        self.clock.sleep(RESET_WAIT_S)

    def configure(self, odr_hz: float = 400, range_dps: float = 2000, watermark: int = 10,
                  bandwidth_code: int | None = None) -> None:
        """Reset, then apply and verify :func:`register_table`: range, ODR/bandwidth, normal
        power mode, FIFO watermark and stream mode (restarted by :meth:`start`), the FIFO
        interrupt on INT3."""
        if range_dps not in RANGES_DPS:
            raise ValueError(f"BMI088 range must be one of {sorted(RANGES_DPS)} °/s, got {range_dps}")
        if bandwidth_code is None:
            codes = [c for c, (odr, _) in BANDWIDTHS.items() if odr == odr_hz]
            if not codes:
                raise ValueError(f"BMI088 ODR must be one of {sorted({o for o, _ in BANDWIDTHS.values()})} Hz")
            bandwidth_code = max(codes, key=lambda c: -BANDWIDTHS[c][1])  # narrowest filter at that ODR
        if bandwidth_code not in BANDWIDTHS:
            raise ValueError(f"unknown BMI088 bandwidth code 0x{bandwidth_code:02X}")
        if not 1 <= watermark < FIFO_CAPACITY:
            raise ValueError(f"watermark must be 1..{FIFO_CAPACITY - 1} frames, got {watermark}")
        self.probe()
        self.soft_reset()
        self.probe()
        self._configure_table(register_table(RANGES_DPS[range_dps], bandwidth_code, watermark))
        self.odr_hz = float(BANDWIDTHS[bandwidth_code][0])
        self.range_dps = float(range_dps)
        self.watermark = watermark
        self.scale = (range_dps / 32768.0) * DPS

    def self_test(self) -> bool:
        """Built-in self test (BIST): start, poll ready, read the fail bit; then soft reset.
        The caller must :meth:`configure` again afterwards."""
        self.self_test_reg = 0x01
        t_end = self.clock.now() + SELF_TEST_TIMEOUT_S
        while True:
            status = self.self_test_reg
            if status & 0x02:
                break
            if self.clock.now() > t_end:
                raise DeviceError(f"{self.describe()}: self test did not finish within "
                                  f"{SELF_TEST_TIMEOUT_S * 1e3:.0f} ms (GYRO_SELF_TEST=0x{status:02X})")
            self.clock.sleep(0.001)
        self.soft_reset()
        self.odr_hz = 0.0
        return not status & 0x04

    # --- FIFO hooks ---------------------------------------------------------------------
    def _fifo_level(self):
        status = self.regs.read(0x0E, 1)[0]
        return status & 0x7F, bool(status & 0x80)

    def _fifo_burst(self, n: int) -> bytes:
        return self.regs.read(0x3F, 6 * n)

    def _after_overrun(self) -> bool:
        self.regs.write(0x3E, bytes([FIFO_STREAM]))  # clears the overrun flag and the FIFO
        return True

    def _fifo_restart(self) -> None:
        self.regs.write(0x3E, bytes([FIFO_STREAM]))
