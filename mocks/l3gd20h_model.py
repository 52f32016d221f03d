"""Register-level model of the ST L3GD20H gyro, in simulated time (see :mod:`.bmi088_model`).

Modelled: WHO_AM_I 0x0F = 0xD7; CTRL1 0x20 (ODR bits 7:6 → 100/200/400/800 Hz with LOW_ODR
bit 0 clear, power bit 3); CTRL4 0x23 full scale bits 5:4 (8.75/17.5/70 m°/s per LSB);
CTRL5 0x24 bit 6 FIFO enable; FIFO_CTRL 0x2E (mode bits 7:5: 0 bypass, 1 FIFO, 2 stream;
threshold bits 4:0); FIFO_SRC 0x2F (bit 7 ≥ threshold, bit 6 OVRN = completely filled,
bit 5 empty, bits 4:0 level, 31 when full); 32 levels; OUT_X_L..OUT_Z_H 0x28..0x2D — with
the FIFO on, each 6 bytes read pops a frame and the address wraps 0x2D → 0x28; multi-byte
access needs bit 7 of the sub-address on I2C, bit 6 of the command on SPI (else the
address does not move); LOW_ODR 0x39 bit 2 software reset; self test: CTRL4 bits 2:1 =
01 adds +``self_test_dps`` to every axis, 11 subtracts it (a model choice: the datasheet's
self-test output change was not verifiable; set ``self_test_dps = 0`` for a failing part).
"""

from __future__ import annotations

import math
import threading

import numpy as np

from .bmi088_model import quantize
from .register_model import RegisterModelBase

WHO_AM_I = 0xD7
LEVELS = 32
ODR = {0: 100.0, 1: 200.0, 2: 400.0, 3: 800.0}
MDPS = {0: 8.75e-3, 1: 17.5e-3, 2: 70e-3, 3: 70e-3}
WRITABLE = set(range(0x20, 0x27)) | {0x2E, 0x30, 0x32, 0x33, 0x34, 0x35, 0x36, 0x37, 0x38, 0x39}


class L3gd20hModel(RegisterModelBase):
    default_address = 0x6A

    def __init__(self, clock, source, odr_error_ppm: float = 0.0, self_test_dps: float = 130.0):
        self.clock = clock
        self.self_test_dps = self_test_dps
        self.source = source
        self.odr_error_ppm = odr_error_ppm
        self.lock = threading.RLock()
        self._k_next = 0
        self._popped: list[np.ndarray] = []
        self._reset()

    def _reset(self) -> None:
        self.regs = np.zeros(128, np.uint8)
        self.regs[0x0F] = WHO_AM_I
        self.regs[0x20] = 0x07
        self.fifo_idx = np.zeros(0, np.int64)
        self.fifo_raw = np.zeros((0, 6), np.uint8)
        self.latest_raw = np.zeros(6, np.uint8)
        self._t_next = self.clock.now() + self.period

    @property
    def period(self) -> float:
        return 1.0 / (ODR[int(self.regs[0x20]) >> 6] * (1 + self.odr_error_ppm * 1e-6))

    @property
    def powered(self) -> bool:
        return bool(self.regs[0x20] & 0x08)

    def _mode(self) -> int:
        return (int(self.regs[0x2E]) >> 5) if self.regs[0x24] & 0x40 else 0

    def _advance(self) -> None:
        now = self.clock.now()
        if not self.powered:
            self._t_next = now + self.period
            return
        if now < self._t_next:
            return
        T = self.period
        n_new = int(math.floor((now - self._t_next) / T + 1e-9)) + 1
        k0, t_first = self._k_next, self._t_next
        self._k_next += n_new
        self._t_next += n_new * T
        mode, before = self._mode(), len(self.fifo_idx)
        if mode == 2:
            keep = min(n_new, LEVELS)
            j0 = n_new - keep
        elif mode == 1:
            keep, j0 = max(min(n_new, LEVELS - before), 0), 0
        else:
            keep, j0 = 0, 0
        pos = np.arange(j0, j0 + keep, dtype=np.int64)
        if keep == 0 or pos[-1] != n_new - 1:
            pos = np.append(pos, n_new - 1)
        rates = self.source(k0 + pos, t_first + T * pos)
        st = (int(self.regs[0x23]) >> 1) & 3
        if st in (1, 3):  # electrostatic self-test deflection
            rates = rates + (1 if st == 1 else -1) * self.self_test_dps * math.pi / 180.0
        raw = quantize(rates, MDPS[(int(self.regs[0x23]) >> 4) & 3])
        self.latest_raw = raw[-1].copy()
        if keep:
            self.fifo_idx = np.concatenate([self.fifo_idx, k0 + pos[:keep]])[-LEVELS:]
            self.fifo_raw = np.concatenate([self.fifo_raw, raw[:keep]])[-LEVELS:]

    def i2c_decode(self, reg_byte: int):
        return reg_byte & 0x7F, bool(reg_byte & 0x80)

    def spi_decode(self, cmd: int):
        return cmd & 0x3F, bool(cmd & 0x80), bool(cmd & 0x40)

    def read(self, reg: int, n: int, autoinc: bool = False) -> bytes:
        with self.lock:
            self._advance()
            if 0x28 <= reg <= 0x2D and self._mode() and autoinc:
                return self._read_fifo(reg, n)
            out = bytearray(n)
            addr = reg
            for i in range(n):
                out[i] = self._read_byte(addr)
                if autoinc:
                    addr = (addr + 1) & 0x7F
            return bytes(out)

    def _read_fifo(self, reg: int, n: int) -> bytes:
        off = reg - 0x28
        frames = min((off + n + 5) // 6, len(self.fifo_idx))
        stream = self.fifo_raw[:frames].tobytes()
        if self.truth_log:
            self._popped.append(self.fifo_idx[:frames].copy())
        self.fifo_idx, self.fifo_raw = self.fifo_idx[frames:], self.fifo_raw[frames:]
        stream += bytes(self.latest_raw) * ((off + n + 5) // 6 - frames)  # empty FIFO repeats the last sample
        return stream[off:off + n]

    def _read_byte(self, addr: int) -> int:
        if 0x28 <= addr <= 0x2D:
            return int(self.latest_raw[addr - 0x28])
        if addr == 0x2F:
            level = len(self.fifo_idx)
            wtm = int(self.regs[0x2E]) & 0x1F
            return ((0x80 if level >= wtm and wtm else 0) | (0x40 if level >= LEVELS else 0)
                    | (0x20 if level == 0 else 0) | min(level, 31))
        return int(self.regs[addr])

    def write(self, reg: int, data: bytes, autoinc: bool = False) -> None:
        with self.lock:
            self._advance()
            addr = reg
            for b in data:
                self._write_byte(addr, b)
                if autoinc:
                    addr = (addr + 1) & 0x7F

    def _write_byte(self, addr: int, val: int) -> None:
        if addr not in WRITABLE:
            return
        if addr == 0x39 and val & 0x04:
            self._reset()
            return
        if addr == 0x2E and (val >> 5) == 0:
            self.fifo_idx, self.fifo_raw = self.fifo_idx[:0], self.fifo_raw[:0]
        if addr == 0x20 and (val ^ int(self.regs[0x20])) & 0xC8:
            self.regs[0x20] = val
            self._t_next = self.clock.now() + self.period
            return
        self.regs[addr] = val

    def brownout(self) -> None:
        """A silent reset (a supply glitch): registers back to their reset values (powered
        down, FIFO off), the FIFO emptied, the global sample count running on."""
        with self.lock:
            self._advance()
            self._reset()

    def watermark_time(self):
        return None
