"""Streaming: frames that stop coming (all lost on the link, the head silent while its link
stays up) make the loop coast, and time out to ACQUIRE, as starless frames would — the
outputs must not say TRACK over a gyro-only attitude. Through the mode keeper's public calls
(:class:`gyrostar.loop.mode_keeper.ModeKeeper`), as the loop makes them."""

from dataclasses import replace

from gyrostar.loop import modes
from gyrostar.loop import record as R
from gyrostar.loop.coupled import LoopParams
from gyrostar.loop.mode_keeper import ModeKeeper
from gyrostar.loop.stream_images import STREAM_FEW_FRAMES, STREAM_GAP_FRAMES, StreamImages

TICK = 0.0025
PERIOD = 0.010


def _tracking_keeper(streaming=True):
    p = LoopParams()
    k = ModeKeeper(p.mode_params(), streaming, p.stream_few_frames, p.stream_gap_frames)
    k.enter(replace(k.state, mode=R.MODE_TRACK), 0.0)
    return k


def _run(k, t0, t1, frames_until, link_up=True):
    """Tick from ``t0`` to ``t1``: a frame updating 10 stars every 10 ms until ``frames_until``,
    none after. Returns [(t, mode, what was heard)] at each tick."""
    out, t, next_frame = [], t0, t0
    while t < t1:
        heard = []
        if t >= next_frame and t <= frames_until:
            heard.append(k.image(t, 10))
            next_frame += PERIOD
        heard.append(k.frame_missing(t, PERIOD, link_up))
        out.append((t, k.mode, [h for h in heard if h is not None]))
        t = round(t + TICK, 9)
    return out


def test_frames_that_stop_coming_coast_after_a_few_periods_and_time_out():
    k = _tracking_keeper()
    trace = _run(k, 100.0, 107.0, frames_until=101.0)
    before = [m for t, m, _ in trace if t <= 101.0 + STREAM_GAP_FRAMES * PERIOD]
    assert set(before) == {R.MODE_TRACK}                 # frames coming (and one late frame's slack)
    coast_at = min(t for t, m, _ in trace if m == R.MODE_COAST)
    # the first missing period counts after STREAM_GAP_FRAMES, then one per period: COAST at the
    # STREAM_FEW_FRAMES-th, as three starless frames would
    assert coast_at - 101.0 <= (STREAM_GAP_FRAMES + STREAM_FEW_FRAMES - 1) * PERIOD + 2 * TICK
    assert coast_at - 101.0 > STREAM_GAP_FRAMES * PERIOD
    acquire_at = min(t for t, m, _ in trace if m == R.MODE_ACQUIRE)
    assert k.p.coast_timeout_s < acquire_at - coast_at <= k.p.coast_timeout_s + 0.011
    # the attitude is given up there, once, with a full frame at once; no acquisition failed
    asks = [(t, h) for t, _, hs in trace for h in hs if h.action]
    assert [t for t, _ in asks] == [acquire_at]
    assert asks[0][1].action == modes.Action.LOSE_ATTITUDE | modes.Action.ACQUIRE_NOW
    # while coasting the heard frames check the tracks without the tracking miss limit
    coasting = [h for t, m, hs in trace for h in hs if coast_at <= t < acquire_at]
    assert coasting and all(h.check_tracks and not h.tracking for h in coasting)
    # the outputs said so: no star updated, too few stars
    assert k.flags == R.FLAG_FEW_STARS
    # in ACQUIRE nothing more is counted (lost-in-space full frames run their own course)
    assert all(not hs for t, m, hs in trace if t > acquire_at)
    assert [c[1:] for c in k.changes] == [("ACQUIRE", "TRACK"), ("TRACK", "COAST"), ("COAST", "ACQUIRE")]


def test_frames_coming_never_count_as_missing_and_a_return_regains_track():
    k = _tracking_keeper()
    trace = _run(k, 100.0, 103.0, frames_until=103.0)
    assert {m for _, m, _ in trace} == {R.MODE_TRACK}
    assert all(h.check_tracks and h.tracking for _, _, hs in trace for h in hs)
    assert k.flags == R.FLAG_IMAGE_UPDATE
    trace = _run(k, 103.0, 103.2, frames_until=103.0)      # frames stop: COAST
    assert trace[-1][1] == R.MODE_COAST
    trace = _run(k, 103.2, 103.3, frames_until=104.0)      # they come back
    assert trace[-1][1] == R.MODE_TRACK


def test_no_missing_frames_while_the_head_is_away_or_in_request_mode():
    for away in (True, False):
        k = _tracking_keeper(streaming=away)
        k.image(100.0, 10)
        for i in range(200):
            assert k.frame_missing(100.0 + i * TICK, PERIOD, link_up=not away) is None
        assert k.mode == R.MODE_TRACK and k.stream_images.few_run == 0


def test_a_short_run_of_starless_frames_is_flagged_only_then_heard():
    """Streaming and tracking: the first STREAM_FEW_FRAMES − 1 frames in a row that updated too
    few stars are not heard (no COAST) but the outputs carry FEW_STARS; the next one coasts.
    In request mode the first one coasts."""
    k = _tracking_keeper()
    for i in range(STREAM_FEW_FRAMES - 1):
        assert k.image(100.0 + i * PERIOD, 1) is None
        assert k.mode == R.MODE_TRACK and k.flags == R.FLAG_IMAGE_UPDATE | R.FLAG_FEW_STARS
    heard = k.image(100.0 + STREAM_FEW_FRAMES * PERIOD, 0)
    assert heard is not None and k.mode == R.MODE_COAST and k.flags == R.FLAG_FEW_STARS
    k = _tracking_keeper(streaming=False)
    assert k.image(100.0, 1) is not None and k.mode == R.MODE_COAST


def test_head_lost_coasts_and_flags_the_link():
    k = _tracking_keeper()
    k.head_lost(50.0)
    assert k.mode == R.MODE_COAST and k.state.coast_since_s == 50.0
    assert k.flags & R.FLAG_LINK_ERROR and k.flags & R.FLAG_FEW_STARS


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
    p = LoopParams()
    assert (p.stream_few_frames, p.stream_gap_frames) == (STREAM_FEW_FRAMES, STREAM_GAP_FRAMES)
    from gyrostar.hil import config as hc

    lc = hc.load_flatsat().loop
    assert (lc.stream_few_frames, lc.stream_gap_frames) == (STREAM_FEW_FRAMES, STREAM_GAP_FRAMES)
    with pytest.raises(ValueError, match="stream_gap_frames"):
        hc.LoopConfig(stream_gap_frames=0).validate()
