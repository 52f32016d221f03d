"""Links paced at their line rate (mocks.paced_relay over linkrate.Wire), with the firmware
host program as the head: wire times against hand-computed ones, and a stream too heavy for
its link dropping frames at the head (back-pressure) instead of building a backlog."""

import time

import numpy as np
import pytest
from gyrostar.head import HeadClient
from gyrostar.protocol import PixelFormat
from gyrostar.transport import SerialLink
from gyrostar.transport.linkrate import Wire, preset


def test_wire_queues_bytes_behind_each_other():
    w = Wire(preset("uart-921k"))
    t1 = w.transmit(921, 0.0)                  # 921 B at 92,160 B/s: 9.99 ms + 3 char times
    assert t1 == pytest.approx(921 / 92_160 + 30 / 921_600)
    t2 = w.transmit(100, 0.001)                # queued behind the first
    assert t2 == pytest.approx((921 + 100) / 92_160 + 30 / 921_600)
    assert w.queued_bytes(0.005) == pytest.approx(1021 - 0.005 * 92_160)
    assert w.queued_bytes(1.0) == 0.0


@pytest.fixture(scope="module")
def fw():
    from gyrostar.mocks.firmware_host import FirmwareHost, is_built

    if not is_built():
        pytest.skip("firmware host program not built (make -C firmware host)")
    host = FirmwareHost(1024, 1024, planes=1)
    host.pixels.write_frame(np.random.default_rng(2).integers(0, 1024, (1024, 1024)).astype(np.uint16))
    host.start()
    yield host
    host.close()


def _client(fw, link):
    from gyrostar.mocks.paced_relay import RelayProcess

    relay = RelayProcess(fw.path, link)
    serial = SerialLink(relay.path)
    return relay, serial, HeadClient(serial, timeout=1.0)


def test_ping_takes_its_wire_time(fw):
    relay, serial, head = _client(fw, "uart-921k")
    try:
        echo = bytes(range(200))
        rtts = [head.ping(echo) for _ in range(20)]
        # request and reply: 6 B header + 200 + 4 B CRC, COBS +1..2, delimiter: ≥ 212 B each way
        wire = 2 * preset("uart-921k").wire_time(212)
        assert min(rtts) >= wire
        # each ping takes four process wake-ups (client, relay, head, relay): the quicker
        # quarter shows the link, the rest also a loaded machine's scheduling
        assert np.percentile(rtts, 25) < wire + 0.004
    finally:
        serial.close()
        relay.close()


def _stream(head, spans, seconds):
    head.set_windows(spans)
    head.sync(4)
    head.start_stream(10_000, 10_000, PixelFormat.PACKED10)
    frames, t_end = [], time.monotonic() + seconds
    try:
        while time.monotonic() < t_end:
            fr = head.next_frame(0.2)
            if fr is not None:
                frames.append(fr)
    finally:
        stop = head.stop_stream()
    return frames, stop


def test_stream_over_a_slow_uart_drops_at_the_head_never_queues(fw):
    """Windows of 1,600 px: about 2 kB per frame packed, 200 kB/s at 100 Hz, twice what a
    921.6 kBd UART carries. The head must drop frames (back-pressure) and the frames that
    come must arrive a bounded time after their exposure, not later and later."""
    spans = np.array([[w, 200 + r, 50 * w, 50 * w + 20] for w in range(10) for r in range(8)], np.int32)
    relay, serial, head = _client(fw, "uart-921k")
    try:
        frames, stop = _stream(head, spans, 3.0)
    finally:
        serial.close()
        relay.close()
    per_frame = np.median([f.wire_bytes for f in frames])
    assert 1900 < per_frame < 2200
    rate = len(frames) / 3.0
    capacity = preset("uart-921k").bytes_per_s / per_frame          # ~45 frames/s
    assert 0.4 * capacity < rate <= 1.05 * capacity     # a frame leaves only onto an idle line
    assert stop["backpressure"] > 0 and stop["dropped"] >= stop["backpressure"]
    lag = np.array([f.t_rx - f.t_mid_host for f in frames])
    # mid-exposure → received: half an exposure + the frame's wire time (+ a little of the
    # previous frame); a backlog would grow by ~20 ms a frame to seconds within 3 s. Bounds
    # are loose for a shared, loaded machine: the median is the model, the tail the load.
    wire = preset("uart-921k").wire_time(per_frame)
    assert 0.005 + wire < np.median(lag) < 0.005 + wire + 0.012
    assert np.percentile(lag, 90) < 0.005 + 3 * wire + 0.03
    assert np.median(lag[-15:]) < np.median(lag[:15]) + 0.01


def test_stream_over_usb_fs_keeps_every_frame(fw):
    """2.1 kB in 2.4 ms of a 10 ms period: nothing to drop. The relay and the head are
    processes of their own on a shared machine, and one held up for tens of ms makes the head
    drop frames for backpressure (15 of 200 with two busy loops beside the test): the 2 s
    stream is run up to 3 times and one must keep within the bounds. A link or a head that
    drops frames of its own fails all three."""
    spans = np.array([[w, 200 + r, 50 * w, 50 * w + 20] for w in range(10) for r in range(8)], np.int32)
    runs = []
    for _ in range(3):
        relay, serial, head = _client(fw, "usb-fs")
        try:
            frames, stop = _stream(head, spans, 2.0)
            while (fr := head.next_frame(0.05)) is not None:      # sent before the stop, still on the way
                frames.append(fr)
        finally:
            serial.close()
            relay.close()
        runs.append((stop["backpressure"], stop["dropped"], stop["frames"], len(frames)))
        if stop["backpressure"] <= 6 and stop["dropped"] <= 8:
            break
    print(f"runs (backpressure, dropped, frames sent, frames received): {runs}")
    assert stop["backpressure"] <= 6 and stop["dropped"] <= 8
    assert stop["frames"] >= 2.0 * 100 - stop["dropped"] - 10
    assert len(frames) == stop["frames"]                     # every frame the head sent came through
    lag = np.array([f.t_rx - f.t_mid_host for f in frames])
    assert np.median(lag) < 0.005 + preset("usb-fs").wire_time(2100) + 0.002


def _pty_pair():
    import os
    import tty

    a, b = os.openpty()
    tty.setraw(a)
    tty.setraw(b)
    return a, b


def _settle(d, n, timeout=1.0):
    """Wait until the pty has handed ``n`` written bytes to the reader side."""
    t_end = time.monotonic() + timeout
    while d.waiting() < n and time.monotonic() < t_end:
        time.sleep(0.001)


def test_relay_never_sends_a_message_before_it_was_written():
    """A read that happens to take a whole slice and empty the queue must not make the next
    message look as if the line had been sending it since (the relay waking late)."""
    import os

    from gyrostar.mocks.paced_relay import LinkDirection

    link = preset("uart-921k")
    w, r = _pty_pair()
    now = [0.0]
    d = LinkDirection(r, -1, link, clock=lambda: now[0])
    try:
        os.write(w, bytes(d.chunk))                 # exactly one slice: the read takes it all
        _settle(d, d.chunk)
        assert d.take(0.0) and d.backlog == 0
        os.write(w, bytes(212))                     # the next message, read 1 s later
        _settle(d, 212)
        now[0] = 1.0
        while d.waiting():
            assert d.take(now[0])
            now[0] = max(now[0], d.wire.busy_until)
        assert d.pending[-1][0] >= 1.0 + link.wire_time(212) - 1e-12
    finally:
        os.close(w)
        os.close(r)


def test_relay_keeps_the_line_rate_when_it_wakes_late():
    """Bytes seen waiting after a read went on the wire when it fell free: a relay that
    wakes 5 ms late reads them as sent then, so the delivery is the line's, not later."""
    import os

    from gyrostar.mocks.paced_relay import LinkDirection

    link = preset("uart-921k")
    w, r = _pty_pair()
    now = [0.0]
    d = LinkDirection(r, -1, link, clock=lambda: now[0])
    try:
        os.write(w, bytes(1000))
        _settle(d, 1000)
        assert d.take(0.0) and d.backlog == 1000 - d.chunk
        now[0] = d.wire.busy_until + 0.005            # the relay sleeps through five slices
        while d.waiting():
            assert d.take(now[0])
            now[0] = max(now[0], d.wire.busy_until)
        assert sum(len(p[1]) for p in d.pending) == 1000
        assert d.pending[-1][0] == pytest.approx(link.wire_time(1000), abs=1e-9)
    finally:
        os.close(w)
        os.close(r)


def test_time_sync_behind_a_window_set_on_a_slow_uart(fw):
    """A TIME_SYNC sent right after a 3.6 kB window set waits ~39 ms on a 921.6 kBd wire
    before its first byte goes out. A client that knows its link counts its request from
    then (and the reply's longer wire time): the head's clock (the firmware host program's,
    CLOCK_MONOTONIC µs: offset 0) comes out within a relay slice. One that does not is off
    by half the wait."""
    from gyrostar.mocks.paced_relay import RelayProcess

    uart = preset("uart-921k")
    spans = np.array([[w, 10 * w + r, 100, 116] for w in range(64) for r in range(7)])   # 448 spans
    errors = {"knows its link": [], "does not": []}
    wait_us = uart.wire_time(448 * 8 + 20) * 1e6
    # one exchange each: a relay that wakes late on this shared machine adds half its delay,
    # so the informed client gets up to 3 tries to come within a relay slice; the other
    # must be off by about half the wait on every try
    for _ in range(3):
        for name, link_preset in (("knows its link", uart), ("does not", None)):
            relay = RelayProcess(fw.path, uart)
            serial = SerialLink(relay.path)
            try:
                head = HeadClient(serial, timeout=1.0, link_preset=link_preset)
                head.ping(b"")                            # the relay's first bytes through
                head.send_windows(spans, frame=1)         # not waited for: on the wire meanwhile
                head.sync(1)
                errors[name].append(head.sync_state.offset_us)
            finally:
                serial.close()
                relay.close()
        if abs(errors["knows its link"][-1]) < 1000.0:
            break
    print(f"offset errors (µs): {errors}, set on the wire {wait_us:.0f} µs")
    assert abs(errors["knows its link"][-1]) < 1000.0     # relay slices of 1 ms, host wake-ups
    assert min(errors["does not"]) > 0.4 * wait_us        # the request's wait counted as link delay



def test_time_sync_replies_behind_streamed_frames_on_a_slow_uart(fw):
    """A stream twice what a 921.6 kBd UART carries keeps the head's transmitter busy: some
    TIME_SYNC replies wait behind frame bytes, and the firmware stamps them when built, so
    that wait is link delay on the way down only. Their NTP midpoints are off by ms, all one
    way; the clock (the host program's CLOCK_MONOTONIC µs: offset 0) must come out within a
    relay slice all the same (this client is not told its link: the reply's 16 more bytes
    leave -87 µs of it)."""
    from gyrostar.head import ClockSync

    uart = preset("uart-921k")
    spans = np.array([[w, 200 + r, 50 * w, 50 * w + 20] for w in range(10) for r in range(8)], np.int32)
    relay, serial, head = _client(fw, "uart-921k")
    try:
        head.set_windows(spans)
        head.start_stream(10_000, 10_000, PixelFormat.PACKED10)
        head.next_frame(1.0)
        head.sync_state = ClockSync()           # only exchanges made while streaming
        # A frame takes ~24 ms on this wire and the head starts one at each 10 ms tick its
        # transmitter is free, so a request sent straight after a frame lands in the idle gap
        # more often than not (1 in 60 waited on one machine). Each request goes 0-22 ms after
        # its frame, a spread over the whole cycle, so that some land while a frame is going out.
        for i in range(72):
            head.next_frame(0.05)
            time.sleep(0.002 * (i % 12))
            head.sync(1)
        head.stop_stream()
    finally:
        serial.close()
        relay.close()
    ex = head.sync_state.exchanges
    midpoints = (ex[:, 1] - ex[:, 2]) / 2
    offset = head.sync_state.offset_us
    print(f"offset error {offset:.0f} µs; midpoints median {np.median(midpoints):.0f} µs, "
          f"min {midpoints.min():.0f} µs, {np.sum(midpoints < -2000.0)} below -2 ms of {len(ex)} exchanges; "
          f"line {uart.name}")
    assert len(ex) >= 60
    assert np.sum(midpoints < -2000.0) >= 3     # replies that waited: one-sided, ms
    assert abs(offset) < 500.0
