"""The loop's link budget: wire bytes of a streamed frame against the protocol's encoders,
per-frame budgets against hand-computed ones, and the degrade order (fewer stars → tighter
windows → lower frame rate → back up when there is room)."""

import numpy as np
import pytest
from gyrostar.loop.linkbudget import LinkBudget, frame_bytes, windows_bytes
from gyrostar.protocol import MsgType, encode_frame
from gyrostar.protocol.defs import REPLY_FLAG
from gyrostar.protocol.payloads import WindowPixels, encode_reply, encode_spans, encode_windows_tail
from gyrostar.transport.linkrate import preset


@pytest.mark.parametrize("sizes", [[36], [36] * 10, [120, 64, 49, 300, 36, 36, 81, 100, 25, 16, 9, 4]])
def test_frame_and_window_bytes_match_the_encoders(sizes):
    rng = np.random.default_rng(len(sizes))
    wins = [WindowPixels(i, 0, rng.integers(1, 1024, n)) for i, n in enumerate(sizes)]
    head = encode_reply(MsgType.FRAME, frame=9, set_frame=7, t_start_us=1, t_end_us=2, exposure_us=1, late_sets=0,
                        dropped=0, backpressure=0, n_pixels=sum(sizes), start=0, count=len(wins), total=len(wins),
                        pixel_format=1)
    wire = len(encode_frame(MsgType.FRAME | REPLY_FLAG, 1, head + encode_windows_tail(wins, 1))) + 1
    model = frame_bytes(sum(sizes), len(sizes))
    assert wire - 2 <= model <= wire + len(sizes) + 2        # never under-counts
    spans = np.array([[i, r, 0, 6] for i in range(len(sizes)) for r in range(6)], np.int32)
    up = len(encode_frame(MsgType.SET_WINDOWS, 1, encode_spans(spans, frame=3))) + 1
    assert up - 1 <= windows_bytes(len(spans)) <= up + 2


def test_budgets_of_a_uart_at_100hz():
    b = LinkBudget(preset("uart-921k"), 100.0)
    px, spans = b.limits(10)
    # 0.8 × 92,160 B/s / 100 Hz = 737 B per frame each way
    # FRAME: 52 B fixed + 12 B framing, 8 B header + 1 B COBS allowance per window
    assert 737 - 52 - 12 - 10 * 9 - 2 <= px * 10 / 8 <= 737 - 52 - 12 - 10 * 9 + 1
    assert spans == pytest.approx((737 - 8 - 12) / 8, abs=1.5)
    usb = LinkBudget(preset("usb-fs"), 100.0)
    assert usb.limits(10)[0] > 9 * px


def test_degrade_order_and_recovery():
    b = LinkBudget(preset("uart-921k"), 100.0, patience=3)
    px, sp = b.limits(8)
    assert b.margin_allowed()
    # stars left out while the budget is full: windows tighten, the rate stays
    assert b.after_plan(0.0, 10, 8, px, 40) is None
    assert not b.margin_allowed() and b.frames_cut == 1
    # even tight windows leave fewer than min_stars for `patience` frames: 50 Hz
    got = [b.after_plan(0.01 * i, 10, 2, px, 20) for i in range(1, 4)]
    assert got[-1] == 2 and b.frame_hz == 50.0 and b.rate_changes[-1][1] == 50.0
    # everything fits, with room at 100 Hz for 2×patience frames: back to 100 Hz
    small_px = int(0.5 * b.limits(10, 100.0)[0])
    got = [b.after_plan(1.0 + 0.02 * i, 10, 10, small_px, 30) for i in range(6)]
    assert got[-1] == 1 and b.frame_hz == 100.0 and b.margin_allowed()
    s = b.summary()
    assert s["preset"] == "uart-921k" and [r[1] for r in s["rate_changes"]] == [50.0, 100.0]


def test_a_star_off_the_sensor_is_not_the_links_doing():
    b = LinkBudget(preset("usb-fs"), 100.0)
    assert b.after_plan(0.0, 12, 11, 500, 60) is None        # budget far from used: not cut
    assert b.frames_cut == 0 and b.margin_allowed()


def test_smeared_windows_that_leave_less_than_one_window_are_cut():
    """10 °/s on a 921.6 kBd UART (a measured plan): 12 stars tracked, two windows of
    ~195 px planned, 390 of the 524 px a two-window frame may carry. That is 74 % of the
    budget, but the 134 px left cannot hold a third such window: the link cut the stars.
    Windows tighten, and when even then fewer than 4 stars fit for `patience` frames the
    frame rate halves, which doubles each frame's budget."""
    b = LinkBudget(preset("uart-921k"), 100.0, patience=3)
    px, _ = b.limits(2)
    assert 520 <= px <= 528 and 390 < 0.8 * px          # not cut by the 80 % rule
    assert b.after_plan(0.0, 12, 2, 390, 30) is None
    assert b.frames_cut == 1 and not b.margin_allowed()
    got = [b.after_plan(0.01 * i, 12, 2, 390, 30) for i in range(1, 3)]   # 3 frames short in all
    assert got[-1] == 2 and b.frame_hz == 50.0
    assert b.limits(4, 50.0)[0] > 2 * b.limits(4, 100.0)[0]
