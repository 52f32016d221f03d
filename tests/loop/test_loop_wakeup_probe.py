"""The host wake-up probe: a child process that reports its late wake-ups, and the count of
loop overruns that fall inside one of those host stalls."""

import numpy as np
from gyrostar.loop.wakeup_probe import LATE_S, WakeupProbe, coincident


def test_coincident_counts_events_inside_stalls():
    probe_t = np.array([1.000, 2.000])
    probe_late = np.array([0.004, 0.002])
    # stalls cover [t − 3 ms, t + late + 3 ms]: 0.997..1.007 and 1.997..2.005
    events = np.array([0.990, 0.998, 1.006, 1.0071, 1.5, 2.004, 2.0049, 2.006])
    assert coincident(events, probe_t, probe_late) == 4
    assert coincident(events, probe_t[:0], probe_late[:0]) == 0


def test_probe_reports_every_wakeup_and_only_late_ones():
    p = WakeupProbe(period_s=0.0025, priority=0)
    p.start(0.5)
    r = p.result()
    assert r["wakeups"] == 200
    assert len(r["late_t"]) == len(r["late_s"]) and np.all(r["late_s"] > LATE_S)
    assert r["max_s"] >= (r["late_s"].max() if len(r["late_s"]) else 0.0)
    assert not r["granted"]
