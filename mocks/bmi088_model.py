"""Register-level model of the Bosch BMI088 gyroscope die, in simulated time.

The model produces samples at the configured ODR (with an optional ODR error in ppm, as a
real part's oscillator has) from a *rate source* — ``source(k, t) -> (n, 3)`` measured
rates in rad/s, sensor axes, for global sample indices ``k`` at model times ``t`` (s), e.g.
:class:`gyrostar.mocks.gyro_rates.TruthRates` over the simulator's gyro truth. Samples are
produced lazily, up to ``clock.now()``, at every bus transaction.

Semantics modelled (from the BMI08x Sensor API / datasheet facts in the hardware notes):

* chip id 0x0F at 0x00; reserved/read-only registers ignore writes;
* range 0x0F, bandwidth 0x10 (reads back with bit 7 set; the ODR follows the code),
  LPM1 0x11; soft reset (0xB6 → 0x14) restores defaults and the part NACKs for 30 ms;
* rate registers 0x02..0x07 int16 LE; reading an LSB latches its MSB;
* data-ready flag 0x0A bit 7 for 300 µs after each sample;
* FIFO (100 frames of 6 bytes): bypass / FIFO / stream modes (0x3E bits 7:6), watermark
  (0x3D), status 0x0E (bit 7 overrun, bits 6:0 count); stream mode overwrites the oldest
  frame when full and sets overrun; FIFO mode stops; writing 0x3E empties the FIFO and
  clears overrun; reading 0x3F pops whole frames and does not auto-increment;
* the watermark crossing time is kept as the FIFO interrupt edge on INT3/INT4;
* self test (0x3C): start bit 0; ready (bit 1) 10 ms later (a model choice: the datasheet
  figure was not verifiable); fail bit 2 when ``bist_fail`` is set; bit 4 rate_ok.

Truth for tests: :meth:`popped_indices` lists the global sample index of every frame
delivered through FIFO_DATA, in order; :meth:`truth_rates` gives the values behind them.
"""

from __future__ import annotations

import errno
import math
import threading

import numpy as np

from .register_model import RegisterModelBase

CHIP_ID = 0x0F
FIFO_FRAMES = 100
RESET_BUSY_S = 0.030
BIST_S = 0.010
DRDY_S = 300e-6
AHEAD = 64  # samples computed ahead per source call, for a source whose output is a function of its state()
RANGE_DPS = {0: 2000.0, 1: 1000.0, 2: 500.0, 3: 250.0, 4: 125.0}
ODR_HZ = {0: 2000.0, 1: 2000.0, 2: 1000.0, 3: 400.0, 4: 200.0, 5: 100.0, 6: 200.0, 7: 100.0}
WRITABLE = {0x0F, 0x10, 0x11, 0x14, 0x15, 0x16, 0x18, 0x1E, 0x34, 0x3C, 0x3D, 0x3E}
DEFAULTS = {0x00: CHIP_ID, 0x10: 0x80, 0x16: 0x0F}


def quantize(rates_rad: np.ndarray, dps_per_lsb: float) -> np.ndarray:
    """Rates (n×3 rad/s) → n×6 little-endian int16 bytes at ``dps_per_lsb`` °/s per LSB, saturating."""
    lsb = np.rint(np.asarray(rates_rad) * (180.0 / math.pi) / dps_per_lsb)
    return np.clip(lsb, -32768, 32767).astype("<i2").view(np.uint8).reshape(-1, 6)


class Bmi088GyroModel(RegisterModelBase):
    default_address = 0x68

    def __init__(self, clock, source, odr_error_ppm: float = 0.0, t_power_on: float | None = None):
        self.clock = clock
        self.source = source
        self.odr_error_ppm = odr_error_ppm
        self.bist_fail = False
        self.lock = threading.RLock()
        self._k_next = 0  # global index of the next sample to be produced
        self._ahead = None  # (first index, FIFO bytes, LSB, source state, ODR grid) computed ahead
        self._popped: list[np.ndarray] = []
        self._popped_raw: list[np.ndarray] = []
        self._power_on(clock.now() if t_power_on is None else t_power_on)

    # --- state ------------------------------------------------------------------------------
    def _power_on(self, now: float) -> None:
        self.regs = np.zeros(128, np.uint8)
        for reg, val in DEFAULTS.items():
            self.regs[reg] = val
        self.fifo_idx = np.zeros(0, np.int64)
        self.fifo_raw = np.zeros((0, 6), np.uint8)
        self.overrun = False
        self.latest_raw = np.zeros(6, np.uint8)
        self.latched = np.zeros(3, np.uint8)
        self.t_last_sample = -math.inf
        self.t_watermark = None
        self.watermark_edges: list[float] = []
        self._busy_until = now
        self._bist_ready_at = None
        self._restart_odr(now)

    @property
    def period(self) -> float:
        return 1.0 / (ODR_HZ[self.regs[0x10] & 0x0F & 0x07] * (1 + self.odr_error_ppm * 1e-6))

    @property
    def range_dps(self) -> float:
        return RANGE_DPS.get(int(self.regs[0x0F]) & 0x07, 2000.0)

    def _restart_odr(self, now: float) -> None:
        self._t_next = now + self.period
        # sample k is taken at t0 + T·(k − k0): one product from the (re)start, never a running
        # sum, so a sample's time depends on its index only (however the reads batch the
        # advances) and the samples computed ahead are the ones the next reads take
        self._grid = (self._t_next, self._k_next, self.period)

    def _sample_time(self, k):
        """Model time (s) of sample(s) ``k`` (int or int64 array) on the current ODR grid."""
        t0, k0, T = self._grid
        return t0 + T * (k - k0)

    def _advance(self) -> None:
        now = self.clock.now()
        if now < self._t_next or self.regs[0x11] & 0xA0:  # no samples before due, or suspended
            return
        T = self.period
        if T != self._grid[2]:
            self._grid = (self._t_next, self._k_next, T)
        n_new = int(math.floor((now - self._t_next) / T + 1e-9)) + 1
        k0 = self._k_next
        self._k_next += n_new
        self._t_next = self._sample_time(self._k_next)
        self.t_last_sample = self._sample_time(self._k_next - 1)
        mode = int(self.regs[0x3E]) & 0xC0
        before = len(self.fifo_idx)
        if mode == 0x80:    # stream: the newest frames survive
            keep = min(n_new, FIFO_FRAMES)
            j0 = n_new - keep
        elif mode == 0x40:  # FIFO: stops when full
            keep = max(min(n_new, FIFO_FRAMES - before), 0)
            j0 = 0
        else:               # bypass
            keep, j0 = 0, 0
        pos = np.arange(j0, j0 + keep, dtype=np.int64)
        if keep == 0 or pos[-1] != n_new - 1:
            pos = np.append(pos, n_new - 1)
        idx = k0 + pos
        raw = self._raw(idx)
        self.latest_raw = raw[-1].copy()
        if mode in (0x40, 0x80) and before + n_new > FIFO_FRAMES:
            self.overrun = True
        if keep:
            wm = int(self.regs[0x3D]) & 0x7F
            if wm and before < wm <= before + n_new and self.regs[0x1E] & 0x80:
                self.t_watermark = self._sample_time(k0 + wm - before - 1)
                if self.truth_log:
                    self.watermark_edges.append(self.t_watermark)
            self.fifo_idx = np.concatenate([self.fifo_idx, idx[:keep]])[-FIFO_FRAMES:]
            self.fifo_raw = np.concatenate([self.fifo_raw, raw[:keep]])[-FIFO_FRAMES:]

    def _raw(self, idx: np.ndarray) -> np.ndarray:
        """FIFO bytes (n, 6) of samples ``idx`` (taken at their times on the ODR grid): from the
        block computed ahead when it holds these samples on the same grid, range and source
        state; else from the source, with the next ``AHEAD`` samples (the ones the following
        advances will ask, however many samples each takes) computed in the same call."""
        lsb = self.range_dps / 32768.0
        state_of = getattr(self.source, "state", None)
        state = state_of() if state_of is not None else None
        a = self._ahead
        if a is not None and a[2] == lsb and a[3] == state and a[4] == self._grid:
            j0 = int(idx[0]) - a[0]
            j1 = int(idx[-1]) - a[0] + 1
            if j0 >= 0 and j1 <= len(a[1]) and j1 - j0 == len(idx):
                return a[1][j0:j1]     # (consecutive indices on the same grid: the same times)
        t = self._sample_time(idx)
        if state is None:
            return quantize(self.source(idx, t), lsb)
        k1 = int(idx[-1]) + 1
        ahead = k1 + np.arange(AHEAD)
        raw = quantize(self.source(np.concatenate([idx, ahead]), np.concatenate([t, self._sample_time(ahead)])), lsb)
        self._ahead = (k1, raw[len(idx):], lsb, state, self._grid)
        return raw[:len(idx)]

    def _check_busy(self) -> None:
        if self.clock.now() < self._busy_until:
            raise OSError(errno.EREMOTEIO, "Remote I/O error (BMI088 gyro busy after soft reset)")

    # --- register access (wire-independent) --------------------------------------------------
    def i2c_decode(self, reg_byte: int):
        return reg_byte & 0x7F, True

    def spi_decode(self, cmd: int):
        return cmd & 0x7F, bool(cmd & 0x80), True

    def read(self, reg: int, n: int, autoinc: bool = True) -> bytes:
        with self.lock:
            self._check_busy()
            self._advance()
            out = bytearray(n)
            addr = reg
            for i in range(n):
                if addr == 0x3F:
                    start = i
                    break
                out[i] = self._read_byte(addr)
                if autoinc:
                    addr = (addr + 1) & 0x7F
            else:
                return bytes(out)
            return bytes(out[:start]) + self._read_fifo(n - start)

    def _read_fifo(self, nbytes: int) -> bytes:
        frames = min(len(self.fifo_idx), (nbytes + 5) // 6)
        data = self.fifo_raw[:frames].tobytes()
        if self.truth_log:
            self._popped.append(self.fifo_idx[:frames].copy())
            self._popped_raw.append(self.fifo_raw[:frames].copy())
        self.fifo_idx = self.fifo_idx[frames:]
        self.fifo_raw = self.fifo_raw[frames:]
        empty = bytes([0x00, 0x80]) * 3  # an empty FIFO reads as -32768 on every axis
        data += empty * ((nbytes - len(data) + 5) // 6)
        return data[:nbytes]

    def _read_byte(self, addr: int) -> int:
        now = self.clock.now()
        if 0x02 <= addr <= 0x07:
            axis, msb = divmod(addr - 0x02, 2)
            if not msb:
                self.latched[axis] = self.latest_raw[2 * axis + 1]
                return int(self.latest_raw[2 * axis])
            return int(self.latched[axis])
        if addr == 0x0A:
            drdy = 0x80 if now - self.t_last_sample < DRDY_S else 0
            fifo = 0x10 if len(self.fifo_idx) >= max(int(self.regs[0x3D]) & 0x7F, 1) else 0
            return drdy | fifo
        if addr == 0x0E:
            return (0x80 if self.overrun else 0) | len(self.fifo_idx)
        if addr == 0x3C:
            val = int(self.regs[0x3C]) & 0x01
            if self._bist_ready_at is not None and now >= self._bist_ready_at:
                val = 0x02 | (0x04 if self.bist_fail else 0x10)
            return val
        if addr == 0x14:
            return 0
        return int(self.regs[addr])

    def write(self, reg: int, data: bytes, autoinc: bool = True) -> None:
        with self.lock:
            self._check_busy()
            self._advance()
            addr = reg
            for b in data:
                self._write_byte(addr, b)
                if autoinc:
                    addr = (addr + 1) & 0x7F

    def _write_byte(self, addr: int, val: int) -> None:
        now = self.clock.now()
        if addr not in WRITABLE:
            return
        if addr == 0x14:
            if val == 0xB6:
                k = self._k_next
                self._power_on(now)
                self._k_next = k
                self._busy_until = now + RESET_BUSY_S
            return
        if addr == 0x10:
            self.regs[0x10] = 0x80 | (val & 0x0F)
            self._restart_odr(now)
            return
        if addr == 0x3E:
            self.regs[0x3E] = val & 0xC3
            self.fifo_idx = self.fifo_idx[:0]
            self.fifo_raw = self.fifo_raw[:0]
            self.overrun = False
            return
        if addr == 0x3C:
            if val & 0x01:
                self._bist_ready_at = now + BIST_S
            self.regs[0x3C] = val & 0x01
            return
        self.regs[addr] = val

    def brownout(self) -> None:
        """A silent reset (a supply glitch): every register back to its reset value (FIFO in
        bypass, ODR code 0x00), the FIFO emptied, the global sample count running on; the
        part keeps answering and nothing tells the host."""
        with self.lock:
            self._advance()
            k = self._k_next
            self._power_on(self.clock.now())
            self._k_next = k

    # --- tests' view --------------------------------------------------------------------------
    def watermark_time(self) -> float | None:
        """Model time (s) of the latest FIFO watermark interrupt edge (None before any)."""
        with self.lock:
            self._advance()
            return self.t_watermark

    def popped_raw(self) -> np.ndarray:
        return np.concatenate(self._popped_raw) if self._popped_raw else np.zeros((0, 6), np.uint8)

    def frames_waiting(self) -> int:
        with self.lock:
            self._advance()
            return len(self.fifo_idx)
