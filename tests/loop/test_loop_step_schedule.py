"""When the loop steps (CoupledLoop.step_due): a FIFO watermark of samples, a head-port
result, an update still without its output, a request-mode frame due, the first tick."""

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
