"""Streaming: frames that stop coming (all lost on the link, the head silent while its link
stays up) make the loop coast, and time out to ACQUIRE, as starless frames would — the
outputs must not say TRACK over a gyro-only attitude."""

import math

from gyrostar.loop import modes
from gyrostar.loop import record as R
from gyrostar.loop.coupled import Counters, CoupledLoop, LoopParams
from gyrostar.loop.head_link import HeadLink
from gyrostar.loop.stream_images import STREAM_FEW_FRAMES, STREAM_GAP_FRAMES, StreamImages

TICK = 0.0025


class _Tracks:
    def __init__(self):
        self.cleared = 0

    def drop_lost(self, tracking):
        pass

    def clear(self):
        self.cleared += 1


class _Filter:
    valid = True


def _tracking_loop():
    lp = CoupledLoop.__new__(CoupledLoop)          # only what the image-mode bookkeeping reads
    lp.p = LoopParams()
    lp.mp = lp.p.mode_params()
    lp.streaming, lp.budget = True, None
    lp.link = HeadLink(lp.p.reconnect_every_s, lp.p.head_timeouts_lost)
    lp.state = modes.ModeState(mode=R.MODE_TRACK)
    lp.c, lp.tracks, lp.filter = Counters(), _Tracks(), _Filter()
    lp.stream_images, lp.last_image_flags, lp.next_acquire_t = StreamImages(), 0, math.inf
    return lp


def _run(lp, t0, t1, frames_until):
    """Tick from ``t0`` to ``t1``: a frame updating 10 stars every 10 ms until ``frames_until``,
    none after. Returns [(t, mode)] at each tick."""
    out, t, next_frame = [], t0, t0
    while t < t1:
        if t >= next_frame and t <= frames_until:
            lp._after_image(t, 10)
            next_frame += 0.010
        lp._frames_missing(t)
        out.append((t, lp.state.mode))
        t = round(t + TICK, 9)
    return out


def test_frames_that_stop_coming_coast_after_a_few_periods_and_time_out():
    lp = _tracking_loop()
    trace = _run(lp, 100.0, 107.0, frames_until=101.0)
    before = [m for t, m in trace if t <= 101.0 + STREAM_GAP_FRAMES * 0.010]
    assert set(before) == {R.MODE_TRACK}                 # frames coming (and one late frame's slack)
    coast_at = min(t for t, m in trace if m == R.MODE_COAST)
    # the first missing period counts after STREAM_GAP_FRAMES, then one per period: COAST at the
    # STREAM_FEW_FRAMES-th, as three starless frames would
    assert coast_at - 101.0 <= (STREAM_GAP_FRAMES + STREAM_FEW_FRAMES - 1) * 0.010 + 2 * TICK
    assert coast_at - 101.0 > STREAM_GAP_FRAMES * 0.010
    acquire_at = min(t for t, m in trace if m == R.MODE_ACQUIRE)
    assert lp.p.coast_timeout_s < acquire_at - coast_at <= lp.p.coast_timeout_s + 0.011
    assert lp.tracks.cleared == 1 and not lp.filter.valid       # the attitude is given up there
    # in ACQUIRE nothing more is counted (lost-in-space full frames run their own course)
    assert lp.stream_images.few_run == 0 or lp.state.mode == R.MODE_ACQUIRE


def test_frames_coming_never_count_as_missing_and_a_return_regains_track():
    lp = _tracking_loop()
    trace = _run(lp, 100.0, 103.0, frames_until=103.0)
    assert {m for _, m in trace} == {R.MODE_TRACK}
    trace = _run(lp, 103.0, 103.2, frames_until=103.0)      # frames stop: COAST
    assert trace[-1][1] == R.MODE_COAST
    trace = _run(lp, 103.2, 103.3, frames_until=104.0)      # they come back
    assert trace[-1][1] == R.MODE_TRACK


def test_no_missing_frames_while_the_head_is_away_or_in_request_mode():
    for away in (True, False):
        lp = _tracking_loop()
        lp._after_image(100.0, 10)
        if away:
            lp.link.lost(99.0)
        else:
            lp.streaming = False
        for i in range(200):
            lp._frames_missing(100.0 + i * TICK)
        assert lp.state.mode == R.MODE_TRACK and lp.stream_images.few_run == 0


def test_stream_images_alone_short_runs_unheard_and_missing_frames_one_per_period():
    """StreamImages: while streaming and tracking, the first STREAM_FEW_FRAMES − 1 short images in
    a row are not passed on, the next is; a good image restarts the run; not tracking, every
    image is. No frame for STREAM_GAP_FRAMES periods: a missing one, then one per period."""
    s = StreamImages()
    heard = [s.image(100.0 + 0.01 * k, True, True) for k in range(STREAM_FEW_FRAMES)]
    assert heard == [False] * (STREAM_FEW_FRAMES - 1) + [True]
    assert s.image(100.1, False, True) and s.few_run == 0
    assert s.image(100.11, True, False)                      # coasting: heard
    s.restart(200.0)
    period = 0.010
    assert not s.frame_missing(200.0 + STREAM_GAP_FRAMES * period - 0.0001, period)
    t = 200.0 + STREAM_GAP_FRAMES * period + 0.001
    assert s.frame_missing(t, period)
    s.missing_counted(t, period)
    assert not s.frame_missing(t + period - 0.0001, period)
    assert s.frame_missing(t + period + 0.0001, period)


def test_stream_counts_from_the_config():
    """The two counts are loop parameters (flatsat config loop.stream_few_frames / stream_gap_frames):
    with 1 a single short image coasts and a single missing period counts; 0 is refused."""
    import pytest

    s = StreamImages(few_frames=1, gap_frames=1)
    assert s.image(100.0, True, True)                       # heard at once
    s.restart(200.0)
    assert s.frame_missing(200.0105, 0.010)
    with pytest.raises(ValueError):
        StreamImages(few_frames=0)
    lp = _tracking_loop()
    assert (lp.p.stream_few_frames, lp.p.stream_gap_frames) == (STREAM_FEW_FRAMES, STREAM_GAP_FRAMES)
    from gyrostar.hil import config as hc

    lc = hc.load_flatsat().loop
    assert (lc.stream_few_frames, lc.stream_gap_frames) == (STREAM_FEW_FRAMES, STREAM_GAP_FRAMES)
    with pytest.raises(ValueError, match="stream_gap_frames"):
        hc.LoopConfig(stream_gap_frames=0).validate()
