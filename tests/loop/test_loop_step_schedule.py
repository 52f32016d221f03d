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
    lp.t_newest = lp.rx_last = -math.inf
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

    period_s = 0.010

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


def _stream_run(arrivals, t_end, newest_lag=0.0004):
    """Tick a streaming loop every gyro period from 100.0 to ``t_end``: frames become ready at
    ``arrivals`` (host s); a due step takes the frames that have arrived (``rx_last``) and
    reads the samples up to ``newest_lag`` before it. Returns (step times, frame → its step)."""
    lp = _loop(4)
    lp.head = _StreamHead()
    queue, steps, taken = sorted(arrivals), [], {}
    t = 100.0
    while t < t_end:
        here = [a for a in queue if a <= t]
        lp.head.since = here[0] if here else None
        if lp.step_due(t):
            steps.append(t)
            lp.t_newest = t - newest_lag
            for a in here:
                taken[a] = t
                lp.rx_last = max(lp.rx_last, a)
            queue = queue[len(here):]
        t = round(t + TICK, 9)
    return steps, taken


def test_frames_jittering_across_a_tick_take_their_samples_in_one_step_each():
    """Frames every 10 ms whose arrival jitters ±1 ms about a watermark tick: without a
    look-ahead a frame that lands just after the tick costs two steps (the watermark's, then
    its own one tick later) — 117 steps in this second. The watermark step waits that tick
    for the expected frame: one step per frame, each at the first sample after its arrival,
    no step more than 5 ticks after the last."""
    import numpy as np

    arrivals = list(100.0025 + 0.010 * np.arange(100) + np.random.default_rng(1).uniform(-0.001, 0.001, 100))
    steps, taken = _stream_run(arrivals, 101.0, newest_lag=0.0004)
    assert len(steps) <= 102
    for a, t in taken.items():
        assert a < t <= a + TICK + 0.0004
    assert max(b - a for a, b in zip(steps, steps[1:])) <= 5 * TICK + 1e-9


def test_a_frame_that_does_not_come_holds_the_watermark_one_tick_only():
    """The stream stops after 100.2: the watermark step waits one tick for the frame expected
    at 100.2127, then the watermark alone steps every 4 ticks again."""
    arrivals = [100.0027 + 0.010 * k for k in range(21)]
    steps, _ = _stream_run(arrivals, 100.4)
    gaps = [round((b - a) / TICK) for a, b in zip(steps, steps[1:]) if a > 100.2]
    assert gaps[0] == 5 and set(gaps[1:]) == {4}


def test_watermark_one_steps_every_tick_whatever_frames_are_expected():
    lp = _loop(1)
    lp.head = _StreamHead()
    lp.rx_last = 100.0 - 0.010          # the next frame expected at 100.0
    assert all(_ticks(lp, 100.0 - 2 * TICK, 5))
