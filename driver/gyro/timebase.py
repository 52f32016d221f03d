"""Frame-count time base: host time of FIFO frame ``k`` as ``t_ref + period·(k − k_ref)``.

FIFO frames carry no timestamp. Time is rebuilt from the frame count and anchors:

* an *event* anchor — frame ``k`` was sampled at host time ``t`` (the watermark or
  data-ready interrupt edge, timestamped by the host): exact up to interrupt latency;
* a *bound* — frame ``k`` was the newest in the FIFO when polled at host time ``t``, so
  ``t_k ≤ t < t_{k+1}``: the line must pass below ``(k, t)`` and above ``(k + 1, t)``.

Events feed a weighted least-squares line with exponential forgetting (``forget`` per
anchor), which tracks the gyro's ODR error and its drift against the host clock. Bounds
alone (no interrupt line) are solved as a feasibility problem every ``block`` polls: over
the last ``history`` bounds, the lines ``t = a + b·k`` with ``max(t_i − b(k_i+1)) < a ≤
min(t_i − b·k_i)`` form a convex polygon in (b, a); its centroid (vectorised over a grid of
periods) gives the line. The polygon shrinks as poll phases vary, to a small fraction of a
period. Before the first solution a
least-squares line through the interval midpoints stands in. The period is held within
±``max_rate_error`` of nominal.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from numba import njit


class _Fit:
    """Weighted LS sums with forgetting, in coordinates relative to the first point."""

    def __init__(self, forget: float):
        self.forget = forget
        self.s = [0.0] * 5  # w, w·x, w·y, w·x², w·x·y
        self.k0 = None
        self.t0 = 0.0
        self.n = 0
        self.k_min = math.inf
        self.k_max = -math.inf

    def add(self, k: float, t: float, w: float) -> None:
        if self.k0 is None:
            self.k0, self.t0 = k, t
        x, y, f, s = k - self.k0, t - self.t0, self.forget, self.s
        s[0] = s[0] * f + w
        s[1] = s[1] * f + w * x
        s[2] = s[2] * f + w * y
        s[3] = s[3] * f + w * x * x
        s[4] = s[4] * f + w * x * y
        self.n += 1
        self.k_min, self.k_max = min(self.k_min, k), max(self.k_max, k)

    def solve(self, nominal: float):
        """``(k_ref, t_ref, period or None)``; period None when the points span < 1 frame."""
        s = self.s
        mx, my = s[1] / s[0], s[2] / s[0]
        var = s[3] / s[0] - mx * mx
        period = (s[4] / s[0] - mx * my) / var if var > 1.0 else None
        return self.k0 + mx, self.t0 + my, period


@njit(cache=True)
def _width(x, y, b):
    hi = np.inf
    lo = -np.inf
    for i in range(x.shape[0]):
        u = y[i] - b * x[i]
        if u < hi:
            hi = u
        v = u - b
        if v > lo:
            lo = v
    return hi, lo


@njit(cache=True)
def polygon_centroid(x, y, b_min, b_max):
    """Lines ``y = a + b·x`` with ``y_i − b(x_i+1) < a ≤ y_i − b·x_i`` for all i: the centroid
    ``(b, a)`` of that convex polygon and its widest offset interval (≤ 0: infeasible)."""
    lo_b, hi_b = b_min, b_max
    for _ in range(60):  # the offset interval's width is concave in b: ternary search
        m1 = lo_b + (hi_b - lo_b) / 3.0
        m2 = hi_b - (hi_b - lo_b) / 3.0
        h1, l1 = _width(x, y, m1)
        h2, l2 = _width(x, y, m2)
        if h1 - l1 < h2 - l2:
            lo_b = m1
        else:
            hi_b = m2
    b_top = 0.5 * (lo_b + hi_b)
    h, l = _width(x, y, b_top)
    if h - l <= 0.0:
        return np.array([b_top, 0.5 * (h + l), h - l])
    edges = np.empty(2)
    for side in range(2):
        inside = b_top
        outside = b_min if side == 0 else b_max
        h, l = _width(x, y, outside)
        if h - l > 0.0:
            edges[side] = outside
            continue
        for _ in range(50):  # bisection for the polygon's edge
            mid = 0.5 * (inside + outside)
            h, l = _width(x, y, mid)
            if h - l > 0.0:
                inside = mid
            else:
                outside = mid
        edges[side] = inside
    area = 0.0
    sb = 0.0
    sa = 0.0
    widest = 0.0
    n = 64
    for j in range(n + 1):
        b = edges[0] + (edges[1] - edges[0]) * j / n
        h, l = _width(x, y, b)
        w = h - l
        if w > 0.0:
            area += w
            sb += w * b
            sa += w * 0.5 * (h + l)
            if w > widest:
                widest = w
    if area <= 0.0:
        h, l = _width(x, y, b_top)
        return np.array([b_top, 0.5 * (h + l), h - l])
    return np.array([sb / area, sa / area, widest])


class FrameTimebase:
    def __init__(self, nominal_period: float, forget: float = 0.97, max_rate_error: float = 0.05,
                 block: int = 32, history: int = 256, mid_forget: float = 0.998):
        self.nominal = float(nominal_period)
        self.forget = forget
        self.mid_forget = mid_forget
        self.max_rate_error = max_rate_error
        self.block = block
        self.history = history
        self.reset()

    def reset(self) -> None:
        self.k_ref = None
        self.t_ref = 0.0
        self.period = self.nominal
        self._events = _Fit(self.forget)
        self._coarse = _Fit(self.mid_forget)
        self._bounds: deque = deque(maxlen=self.history)
        self._new_bounds = 0
        self._since_event = 1 << 30
        self._solved = False
        self.anchors = 0
        self.envelope_width = math.nan  # s, width of the feasible offset interval at the last solve

    @property
    def ready(self) -> bool:
        return self.k_ref is not None

    def assume(self, k: int, t: float) -> None:
        """A guess until the first anchor: frame ``k`` was sampled near host time ``t`` (s),
        frames one nominal period apart (e.g. just after the FIFO was started)."""
        self.k_ref, self.t_ref, self.period = float(k), float(t), self.nominal

    def add_event(self, k: int, t: float) -> None:
        """Frame ``k`` was sampled at host time ``t`` (s)."""
        self._since_event = 0
        self._events.add(float(k), t, 1.0)
        self.anchors += 1
        self._use(self._events)

    def add_bound(self, k: int, t_poll: float) -> None:
        """Frame ``k`` was the newest in the FIFO at host time ``t_poll`` (s)."""
        self._since_event += 1
        self.anchors += 1
        self._bounds.append((k, t_poll))
        self._new_bounds += 1
        if self._since_event <= self.block and self._events.n >= 2:
            return  # interrupt anchors are recent: they are better than any envelope
        if not self._solved or self._new_bounds >= self.block:
            self._coarse.add(float(k), t_poll - 0.5 * self.period, 1.0)
            if len(self._bounds) >= self.block and self._solve():
                self._new_bounds = 0
                self._solved = True
            elif not self._solved:
                self._use(self._coarse)
            return
        # between solutions: keep the line's offset inside the recent bounds' envelope
        lo, hi = self._offset_interval(self.period, list(self._bounds)[-self.block:], self.k_ref)
        if lo < hi and not lo <= self.t_ref <= hi:
            self.t_ref = 0.5 * (lo + hi)

    @staticmethod
    def _offset_interval(b, bounds, k_ref):
        lo, hi = -math.inf, math.inf
        for kb, tb in bounds:
            x = kb - k_ref
            hi = min(hi, tb - b * x)
            lo = max(lo, tb - b * (x + 1))
        return lo, hi

    def _solve(self) -> bool:
        """Centroid of the feasible (period, offset) polygon of the stored bounds."""
        kb = np.array([k for k, _ in self._bounds], np.float64)
        tb = np.array([t for _, t in self._bounds], np.float64)
        b_min = self.nominal * (1 - self.max_rate_error)
        b_max = self.nominal * (1 + self.max_rate_error)
        while len(kb) >= self.block:
            k_ref, t0 = kb[-1], tb[-1]
            out = polygon_centroid(kb - k_ref, tb - t0, b_min, b_max)
            if out[2] > 0:
                self.period, self.k_ref, self.t_ref = float(out[0]), float(k_ref), t0 + float(out[1])
                self.envelope_width = float(out[2])
                return True
            kb, tb = kb[len(kb) // 2:], tb[len(tb) // 2:]  # inconsistent (rate changed): keep the recent half
        return False

    def _use(self, fit: _Fit) -> None:
        k_ref, t_ref, period = fit.solve(self.nominal)
        if period is not None:
            lo, hi = self.nominal * (1 - self.max_rate_error), self.nominal * (1 + self.max_rate_error)
            self.period = min(max(period, lo), hi)
        self.k_ref, self.t_ref = k_ref, t_ref

    def time_of(self, k: float) -> float:
        """Host time (s) of frame ``k``."""
        return self.t_ref + self.period * (k - self.k_ref)

    def latest_index_at(self, t: float) -> int:
        """Index of the newest frame sampled at or before host time ``t`` (s)."""
        return int(math.floor((t - self.t_ref) / self.period + self.k_ref + 1e-6))
