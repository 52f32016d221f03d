"""When the loop steps (CoupledLoop.step_due, its timing in gyrostar.loop.step_schedule): a
FIFO watermark of samples, a head-port result (a streamed frame once the first sample after
its arrival is due), an update still without its output, a request-mode frame due, the first
tick."""

import math

import pytest
from gyrostar.loop.coupled import CoupledLoop
from gyrostar.loop.head_link import HeadLink
from gyrostar.loop.step_schedule import StepSchedule

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
    lp.schedule, lp.updates_owed = StepSchedule(), []
    lp.link, lp.next_frame_t = HeadLink(0.25, 3), math.inf
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
    lp.updates_owed = [99.99]                           # its update applied, no sample after its arrival yet
    assert lp.step_due(100.0 + 2 * TICK)
    lp.updates_owed = []
    # the watermark counts from the last step: due again 4 ticks later, not before
    assert _ticks(lp, 100.0 + 3 * TICK, 4) == [False, False, False, True]


def test_request_mode_frame_due_and_head_down():
    lp = _loop(4, streaming=False)
    assert lp.step_due(100.0)
    lp.next_frame_t = 100.0 + TICK
    assert lp.step_due(100.0 + TICK)             # the next request-mode frame is due
    lp.link.lost(100.0)                          # head lost: only the watermark steps (reconnects run there)
    assert _ticks(lp, 100.0 + 2 * TICK, 4) == [False, False, False, True]
    lp.link.back(100.0 + 6 * TICK)
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
    lp.schedule.sample_read(100.0004)
    lp.head.since = 100.0011
    assert _ticks(lp, 100.0 + 0.5 * TICK, 1) == [False]
    assert not lp.step_due(100.0 + TICK)             # 100.0025: the sample after the arrival is not in
    assert lp.step_due(100.00291)                     # ... now it is
    # a frame whose arrival the newest sample read already follows: at once
    lp.schedule.sample_read(100.0054)
    lp.head.since = 100.0050
    assert lp.step_due(100.0055)
    # a finished job (a full frame, a reconnect): at once
    lp.head.since = -math.inf
    assert lp.step_due(100.0056)
    # no sample read yet: at once (nothing to wait for)
    lp.schedule.sample_read(-math.inf)
    lp.head.since = 100.0100
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
        lp.schedule.sample_read(100.0 + rng.uniform(0.0, 0.0025))
        lp.head.since = lp.schedule.t_newest + rng.uniform(1e-6, 0.05)
        for dt, want in ((-1e-7, False), (0.0, False), (TICK + 1e-9, True)):
            t = lp.head.since + dt
            lp.schedule.stepped(t - 0.001)         # no watermark due: only the frame can make a step
            assert lp.step_due(t) == want


def _stream_run(arrivals, t_end, newest_lag=0.0004):
    """Tick a streaming loop every gyro period from 100.0 to ``t_end``: frames become ready at
    ``arrivals`` (host s); a due step takes the frames that have arrived (:meth:`StepSchedule.frame_taken`) and
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
            lp.schedule.sample_read(t - newest_lag)
            for a in here:
                taken[a] = t
                lp.schedule.frame_taken(a)
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
    lp.schedule.frame_taken(100.0 - 0.010)         # the next frame expected at 100.0
    assert all(_ticks(lp, 100.0 - 2 * TICK, 5))


def test_schedule_watermark_waits_one_tick_for_an_expected_frame_and_never_when_late():
    """StepSchedule alone: the watermark (4 ticks) is held for a frame expected within a tick,
    but not once the step is half a tick late, and never at watermark 1."""
    s = StepSchedule()
    assert s.watermark_due(100.0, TICK, 4 * TICK, 0.010)       # no step yet
    s.stepped(100.0)
    assert not s.watermark_due(100.0 + 3 * TICK, TICK, 4 * TICK, 0.010)
    s.frame_taken(100.0 + 4 * TICK - 0.010 + 0.0005)           # next frame expected 0.5 ms after the tick
    assert not s.watermark_due(100.0 + 4 * TICK, TICK, 4 * TICK, 0.010)
    assert s.watermark_due(100.0 + 4.5 * TICK, TICK, 4 * TICK, 0.010)   # half a tick late: step
    assert s.watermark_due(100.0 + 4 * TICK, TICK, 4 * TICK, 0.0)       # not streaming: step
    s1 = StepSchedule()
    s1.stepped(100.0)
    s1.frame_taken(100.0 + TICK - 0.010)
    assert s1.watermark_due(100.0 + TICK, TICK, TICK, 0.010)            # watermark 1: every tick


def test_schedule_arrival_due_on_the_newest_samples_grid():
    """A frame that arrived 0.7 ms after the newest sample (stamped 100.0004) is due at the next
    sample on that grid, 100.0029; nothing waiting is never due; an older arrival at once."""
    s = StepSchedule()
    assert s.arrival_due(100.0, TICK, 99.0)                    # no sample read yet: at once
    s.sample_read(100.0004)
    assert not s.arrival_due(100.0028, TICK, 100.0011)
    assert s.arrival_due(100.00291, TICK, 100.0011)
    assert s.arrival_due(100.0005, TICK, 100.0003)             # the newest sample already follows it
    assert s.arrival_due(100.0005, TICK, -math.inf)            # a finished job
    assert not s.arrival_due(200.0, TICK, None)


def test_head_link_counts_unanswered_jobs_and_paces_reconnects():
    """HeadLink alone: 3 timeouts in a row mean lost, an answer or an error reply restarts the
    count; while down, a reconnect every 0.25 s, none while the port is busy; back says how long."""
    link = HeadLink(0.25, 3)
    assert link.up
    assert not link.job_failed(True) and not link.job_failed(True)
    assert not link.job_failed(False)                  # an answer that was an error: not a timeout
    assert not link.job_failed(True) and not link.job_failed(True)
    assert link.job_failed(True)
    link.lost(10.0)
    link.lost(10.1)                                    # already down: the loss time stays
    assert not link.up and link.down_since == 10.0
    assert not link.reconnect_due(10.2, busy=False)    # the first attempt 0.25 s after the loss
    assert not link.reconnect_due(10.3, busy=True)
    assert link.reconnect_due(10.3, busy=False)
    assert not link.reconnect_due(10.5, busy=False)
    assert link.reconnect_due(10.55, busy=False)
    assert link.back(10.6) == pytest.approx(0.6) and link.up and link.timeouts == 0
