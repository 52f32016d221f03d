"""When the loop steps (CoupledLoop.step_due): a FIFO watermark of samples, a head-port
result (a streamed frame once the first sample after its arrival is due), an update still
without its output, a request-mode frame due, the first tick."""

import math

import pytest
from gyrostar.loop.coupled import CoupledLoop

TICK = 0.0025


class _Gyro:
    odr_hz = 400.0

    def __init__(self, watermark):
        self.watermark = watermark


class _Head:
    def __init__(self):
        self.result = False

    def ready(self):
        return self.result


class _Image:
    busy = False


def _loop(watermark=4, streaming=True):
    lp = CoupledLoop.__new__(CoupledLoop)      # only what step_due reads
    lp.gyro, lp.head, lp.image = _Gyro(watermark), _Head(), _Image()
    lp.streaming = streaming
    lp._t_due, lp._mids = None, []
    lp.head_down_since, lp.next_frame_t = None, math.inf
    return lp


def _ticks(lp, t0, n):
    return [lp.step_due(t0 + k * TICK) for k in range(n)]


def test_a_step_every_watermark_of_samples_and_at_the_first_tick():
    lp = _loop(4)
    assert lp.step_period_s == pytest.approx(4 * TICK)
    assert _ticks(lp, 100.0, 12) == [True, False, False, False] * 3
    lp1 = _loop(1)
    assert all(_ticks(lp1, 100.0, 8))            # watermark 1: every tick


def test_a_measured_frame_or_a_waiting_update_steps_at_once_and_restarts_the_count():
    lp = _loop(4)
    assert lp.step_due(100.0)
    lp.head.result = True                        # a frame measured one tick later
    assert lp.step_due(100.0 + TICK)
    lp.head.result = False
    lp._mids = [99.99]                           # its update applied, no sample after its arrival yet
    assert lp.step_due(100.0 + 2 * TICK)
    lp._mids = []
    # the watermark counts from the last step: due again 4 ticks later, not before
    assert _ticks(lp, 100.0 + 3 * TICK, 4) == [False, False, False, True]


def test_request_mode_frame_due_and_head_down():
    lp = _loop(4, streaming=False)
    assert lp.step_due(100.0)
    lp.next_frame_t = 100.0 + TICK
    assert lp.step_due(100.0 + TICK)             # the next request-mode frame is due
    lp.head_down_since = 100.0                   # head lost: only the watermark steps (reconnects run there)
    assert _ticks(lp, 100.0 + 2 * TICK, 4) == [False, False, False, True]
    lp.head_down_since = None
    lp.next_frame_t = math.inf
    lp.image.busy = True                         # a readout centroided, waiting to be applied
    assert lp.step_due(100.0 + 6 * TICK)


class _StreamHead:
    """A stream port that says what waits: a measured frame's arrival time, −inf for a job."""

    def __init__(self):
        self.since = None

    def ready_since(self):
        return self.since


def test_a_measured_frame_steps_when_the_first_sample_after_its_arrival_is_due():
    """Samples every 2.5 ms stamped on a grid at 0.4 ms past the ticks; the newest read at
    100.0004. A frame that arrived at 100.0011 waits for the sample at 100.0029, the first
    its update can go into — one step applies it and emits that sample's output —, not
    the tick at 100.0025 (a step there could carry the update into no output)."""
    lp = _loop(4)
    lp.head = _StreamHead()
    assert lp.step_due(100.0)
    lp.t_newest = 100.0004
    lp.head.since = 100.0011
    assert _ticks(lp, 100.0 + 0.5 * TICK, 1) == [False]
    assert not lp.step_due(100.0 + TICK)             # 100.0025: the sample after the arrival is not in
    assert lp.step_due(100.00291)                     # ... now it is
    # a frame whose arrival the newest sample read already follows: at once
    lp.t_newest, lp.head.since = 100.0054, 100.0050
    assert lp.step_due(100.0055)
    # a finished job (a full frame, a reconnect): at once
    lp.head.since = -math.inf
    assert lp.step_due(100.0056)
    # no sample read yet: at once (nothing to wait for)
    lp.t_newest, lp.head.since = -math.inf, 100.0100
    assert lp.step_due(100.0101)


def test_a_measured_frame_waits_one_tick_at_most():
    """Whatever the newest stamp and the arrival, a measured frame is due after its arrival
    and no later than one gyro period after it (the first sample on the newest's grid)."""
    import numpy as np

    rng = np.random.default_rng(2)
    for _ in range(200):
        lp = _loop(4)
        lp.head = _StreamHead()
        assert lp.step_due(100.0)
        lp.t_newest = 100.0 + rng.uniform(0.0, 0.0025)
        lp.head.since = lp.t_newest + rng.uniform(1e-6, 0.05)
        for dt, want in ((-1e-7, False), (0.0, False), (TICK + 1e-9, True)):
            t = lp.head.since + dt
            lp._t_due = t - 0.001          # no watermark due: only the frame can make a step
            assert lp.step_due(t) == want
