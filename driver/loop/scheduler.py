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

from ..realtime import fifo_policy, set_loop_priority

LATE_KEEP = 4096   # wake-up lateness values kept (≈ 10 s at 400 Hz)
# Waiting by sleeping alone: spinning the last 200 µs before each 400 Hz deadline cost 7–8 % of
# a core (process CPU 31 % → 24 % on the simulated flatsat, 2026-11-26) and bought neither
# fewer overruns (19, 21 spinning; 10, 15 sleeping) nor a shorter exposure → output
# (7.8–8.9 ms either way): the kernel wakes a sleeper about 0.1 ms late here.
SPIN_S = 0.0
OVERRUN_KEEP = 65536  # times of the latest overrun events kept


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
            # reset-on-fork: threads and processes started from here on (emulators, host
            # work) run SCHED_OTHER; the driver's workers raise themselves just below the
            # loop (gyrostar.realtime.join_realtime)
            os.sched_setscheduler(0, fifo_policy(), os.sched_param(int(priority)))
            set_loop_priority(int(priority))
            st.sched_fifo = True
            st.priority = int(priority)
        except (OSError, AttributeError) as exc:
            st.notes.append(f"SCHED_FIFO priority {priority} not granted ({exc}); running SCHED_OTHER "
                            "(grant with: setcap cap_sys_nice+ep, or an rtprio limit in limits.conf)")
    return st


class PeriodicScheduler:
    """Wake at ``t0 + k·period`` on ``time.monotonic``; count overruns.

    Use: ``s.start(); while ...: s.wait(); step(); s.done()``. ``spin_s``: the last stretch
    before a deadline spent polling the clock instead of asleep (0: sleep all the way). ``late_s`` holds how late
    each of the last ``LATE_KEEP`` wake-ups was (s, a bounded ring so a long run's memory stays
    flat); ``overruns`` how many deadlines were missed in total.
    """

    def __init__(self, period_s: float, clock=time.monotonic, sleep=time.sleep, spin_s: float = SPIN_S):
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
        self.overrun_t: deque[float] = deque(maxlen=OVERRUN_KEEP)   # missed deadlines (clock s)

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
            self.overrun_t.append(self.deadline)
            self.k += missed
        return missed


class StepGate:
    """Keeps a device worker's Python work out of the loop's steps and wake-ups.

    The loop and its device workers share one interpreter lock, so a worker busy in Python
    when a step is due delays it. The loop holds the gate for each step
    (:meth:`loop_enter` … :meth:`loop_exit` with its next wake-up time); a worker wraps each
    stretch of Python work in :meth:`worker_enter`/:meth:`worker_exit` and starts one only
    between steps with at least ``min_slot_s`` left before the next wake-up (blocking waits
    for device replies happen outside). :meth:`open` ends the schedule (workers run freely).
    """

    def __init__(self, min_slot_s: float = 0.001, clock=time.monotonic):
        import threading

        self.min_slot = float(min_slot_s)
        self.clock = clock
        self._cv = threading.Condition(threading.Lock())
        self._loop_in = False
        self._worker_in = False
        self._next: float | None = None

    def loop_enter(self) -> None:
        with self._cv:
            while self._worker_in:
                self._cv.wait()
            self._loop_in = True

    def loop_exit(self, next_wake: float) -> None:
        with self._cv:
            self._loop_in = False
            self._next = float(next_wake)
            self._cv.notify_all()

    def open(self) -> None:
        """No more steps: let workers run whenever they like."""
        with self._cv:
            self._loop_in = False
            self._next = None
            self._cv.notify_all()

    def worker_enter(self) -> None:
        with self._cv:
            while True:
                if not self._loop_in:
                    if self._next is None:
                        break
                    left = self._next - self.clock()
                    # enough room before the next step, or the loop is not stepping at all
                    if left >= self.min_slot or left < -0.05:
                        break
                self._cv.wait(timeout=0.005)
            self._worker_in = True

    def worker_exit(self) -> None:
        with self._cv:
            self._worker_in = False
            self._cv.notify_all()
