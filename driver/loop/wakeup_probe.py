"""The host's own wake-up latency, measured beside the loop: is an overrun the loop's or the machine's?

:class:`WakeupProbe` runs a child process (no Python threads, no interpreter lock shared
with the loop) that sleeps to deadlines every ``period_s`` on the monotonic clock and
records how late each wake-up was, at a SCHED_FIFO priority above the loop's when the host
permits it. A late wake-up of the probe means the kernel could not run a real-time task
on time (non-preemptible kernel work, another CPU hog, a hypervisor pause); loop overruns
that coincide with one are the machine's, not the loop's (:func:`coincident`).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time

import numpy as np

from .scheduler import SPIN_S  # sleep until this close to the deadline, then spin (as the loop's scheduler)

LATE_S = 0.001      # a wake-up later than this is recorded (s)


def _probe(conn, seconds: float, period_s: float, priority: int) -> None:
    granted = False
    if priority > 0:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            granted = True
        except (OSError, AttributeError):
            pass
    t0 = time.monotonic()
    n = int(seconds / period_s)
    late_t = []
    late_s = []
    worst = 0.0
    for k in range(1, n + 1):
        target = t0 + k * period_s
        while True:
            now = time.monotonic()
            left = target - now
            if left <= 0:
                break
            if left > SPIN_S:
                time.sleep(left - SPIN_S)
        late = now - target
        worst = max(worst, late)
        if late > LATE_S:
            late_t.append(target)
            late_s.append(late)
    conn.send({"granted": granted, "wakeups": n, "late_t": late_t, "late_s": late_s, "max_s": worst})
    conn.close()


class WakeupProbe:
    """``start(seconds)`` … ``result()``: the probe's late wake-ups (host monotonic times)."""

    def __init__(self, period_s: float = 0.0025, priority: int = 0):
        self.period_s = float(period_s)
        self.priority = int(priority)
        self._conn = None
        self._proc = None

    def start(self, seconds: float) -> None:
        ctx = mp.get_context("fork")
        self._conn, child = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(target=_probe, args=(child, float(seconds), self.period_s, self.priority),
                                 name="wakeup-probe", daemon=True)
        self._proc.start()
        child.close()

    def result(self, timeout_s: float = 30.0) -> dict:
        """``{"granted", "wakeups", "late_t" (s), "late_s" (s), "max_s"}``; waits for the end."""
        if self._conn is None:
            raise RuntimeError("probe not started")
        if not self._conn.poll(timeout_s):
            self._proc.kill()
            raise TimeoutError("wake-up probe did not report")
        out = self._conn.recv()
        self._proc.join(timeout=2.0)
        out["late_t"] = np.asarray(out["late_t"], float)
        out["late_s"] = np.asarray(out["late_s"], float)
        return out


def coincident(events_t: np.ndarray, probe_t: np.ndarray, probe_late: np.ndarray, slack_s: float = 0.003) -> int:
    """How many of ``events_t`` (e.g. loop overrun times, s) fall in a probe stall
    ``[t, t + late + slack_s]`` (the probe's deadline ``t`` and how late it woke)."""
    events_t = np.sort(np.asarray(events_t, float))
    hit = np.zeros(len(events_t), bool)
    for t, late in zip(probe_t, probe_late, strict=True):
        a = np.searchsorted(events_t, t - slack_s)
        b = np.searchsorted(events_t, t + late + slack_s, side="right")
        hit[a:b] = True
    return int(hit.sum())
