"""Clock synchronisation between the head MCU's microsecond clock and the host monotonic clock.

One TIME_SYNC exchange gives four times: host send ``t1`` and receive ``t4`` (host
monotonic, s) and MCU receive ``rx`` and transmit ``tx`` (MCU µs). As in NTP,

    offset θ = ((rx − t1) + (tx − t4)) / 2      (MCU − host, µs, at host time (t1 + t4)/2)
    delay  δ = (t4 − t1) − (tx − rx)            (round-trip link time, µs)

Link jitter and queueing only ever add delay, and an exchange whose delay exceeds the
smallest by ``e`` has an offset error of at most ``e/2``, so :class:`ClockSync` keeps the
last ``window`` exchanges and fits ``θ(t) = offset + drift·(t − t_ref)`` by weighted least
squares with weights ``1/(e² + slack_us²)``: the offset (µs) and the drift
(MCU rate error against the host, dimensionless, ×1e6 for ppm) are estimated continuously
as exchanges arrive. :meth:`mcu_to_host` maps MCU µs (e.g. an exposure mid-time) into
host monotonic seconds.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ..errors import DeviceError


class ClockSync:
    def __init__(self, window: int = 256, slack_us: float = 20.0, min_span_s: float = 0.5):
        self.window = window
        self.slack_us = slack_us
        self.min_span_s = min_span_s
        self._ex: deque = deque(maxlen=window)  # (t_mid_s, theta_us, delay_us)
        self.offset_us = 0.0      # θ at t_ref
        self.drift = 0.0          # dθ/dt (µs per µs)
        self.t_ref = 0.0          # host s
        self.count = 0
        self.rejected = 0

    @property
    def ready(self) -> bool:
        return self.count > 0

    def add(self, t1: float, rx_us: int, tx_us: int, t4: float) -> None:
        """One exchange: host send/receive times (s), MCU receive/transmit times (µs)."""
        if not (t4 >= t1 and tx_us >= rx_us):
            self.rejected += 1
            return
        t1_us, t4_us = t1 * 1e6, t4 * 1e6
        theta = ((rx_us - t1_us) + (tx_us - t4_us)) / 2.0
        delay = (t4_us - t1_us) - (tx_us - rx_us)
        if delay < 0:  # impossible unless the clocks stepped
            self.rejected += 1
            return
        self._ex.append((0.5 * (t1 + t4), theta, delay))
        self.count += 1
        self._fit()

    def _fit(self) -> None:
        ex = np.array(self._ex)
        t, theta, delay = ex[:, 0], ex[:, 1], ex[:, 2]
        extra = delay - delay.min()
        w = 1.0 / (extra * extra + self.slack_us * self.slack_us)
        sw = w.sum()
        self.t_ref = float(np.dot(w, t) / sw)
        th_mean = float(np.dot(w, theta) / sw)
        dt = t - self.t_ref
        if t.max() - t.min() >= self.min_span_s:
            self.drift = float(np.dot(w * dt, theta - th_mean) / np.dot(w * dt, dt)) * 1e-6
        # else: keep the previous drift estimate; a short baseline cannot resolve it
        self.offset_us = th_mean

    def offset_at(self, t_host: float) -> float:
        """Estimated MCU − host offset (µs) at host time ``t_host`` (s)."""
        return self.offset_us + self.drift * (t_host - self.t_ref) * 1e6

    def mcu_to_host(self, mcu_us: float) -> float:
        """Host monotonic time (s) of the MCU clock reading ``mcu_us``."""
        if not self.ready:
            raise DeviceError("no TIME_SYNC exchange yet: MCU times cannot be mapped to host time")
        # host = mcu − θ(host); θ is linear in host time, solve exactly.
        a = self.offset_us - self.drift * self.t_ref * 1e6
        return (mcu_us - a) / (1.0 + self.drift) * 1e-6

    def host_to_mcu(self, t_host: float) -> float:
        return t_host * 1e6 + self.offset_at(t_host)

    @property
    def min_delay_us(self) -> float:
        return min(d for _, _, d in self._ex) if self._ex else float("nan")
