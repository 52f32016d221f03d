"""When the loop steps: the FIFO watermark, a streamed frame's arrival, the look-ahead.

A runner ticks every gyro period and asks the loop whether to step
(:meth:`gyrostar.loop.coupled.CoupledLoop.step_due`). This stage keeps what that answer
rests on from one tick to the next — the time of the last step, the stamp of the newest
gyro sample read and the arrival of the newest streamed frame taken in — and answers its
two timing questions:

* :meth:`StepSchedule.watermark_due`: a FIFO watermark of samples has come in since the
  last step. It waits one more tick when the next streamed frame is expected within a
  tick (:meth:`StepSchedule.frame_expected`): that frame's step then takes the samples, so
  a frame whose arrival jitters across a tick does not cost two steps. It never waits
  longer, and a watermark of 1 steps at every tick.
* :meth:`StepSchedule.arrival_due`: a frame that arrived at ``t_rx`` is worth a step once
  the first gyro sample stamped after ``t_rx`` is due (on the grid of the newest sample
  read and the gyro period: at most one period after ``t_rx``), so its update goes in
  before that sample and exposure → output does not wait for the watermark.

Times are host seconds on the runner's clock; ``tick`` is the gyro period and ``period``
the watermark's (``watermark / ODR``), both read by the caller at each tick (the gyro's
ODR is known only once it is configured). No clock is read and nothing is logged here: a
replay steps through the logged steps whatever the ticks between them were.
"""

from __future__ import annotations

import math


class StepSchedule:
    def __init__(self) -> None:
        self.t_due: float | None = None   # runner time of the last tick that was a step (s)
        self.t_newest = -math.inf         # stamp of the newest gyro sample read (host s)
        self.rx_last = -math.inf          # arrival of the newest streamed frame taken in (host s)

    def stepped(self, now: float) -> None:
        """The tick at ``now`` (s) is a step: the watermark counts from here."""
        self.t_due = now

    def sample_read(self, t: float) -> None:
        """The newest gyro sample read is stamped ``t`` (host s)."""
        self.t_newest = t

    def frame_taken(self, t_rx: float) -> None:
        """A streamed frame that arrived at ``t_rx`` (host s) was taken in."""
        if t_rx > self.rx_last:
            self.rx_last = t_rx

    def watermark_due(self, now: float, tick: float, period: float, frame_period: float) -> bool:
        """A watermark of samples (``period`` s) has come in since the last step, or there was
        no step yet — unless the next streamed frame (stream period ``frame_period`` s, 0: not
        streaming) is expected by the next tick and this step is not already late."""
        last = self.t_due
        if last is None:
            return True
        since = now - last
        if since < period - 0.5 * tick:
            return False
        return not (period > 1.5 * tick and since < period + 0.5 * tick
                    and self.frame_expected(now, tick, frame_period))

    def frame_expected(self, now: float, tick: float, frame_period: float) -> bool:
        """The next streamed frame (the newest one's arrival plus ``frame_period``) is
        expected within one gyro period ``tick`` of ``now`` (s), either side."""
        return frame_period > 0.0 and abs(self.rx_last + frame_period - now) <= tick

    def arrival_due(self, now: float, tick: float, t_rx: float | None) -> bool:
        """A head-port result that arrived at ``t_rx`` (None: nothing waits; −inf: a job,
        due at once) is due at ``now``: at once when no sample was read yet or one stamped
        after the arrival was; else at the first sample after ``t_rx`` on the newest's grid."""
        if t_rx is None:
            return False
        newest = self.t_newest
        if not t_rx > newest or newest == -math.inf:
            return True
        return now >= newest + math.ceil((t_rx - newest) / tick) * tick
