"""Drift-free periodic scheduling on the monotonic clock, with overrun counting.

Deadlines are ``t0 + k·period`` (never "now + period"), so jitter does not accumulate.
When a step finishes after the next deadline the missed deadlines are counted as
overruns and the schedule skips ahead (it never bursts to catch up). Optional real-time
set-up (:func:`realtime_setup`): SCHED_FIFO priority and CPU affinity when the process is
permitted (CAP_SYS_NICE / rtprio limit); otherwise it reports why not and carries on.
"""

from __future__ import annotations

import os
import time
from collections import deque
from dataclasses import dataclass, field

LATE_KEEP = 4096   # wake-up lateness values kept (≈ 10 s at 400 Hz)


@dataclass
class RealtimeStatus:
    sched_fifo: bool = False
    priority: int = 0
    cpus: list[int] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def realtime_setup(priority: int | None = None, cpus: list[int] | None = None) -> RealtimeStatus:
    """Try SCHED_FIFO at ``priority`` and pin to ``cpus``; report what was granted."""
    st = RealtimeStatus()
    if cpus:
        try:
            os.sched_setaffinity(0, set(cpus))
            st.cpus = sorted(os.sched_getaffinity(0))
        except (OSError, AttributeError, ValueError) as exc:
            st.notes.append(f"CPU affinity {cpus} not set: {exc}")
    if priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(priority)))
            st.sched_fifo = True
            st.priority = int(priority)
        except (OSError, AttributeError) as exc:
            st.notes.append(f"SCHED_FIFO priority {priority} not granted ({exc}); running SCHED_OTHER "
                            "(grant with: setcap cap_sys_nice+ep, or an rtprio limit in limits.conf)")
    return st


class PeriodicScheduler:
    """Wake at ``t0 + k·period`` on ``time.monotonic``; count overruns.

    Use: ``s.start(); while ...: s.wait(); step(); s.done()``. ``late_s`` holds how late
    each of the last ``LATE_KEEP`` wake-ups was (s, a bounded ring so a long run's memory stays
    flat); ``overruns`` how many deadlines were missed in total.
    """

    def __init__(self, period_s: float, clock=time.monotonic, sleep=time.sleep, spin_s: float = 0.0002):
        if period_s <= 0:
            raise ValueError("period must be positive")
        self.period = float(period_s)
        self.clock = clock
        self.sleep = sleep
        self.spin_s = spin_s
        self.t0 = 0.0
        self.k = 0
        self.overruns = 0
        self.steps = 0
        self.late_s: deque[float] = deque(maxlen=LATE_KEEP)

    def start(self, t0: float | None = None) -> None:
        self.t0 = self.clock() if t0 is None else t0
        self.k = 0

    @property
    def deadline(self) -> float:
        return self.t0 + self.k * self.period

    def wait(self) -> float:
        """Sleep until the current deadline; return the wake-up time."""
        target = self.deadline
        while True:
            now = self.clock()
            left = target - now
            if left <= 0:
                break
            if left > self.spin_s:
                self.sleep(left - self.spin_s)
        self.late_s.append(now - target)
        return now

    def done(self) -> int:
        """Mark the step finished; advance to the next deadline. Returns overruns this step."""
        self.steps += 1
        self.k += 1
        now = self.clock()
        missed = 0
        if now > self.deadline:
            missed = int((now - self.deadline) // self.period) + 1
            self.overruns += missed
            self.k += missed
        return missed
