"""Frame-count time base: host time of FIFO frame ``k`` as ``t_ref + period·(k − k_ref)``.

FIFO frames carry no timestamp. Time is rebuilt from the frame count and anchors:

* an *event* anchor — frame ``k`` was sampled at host time ``t`` (the watermark or
  data-ready interrupt edge, timestamped by the host);
* a *bound* anchor — frame ``k`` was the newest in the FIFO when polled at host time ``t``,
  so it was sampled in ``(t − period, t]``; it counts as ``t − period/2`` with a lower weight.

A weighted least-squares line through the anchors with exponential forgetting (so the
gyro's own ODR error and drift against the host clock are tracked) gives ``t_ref`` and
``period``; the period is held within ±``max_rate_error`` of nominal. When only bound
anchors are recent, the line's offset is then placed mid-way in the intersection of the
recent bounds' intervals (a lower/upper envelope), which shrinks to a small fraction of a
period as poll phases vary.
"""

from __future__ import annotations

import math
from collections import deque


class FrameTimebase:
    def __init__(self, nominal_period: float, forget: float = 0.97, max_rate_error: float = 0.05,
                 bound_weight: float = 0.05, bound_forget: float = 0.998):
        self.nominal = float(nominal_period)
        self.forget = forget
        self.max_rate_error = max_rate_error
        self.bound_weight = bound_weight
        self.bound_forget = bound_forget  # poll bounds are coarse: average them over a longer memory
        self.reset()

    def reset(self) -> None:
        self.k_ref = None
        self.t_ref = 0.0
        self.period = self.nominal
        self._s = [0.0] * 5  # sums w, w·k, w·t, w·k², w·k·t  (k, t relative to the first anchor)
        self._k0 = 0
        self._t0 = 0.0
        self.anchors = 0
        self._bounds: deque = deque(maxlen=48)
        self._since_event = 1 << 30

    @property
    def ready(self) -> bool:
        return self.k_ref is not None

    def add_event(self, k: int, t: float) -> None:
        """Frame ``k`` was sampled at host time ``t`` (s)."""
        self._since_event = 0
        self._add(k, t, 1.0, self.forget)

    def add_bound(self, k: int, t_poll: float) -> None:
        """Frame ``k`` was the newest in the FIFO at host time ``t_poll`` (s)."""
        self._since_event += 1
        self._add(k, t_poll - 0.5 * self.period, self.bound_weight, self.bound_forget)
        self._bounds.append((k, t_poll))
        if self._since_event > self._bounds.maxlen:
            lo, hi = -math.inf, math.inf
            for kb, tb in self._bounds:
                r = tb - self.time_of(kb)
                hi = min(hi, r)
                lo = max(lo, r - self.period)
            if lo < hi:
                self.t_ref += 0.5 * (lo + hi)

    def _add(self, k: int, t: float, w: float, f: float) -> None:
        if self.k_ref is None:
            self._k0, self._t0 = int(k), float(t)
        s = self._s
        x = float(k - self._k0)
        y = t - self._t0
        s[0] = s[0] * f + w
        s[1] = s[1] * f + w * x
        s[2] = s[2] * f + w * y
        s[3] = s[3] * f + w * x * x
        s[4] = s[4] * f + w * x * y
        self.anchors += 1
        mx, my = s[1] / s[0], s[2] / s[0]
        var = s[3] / s[0] - mx * mx
        period = self.nominal
        if var > 1.0:  # anchors span more than a frame: fit the slope
            period = (s[4] / s[0] - mx * my) / var
            lo, hi = self.nominal * (1 - self.max_rate_error), self.nominal * (1 + self.max_rate_error)
            period = min(max(period, lo), hi)
        self.period = period
        # Reference at the weighted mean anchor (best-determined point of the line).
        self.k_ref = self._k0 + mx
        self.t_ref = self._t0 + my

    def time_of(self, k: float) -> float:
        """Host time (s) of frame ``k``."""
        return self.t_ref + self.period * (k - self.k_ref)

    def latest_index_at(self, t: float) -> int:
        """Index of the newest frame sampled at or before host time ``t`` (s)."""
        return int(math.floor((t - self.t_ref) / self.period + self.k_ref + 1e-6))
