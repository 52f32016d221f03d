"""Preallocated gyro sample storage: arrays, not per-sample Python objects.

:class:`GyroSamples` holds ``capacity`` rows of
``t`` (host monotonic time of the sample, s), ``index`` (frame number since the FIFO was
started, so a gap shows as a jump), ``rate`` (N×3 body rates, rad/s) and ``flags``
(:mod:`gyrostar.gyro.convert` FLAG_* bits). ``n`` rows are valid; drivers append.
"""

from __future__ import annotations

import numpy as np


class GyroSamples:
    def __init__(self, capacity: int):
        if capacity <= 0:
            raise ValueError(f"capacity must be positive, got {capacity}")
        self.capacity = int(capacity)
        self.t = np.zeros(capacity, np.float64)
        self.index = np.zeros(capacity, np.int64)
        self.rate = np.zeros((capacity, 3), np.float64)
        self.flags = np.zeros(capacity, np.uint8)
        self.n = 0
        self.gap_frames = 0   # frames known lost (overruns), summed over the flagged gaps
        self.gaps = 0         # number of flagged gaps
        self.saturated = 0    # samples with an axis at the range limit (FLAG_SAT_*)
        self.stuck_axis = 0   # samples flagged FLAG_STUCK_AXIS
        self.register_faults = 0  # gyro configuration found lost (and restored) during these reads

    @property
    def room(self) -> int:
        return self.capacity - self.n

    def clear(self) -> None:
        """Forget the rows (keep the arrays); gap and fault counters are reset too."""
        self.n = 0
        self.gap_frames = 0
        self.gaps = 0
        self.saturated = 0
        self.stuck_axis = 0
        self.register_faults = 0

    def view(self):
        """``(t, index, rate, flags)`` views of the valid rows."""
        n = self.n
        return self.t[:n], self.index[:n], self.rate[:n], self.flags[:n]
