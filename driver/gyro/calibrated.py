"""A gyro seen in camera axes and on camera time, through its calibration.

:class:`CalibratedGyro` wraps any :class:`~gyrostar.gyro.GyroDevice` and corrects every
sample it appends, in place, with one numba call per FIFO batch::

    ω_camera = M (ω_meas − b)        (rad/s, camera axes)
    t_camera = t_gyro + δt           (s, host clock)

``M = R_gyro→camera · correction`` (mounting rotation × scale/misalignment correction), ``b``
the gyro bias in gyro axes, ``δt`` the camera–gyro time offset: what
:func:`gyrostar.calibration.calfile.gyro_to_camera` returns. The loop's own drift estimate
then tracks only what the calibration left over.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .base import GyroDevice


@njit(cache=True)
def correct_samples(t, rate, start, stop, m, b, dt):
    """Rows ``start:stop`` of ``t`` (s) and ``rate`` (rad/s) → camera time and axes, in place."""
    for i in range(start, stop):
        x = rate[i, 0] - b[0]
        y = rate[i, 1] - b[1]
        z = rate[i, 2] - b[2]
        rate[i, 0] = m[0, 0] * x + m[0, 1] * y + m[0, 2] * z
        rate[i, 1] = m[1, 0] * x + m[1, 1] * y + m[1, 2] * z
        rate[i, 2] = m[2, 0] * x + m[2, 1] * y + m[2, 2] * z
        t[i] += dt


class CalibratedGyro(GyroDevice):
    """``gyro`` with its samples mapped by ``(m, b, dt)`` (see the module docstring)."""

    def __init__(self, gyro: GyroDevice, m, b, dt: float):
        self.raw = gyro
        self.m = np.ascontiguousarray(m, np.float64).reshape(3, 3)
        self.b = np.ascontiguousarray(b, np.float64).reshape(3)
        self.dt = float(dt)
        if not (np.all(np.isfinite(self.m)) and np.all(np.isfinite(self.b)) and np.isfinite(self.dt)):
            raise ValueError("gyro calibration must be finite")

    @property
    def odr_hz(self) -> float:
        return self.raw.odr_hz

    @property
    def range_dps(self) -> float:
        return self.raw.range_dps

    def describe(self) -> str:
        return f"{self.raw.describe()} (calibrated)" if hasattr(self.raw, "describe") else "calibrated gyro"

    def probe(self) -> None:
        self.raw.probe()

    def configure(self, odr_hz: float, range_dps: float, watermark: int) -> None:
        self.raw.configure(odr_hz, range_dps, watermark)

    def self_test(self) -> bool:
        return self.raw.self_test()

    def start(self) -> None:
        self.raw.start()

    def read(self, out, event_time: float | None = None, event_clock=None) -> int:
        n0 = out.n
        n = self.raw.read(out, event_time, event_clock)
        if n:
            correct_samples(out.t, out.rate, n0, n0 + n, self.m, self.b, self.dt)
        return n
