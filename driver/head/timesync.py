"""Clock synchronisation between the head MCU's microsecond clock and the host monotonic clock.

One TIME_SYNC exchange gives four times: host send ``t1`` and receive ``t4`` (host
monotonic, s) and MCU receive ``rx`` and transmit ``tx`` (MCU µs). With θ the MCU − host
offset, each exchange measures both one-way delays, each plus or minus θ:

    u = rx − t1 = θ + up        d = t4 − tx = down − θ        (µs)
    delay δ = u + d = up + down (the round trip, µs)

Queueing, jitter and late reading only ever *add* delay, and often on one side only (a
reply waiting behind frame bytes, a host thread that reads it late): the NTP midpoint
``(u − d)/2`` of such an exchange is off by half that extra delay, always the same way. So
:class:`ClockSync` keeps the last ``window`` exchanges and uses each direction's *minimum*:
with θ(t) = offset + b·(t − t_ref), the lower envelopes ``min(u − b·dt) = offset + up_min``
and ``min(d + b·dt) = down_min − offset`` give

    offset = (min(u − b·dt) − min(d + b·dt)) / 2        (up_min = down_min)

Each direction's minimum may come from a different exchange: a reply that waited does not
spoil its request's clean trip. With symmetric jitter the minima converge on the true
delays; with one-sided delays the midpoint's bias (half of them) never enters.

The drift b (µs/s = ppm) is a quantile regression (:func:`drift_fit`): one slope, fitted to
the lower tenth of each direction's delays at once (pinball loss, convex in b), so that
neither a single lucky exchange nor the one-sided tail sets it. Its prior costs ``slack_us``
of envelope per ``drift_sigma_ppm`` of drift (the MCU oscillator's tolerance), so a
baseline that a few exchanges leave undetermined does not tilt the line.

A clock that steps (a host suspend stops CLOCK_MONOTONIC while the MCU counts on; an MCU
reset behind a UART the host keeps open) puts a new exchange outside what the window allows:
the envelopes bound θ hard, ``−min(d + b·dt) ≤ θ − b·dt ≤ min(u − b·dt)`` (no delay is
negative), so one direction's delay against the model is below minus half the envelopes'
round trip — faster than instantaneous, which no queueing does. Beyond that bound and the
model's own error it is a step: :data:`STEP_MIN_US`, plus the oscillator's tolerance
(``drift_sigma_ppm``) over the time since the newest exchange (a head that was away a minute
is allowed 12 ms more). With clean minima in the window, steps of a few ms are found; right
after a start whose every reply waited, the bound is as wide as the waits. The exchanges
before it describe another clock, so the window restarts from that exchange
(:attr:`ClockSync.steps` counts it; the drift, the oscillator's, is kept). A step smaller
than the tolerance leaves at most half of it in the offset.

A reply longer than its request spends longer on a slow wire: :meth:`add` takes that
known down − up difference (``asym_us``, the two frames' serialisation times; link latency
is the same both ways) and removes it from ``d``. :meth:`mcu_to_host` maps MCU µs (e.g.
an exposure mid-time) into host monotonic seconds.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numba import njit

from ..errors import DeviceError

_DRIFT_SEARCH_PPM = 2000.0   # the drift is searched in ±this (an MCU oscillator is far better)
DRIFT_QUANTILE = 0.1         # the drift fits each direction's lower tenth, not its single minimum
# An MCU time the model maps more than this (s) outside the host times that bound it (a capture
# between its request and its reply, a streamed frame's exposure end before its arrival) means
# the model no longer fits the head's clock (it stepped): callers re-synchronise
CLOCK_CHECK_TOL_S = 2e-3
# µs: a one-way delay this far below zero against the model, at the newest exchange's time, is a
# clock step (the same tolerance as the frame check's). Queueing only adds delay; the model's own
# error there is tens of µs (its envelopes' scatter; a drift fitted over a 0.5 s baseline through
# 200 µs of jitter is off by up to ~400 ppm, 0.4 ms a second on)
STEP_MIN_US = CLOCK_CHECK_TOL_S * 1e6


@njit(cache=True)
def _pinball(r, q, k):
    """Pinball loss of ``r`` about its ``k``-th smallest value (the q-quantile)."""
    qv = np.sort(r)[k]
    c = 0.0
    for x in r:
        e = x - qv
        c += q * e if e >= 0.0 else (q - 1.0) * e
    return c


@njit(cache=True)
def drift_fit(dt, u, d, q, penalty, search_ppm):
    """The drift b (µs/s) minimising both directions' pinball loss about their q-quantile
    lines ``u − b·dt`` and ``d + b·dt`` plus ``penalty·|b|`` (convex in b): golden-section
    search over ±``search_ppm``. ``dt`` s from the reference time, ``u``/``d`` µs."""
    k = int(q * (dt.shape[0] - 1))
    gr = 0.6180339887498949
    a, b = -search_ppm, search_ppm
    c, e = b - gr * (b - a), a + gr * (b - a)
    fc = penalty * abs(c) + _pinball(u - c * dt, q, k) + _pinball(d + c * dt, q, k)
    fe = penalty * abs(e) + _pinball(u - e * dt, q, k) + _pinball(d + e * dt, q, k)
    for _ in range(50):
        if fc > fe:            # the minimum is in [c, b]
            a, c, fc = c, e, fe
            e = a + gr * (b - a)
            fe = penalty * abs(e) + _pinball(u - e * dt, q, k) + _pinball(d + e * dt, q, k)
        else:                  # in [a, e]
            b, e, fe = e, c, fc
            c = b - gr * (b - a)
            fc = penalty * abs(c) + _pinball(u - c * dt, q, k) + _pinball(d + c * dt, q, k)
    return 0.5 * (a + b)


class ClockSync:
    def __init__(self, window: int = 256, slack_us: float = 20.0, min_span_s: float = 0.5,
                 drift_sigma_ppm: float = 200.0):
        self.window = window
        self.slack_us = slack_us
        self.min_span_s = min_span_s
        self.drift_sigma_ppm = drift_sigma_ppm
        self._ex: deque = deque(maxlen=window)  # (t_mid_s, u_us, d_us)
        self.offset_us = 0.0      # θ at t_ref
        self.drift = 0.0          # dθ/dt (µs per µs)
        self.t_ref = 0.0          # host s
        self.count = 0
        self.rejected = 0
        self.steps = 0            # clock steps seen (the window restarted at each)

    @property
    def ready(self) -> bool:
        return self.count > 0

    def add(self, t1: float, rx_us: int, tx_us: int, t4: float, asym_us: float = 0.0) -> None:
        """One exchange: host send/receive times (s), MCU receive/transmit times (µs), and the
        known excess of the reply's transit over the request's (µs; 0 when unknown)."""
        if not (t4 >= t1 and tx_us >= rx_us):
            self.rejected += 1
            return
        u = rx_us - t1 * 1e6
        d = t4 * 1e6 - tx_us - asym_us
        if u + d + asym_us < 0:  # a negative round trip: impossible unless the clocks stepped
            self.rejected += 1
            return
        t_mid = 0.5 * (t1 + t4)
        if self._ex:
            theta = self.offset_at(t_mid)
            if min(u - theta, d + theta) < -self.step_tolerance_us(t_mid):
                self._ex.clear()          # the old exchanges describe the clock before the step
                self.steps += 1
        self._ex.append((t_mid, u, d))
        self.count += 1
        self._fit()

    def step_tolerance_us(self, t_host: float) -> float:
        """How far below zero (µs) an exchange at ``t_host`` (s) may put a one-way delay
        against the model before it counts as a clock step: half the envelopes' round trip
        (the hard bound), :data:`STEP_MIN_US` and the oscillator's tolerance over the time
        since the newest exchange in the window."""
        gap_s = max(0.0, t_host - self._ex[-1][0]) if self._ex else 0.0
        return 0.5 * self.min_delay_us + STEP_MIN_US + self.drift_sigma_ppm * gap_s

    def _fit(self) -> None:
        t, u, d = np.array(self._ex).T.copy()       # contiguous rows: the signature warm-up compiled
        self.t_ref = float(t.mean())
        dt = t - self.t_ref
        b = self.drift * 1e6                        # µs/s; kept while the baseline is too short
        if t.max() - t.min() >= self.min_span_s:
            # a drift of drift_sigma_ppm costs as much as the envelope's share of points each
            # slack_us off it
            penalty = DRIFT_QUANTILE * len(t) * self.slack_us / self.drift_sigma_ppm
            b = drift_fit(dt, u, d, DRIFT_QUANTILE, penalty, _DRIFT_SEARCH_PPM)
        self.drift = b * 1e-6
        self.offset_us = 0.5 * (float(np.min(u - b * dt)) - float(np.min(d + b * dt)))

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
    def exchanges(self) -> np.ndarray:
        """The exchanges in the window, one row each: (host mid-time s, u µs, d µs)."""
        return np.array(self._ex).reshape(-1, 3)

    @property
    def min_delay_us(self) -> float:
        """The round trip of the two minimum one-way delays (µs): the link's clean delay."""
        if not self._ex:
            return float("nan")
        ex = np.array(self._ex)
        dt = (ex[:, 0] - self.t_ref) * self.drift * 1e6
        return float(np.min(ex[:, 1] - dt) + np.min(ex[:, 2] + dt))
