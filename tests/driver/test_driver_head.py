"""One head-client suite, run against the Python head emulator and the firmware host program.

Both legs are real byte streams: each backend serves a pseudo-terminal, the client opens it
with pyserial (SerialLink). Truth: the sensor image each backend reads windows from.
"""

import struct
import time

import numpy as np
import pytest
from cobs import cobs
from gyrostar.attitude import quat_from_boresight
from gyrostar.head import HeadClient
from gyrostar.protocol import MsgType, PixelFormat, crc32c, encode_frame
from gyrostar.protocol import errors as perr
from gyrostar.protocol.defs import LIMITS, PING_MAX, VERSION
from gyrostar.protocol.payloads import encode_request, encode_spans
from gyrostar.transport import SerialLink

Q0 = quat_from_boresight(np.radians(83.8), np.radians(-5.4), 0.0)  # Orion: bright stars in view


@pytest.fixture(scope="module")
def sky():
    from gyrostar.catalog import load_catalog
    from gyrostar.mocks.sky import Sky

    return Sky(load_catalog("hip2", 7.5), "xing2012", seed=3)


class EmulatorLeg:
    name = "emulator"

    def __init__(self, sky):
        from gyrostar.mocks.head_emulator import ConstantRateScene, HeadEmulator

        self.em = HeadEmulator(sky, ConstantRateScene(Q0), mcu_offset_us=987_654_321, drift_ppm=0.0, noise=False)
        self.em.warm_up(Q0)     # compiled before the first CAPTURE's 1 s reply timeout starts (cold numba cache)
        self._images = {}
        self.image = self.expected(LIMITS["exposure_default_us"])
        self.path = self.em.start()

    def expected(self, exposure_us):
        """The noiseless frame of the static scene at this exposure (what the emulator renders)."""
        if exposure_us not in self._images:
            from gyrostar.mocks.sky import Sky

            s = Sky(self.em.sky.catalog, self.em.sky.preset.with_exposure(exposure_us * 1e-6), seed=self.em.sky.seed)
            self._images[exposure_us] = np.minimum(s.render_frame(Q0, np.zeros(3), noise=False)[0], 0x3FF)
        return self._images[exposure_us]

    def true_offset_us(self, t):
        return self.em.mcu_offset_us_at(t)

    def close(self):
        self.em.stop()


class FirmwareLeg:
    name = "firmware"

    def __init__(self, sky):
        from gyrostar.mocks.firmware_host import FirmwareHost

        self.fw = FirmwareHost(sky.camera.width_px, sky.camera.height_px, planes=1)
        img, _ = sky.render_frame(Q0, np.zeros(3), frame=1, noise=True)
        self.fw.pixels.write_frame(img)
        self.image = np.minimum(img, 0x3FF)
        self.path = self.fw.start()

    def expected(self, exposure_us):
        return self.image  # the pixel file holds one frame whatever the exposure

    def true_offset_us(self, t):
        return 0.0  # the host program's MCU clock is CLOCK_MONOTONIC, as time.monotonic

    def close(self):
        self.fw.close()


def _firmware_built():
    from gyrostar.mocks.firmware_host import is_built

    return is_built()


@pytest.fixture(scope="module", params=["emulator", "firmware"])
def leg(request, sky):
    if request.param == "firmware" and not _firmware_built():
        pytest.skip("firmware host program not built (make -C firmware host)")
    backend = EmulatorLeg(sky) if request.param == "emulator" else FirmwareLeg(sky)
    yield backend
    backend.close()


@pytest.fixture
def head(leg):
    link = SerialLink(leg.path)
    client = HeadClient(link, timeout=1.0, retries=1)
    client.reset()
    yield client
    link.close()


def spans_grid(n_windows=10, rows=12, width=16, row0=300):
    return np.array([[w, row0 + r, 60 * w + 5, 60 * w + 5 + width] for w in range(n_windows) for r in range(rows)],
                    np.int32)


def test_ping_echo_and_limits(head):
    for echo in (b"", b"\x00\x01\x00", bytes(range(256))[:PING_MAX]):
        assert head.ping(echo) < 0.5
    with pytest.raises(perr.PayloadLengthError) as exc:
        head.request(MsgType.PING, bytes(PING_MAX + 1))
    assert exc.value.detail == PING_MAX + 1 and "PING" in str(exc.value)


def test_get_info_matches_sensor(head, leg):
    info = head.get_info()
    assert (info["width"], info["height"]) == leg.image.shape[::-1]
    assert info["proto_version"] == VERSION and info["bits"] == 10 and info["planes"] == 1
    for key in ("max_windows", "max_spans", "max_window_pixels", "pixel_budget", "frame_chunk_max"):
        assert info[key] == LIMITS[key]


def test_exposure_and_gain(head):
    assert head.set_exposure(5000) == 5000
    assert head.set_gain(32) == 32
    with pytest.raises(perr.ExposureRangeError) as exc:
        head.set_exposure(LIMITS["exposure_max_us"] + 1)
    assert exc.value.detail == LIMITS["exposure_max_us"] + 1
    with pytest.raises(perr.GainRangeError):
        head.set_gain(LIMITS["gain_min_x16"] - 1)
    assert head.set_exposure(LIMITS["exposure_min_us"]) == LIMITS["exposure_min_us"]


def test_windows_capture_pixels_and_times(head, leg):
    spans = spans_grid()
    rep = head.set_windows(spans)
    assert rep == {"n_windows": 10, "n_spans": len(spans), "n_pixels": int((spans[:, 3] - spans[:, 2]).sum()),
                   "frame": 0}
    head.set_exposure(20_000)
    head.sync(16)
    for fmt in (PixelFormat.PACKED10, PixelFormat.U16):
        t_before = time.monotonic()
        cap = head.capture(pixel_format=fmt)
        t_after = time.monotonic()
        assert cap.exposure_us == 20_000 and cap.t_end_us - cap.t_start_us >= 20_000
        assert t_after - t_before >= 0.020  # the exposure takes its time
        assert t_before - 0.002 < cap.t_mid_host < t_after  # mid-time mapped into host time
        assert [w.window_id for w in cap.windows] == list(range(10))
        image = leg.expected(cap.exposure_us)
        for w in cap.windows:
            rows = spans[spans[:, 0] == w.window_id]
            expect = np.concatenate([image[r, c0:c1] for _, r, c0, c1 in rows])
            assert np.array_equal(w.pixels, expect)
            assert w.sum == int(expect.sum())


def test_window_pages_when_one_payload_is_not_enough(head, leg):
    spans = spans_grid(n_windows=8, rows=32, width=32, row0=100)  # 8 × 1024 px = whole pixel budget
    head.set_windows(spans)
    cap = head.capture(pixel_format=PixelFormat.U16)  # 2 KiB per window: several pages
    assert len(cap.windows) == 8 and head.stats["requests"] >= 4
    got = np.concatenate([w.pixels for w in cap.windows])
    assert np.array_equal(got, np.concatenate([leg.image[r, c0:c1] for _, r, c0, c1 in spans]))


@pytest.mark.parametrize("bad, error, detail", [
    ([[0, 2000, 0, 10]], perr.SpanOutsideError, 0),
    ([[0, 5, 0, 10], [0, 6, 10, 10]], perr.SpanEmptyError, 1),
    ([[1, 5, 0, 10], [0, 6, 0, 10]], perr.SpanOrderError, 1),
    ([[0, 5, 0, 10], [0, 5, 20, 30]], perr.SpanOrderError, 1),
    ([[0, r, 0, 100] for r in range(21)], perr.WindowTooLargeError, 20),
    ([[w, 0, 0, 1] for w in range(65)], perr.WindowCountError, 64),
    ([[w, r, 0, 1000] for w in range(9) for r in range(2)], perr.PixelBudgetError, 8),
])
def test_window_rejections(head, bad, error, detail):
    head.set_windows(spans_grid(2, 2))
    with pytest.raises(error) as exc:
        head.set_windows(np.array(bad))
    assert exc.value.detail == detail and exc.value.code.name in str(exc.value)
    assert head.set_windows(spans_grid(2, 2))["n_windows"] == 2  # a rejected set changed nothing


def test_request_rejections(head):
    with pytest.raises(perr.NoWindowsError):
        head.capture()
    head.set_windows(spans_grid(2, 2))
    with pytest.raises(perr.NoCaptureError):
        head.window_data()
    head.capture(fetch=False)
    with pytest.raises(perr.PixelFormatError):
        head.request(MsgType.WINDOW_DATA, encode_request(MsgType.WINDOW_DATA, start=0, pixel_format=7))
    with pytest.raises(perr.WindowIndexError):
        head.request(MsgType.WINDOW_DATA, encode_request(MsgType.WINDOW_DATA, start=2, pixel_format=0))
    with pytest.raises(perr.DarkUnavailableError):
        head.capture(dark=True)
    with pytest.raises(perr.SpanCountError):
        head.request(MsgType.SET_WINDOWS, encode_request(MsgType.SET_WINDOWS, n_spans=LIMITS["max_spans"] + 1, frame=0))
    with pytest.raises(perr.SpansLengthError):
        head.request(MsgType.SET_WINDOWS, encode_spans(spans_grid(1, 2))[:-8])
    with pytest.raises(perr.PayloadLengthError):
        head.request(MsgType.TELEMETRY, b"\x00")
    ff = dict(offset=0, count=16, pixel_format=0, plane=0)
    for change, error in ((dict(count=0), perr.ChunkSizeError), (dict(count=LIMITS["frame_chunk_max"] + 1),
                                                                   perr.ChunkSizeError),
                          (dict(offset=1024 * 1024 - 8), perr.FrameRangeError), (dict(plane=2), perr.BadPlaneError),
                          (dict(plane=1), perr.DarkUnavailableError), (dict(pixel_format=2), perr.PixelFormatError)):
        with pytest.raises(error):
            head.request(MsgType.FULL_FRAME, encode_request(MsgType.FULL_FRAME, **{**ff, **change}))


def _raw_frame(version, msg_type, seq, length, payload):
    raw = struct.pack("<BBHH", version, msg_type, seq, length) + payload
    return cobs.encode(raw + struct.pack("<I", crc32c(raw))) + b"\x00"


def _reply_to(head, data, seq):
    head.link.send(data)
    t_end = time.monotonic() + 1.0
    while time.monotonic() < t_end:
        got = head.link.recv(t_end - time.monotonic())
        if got is None:
            return None
        from gyrostar.protocol import decode_frame

        frame = decode_frame(got[1])
        if frame.seq == seq:
            return frame
    return None


def test_link_level_rejections_and_corrupt_frames(head):
    from gyrostar.protocol.payloads import decode_reply

    for data, error in ((_raw_frame(VERSION + 1, MsgType.PING, 900, 0, b""), perr.BadVersionError),
                        (_raw_frame(VERSION, MsgType.PING, 900, 5, b"ab"), perr.FrameLengthError),
                        (_raw_frame(VERSION, 0x42, 900, 0, b""), perr.UnknownTypeError)):
        frame = _reply_to(head, data, 900)
        with pytest.raises(error):
            decode_reply(frame)
    before = head.telemetry()
    good = bytearray(encode_frame(MsgType.PING, 901, b"abc"))
    good[3] ^= 0x10  # a flipped bit: the CRC fails, no reply
    assert _reply_to(head, bytes(good), 901) is None
    after = head.telemetry()
    assert after["crc_errors"] == before["crc_errors"] + 1 and after["rejected"] == before["rejected"]


def test_full_frame_streamed(head, leg):
    img, _ = head.full_frame(pixel_format=PixelFormat.PACKED10)
    assert np.array_equal(img, leg.image)


def test_find_spots_lists_the_stars_and_reads_their_windows(head, leg, sky):
    """FIND_SPOTS on both legs: the spot list is the firmware rule applied to the frame the
    leg holds (the Python mirror of gs_spots.c), each spot lies on a true star, and the
    windows hold that frame's pixels."""
    from gyrostar.mocks.spot_finder import find_spots

    got = head.find_spots(n_sigma=6.0, max_spots=40, box=7)
    want = find_spots(leg.image, 96, 40, 7)
    assert got.spots.tolist() == want["spots"].tolist() and len(got.spots) >= 10
    assert (got.background_dn * 16, got.sigma_dn * 16, got.candidates) == (
        want["background_x16"], want["sigma_x16"], want["candidates"])
    pixels = np.concatenate([w.pixels for w in got.capture.windows])
    truth = np.concatenate([leg.image[r, c0:c1] for _, r, c0, c1 in want["spans"]])
    assert np.array_equal(pixels, truth)
    # independent truth: the brightest spots sit within 1.5 px of a true star's centroid
    _, st = sky.render_frame(Q0, np.zeros(3), noise=False)
    uv = st.uv[st.in_field]
    for row, col, _ in got.spots[:8]:
        assert np.min(np.hypot(uv[:, 0] - col, uv[:, 1] - row)) < 1.5
    # a rejected setting names the field, changes nothing
    with pytest.raises(perr.FirmwareError) as info:
        head.find_spots(n_sigma=6.0, max_spots=40, box=8)
    assert info.value.detail == 3
    assert head.window_data(PixelFormat.U16, got.capture.capture_no)[0].window_id == 1


def test_time_sync_offset(head, leg):
    head.sync(32)
    est = head.sync_state.offset_at(time.monotonic())
    assert abs(est - leg.true_offset_us(time.monotonic())) < 200.0  # pty + reader thread, no injected jitter


def test_telemetry_and_reset(head):
    head.set_exposure(777)
    head.set_windows(spans_grid(1, 1))
    head.capture(fetch=False)
    tm = head.telemetry()
    assert tm["captures"] == 1 and tm["rx_frames"] >= 4
    head.reset()
    with pytest.raises(perr.NoWindowsError):
        head.capture()
    head.set_windows(spans_grid(1, 1))
    assert head.capture(fetch=False).exposure_us == LIMITS["exposure_default_us"]


def test_corrupted_requests_are_dropped_by_the_head_and_retried(leg):
    from gyrostar.mocks.faults import ByteFaults, JitteredLink

    link = SerialLink(leg.path)
    faults = ByteFaults(seed=3, corrupt_p=0.01)  # ~28 % of the requests damaged
    head = HeadClient(JitteredLink(link, faults), timeout=0.1, retries=12)
    try:
        before = HeadClient(link).telemetry()
        for i in range(40):
            assert head.ping(bytes([i]) * 20) < 1.0
        after = HeadClient(link).telemetry()
        assert faults.injected["corrupt"] > 0 and head.stats["retries"] > 0
        dropped = (after["crc_errors"] - before["crc_errors"]) + (after["framing_errors"] - before["framing_errors"])
        assert dropped > 0  # the head counted the damaged requests and did not answer them
    finally:
        link.close()


def test_pipelined_windows_capture_matches_the_sequential_one(head, leg):
    """SET_WINDOWS + CAPTURE + WINDOW_DATA sent back to back: the same pixels as the
    request-by-request exchange, pages beyond the first fetched, no fallback needed."""
    for spans in (spans_grid(), spans_grid(n_windows=8, rows=32, width=32, row0=100)):   # 1 page, several
        cap = head.capture_windows(spans)
        assert head.stats["pipeline_fallbacks"] == 0
        assert [w.window_id for w in cap.windows] == sorted(set(spans[:, 0].tolist()))
        got = np.concatenate([w.pixels for w in cap.windows])
        image = leg.expected(cap.exposure_us)
        assert np.array_equal(got, np.concatenate([image[r, c0:c1] for _, r, c0, c1 in spans]))
        seq = head.capture(pixel_format=PixelFormat.U16)           # same window set, request by request
        assert seq.capture_no == cap.capture_no + 1
        assert np.array_equal(np.concatenate([w.pixels for w in seq.windows]), got)


def test_pipelined_capture_with_a_rejected_window_set_raises_that_rejection(head):
    from gyrostar.protocol.errors import FirmwareError

    good = spans_grid()
    head.capture_windows(good)
    bad = good.copy()
    bad[0, 3] = 5000                                   # a span off the sensor: SET_WINDOWS is rejected
    with pytest.raises(FirmwareError):
        head.capture_windows(bad)
    assert head.stats["pipeline_fallbacks"] == 1       # the pipelined capture was not used
    cap = head.capture_windows(good)                   # the stale replies of the rejected try are skipped
    assert len(cap.windows) == 10


def test_pipelined_capture_under_request_corruption_never_returns_the_old_windows(leg):
    """Requests damaged on the way (the head drops them): a capture is returned only for the
    window set asked for — never the previous set's pixels."""
    from gyrostar.mocks.faults import ByteFaults, JitteredLink

    link = SerialLink(leg.path)
    faults = ByteFaults(seed=11, corrupt_p=0.0005)    # ~20 % of the window sets damaged
    head = HeadClient(JitteredLink(link, faults), timeout=0.1, retries=12)
    try:
        HeadClient(link).reset()
        sets = [spans_grid(rows=6, row0=200), spans_grid(n_windows=6, rows=8, width=24, row0=500)]
        for i in range(24):
            spans = sets[i % 2]
            cap = head.capture_windows(spans)
            image = leg.expected(cap.exposure_us)
            got = np.concatenate([w.pixels for w in cap.windows])
            assert np.array_equal(got, np.concatenate([image[r, c0:c1] for _, r, c0, c1 in spans]))
        assert faults.injected["corrupt"] > 0 and head.stats["pipeline_fallbacks"] > 0
    finally:
        link.close()


# --- streaming -------------------------------------------------------------------------------
def _window_truth(image, spans, w):
    rows = spans[spans[:, 0] == w.window_id]
    return np.concatenate([image[r, c0:c1] for _, r, c0, c1 in rows])


def test_stream_frames_follow_the_timer_back_to_back(head, leg):
    """Frames come unasked, numbered in sequence, one exposure every period with no gap
    (frame k+1 integrates while k is read), pixels equal to the sensor's."""
    spans = spans_grid(n_windows=6, rows=8, width=10)
    head.set_windows(spans)
    head.sync(8)
    # a head held up by this shared machine (the emulator is a thread of this interpreter)
    # drops a frame now and then: up to 3 streams of 40 frames, one must drop at most 2;
    # every stream must account for each of its gaps
    for _ in range(3):
        rep = head.start_stream(10_000, 10_000, PixelFormat.PACKED10)
        got = []
        try:
            while len(got) < 40:
                fr = head.next_frame(0.5)
                assert fr is not None, f"no frame after {len(got)}"
                got.append(fr)
            with pytest.raises(perr.StreamingError):
                head.capture()
        finally:
            stop = head.stop_stream()
        ks = np.array([f.frame for f in got])
        # in sequence; a frame the head could not serve in time is a gap that its dropped
        # counter accounts for, never a silent one
        assert ks[0] - rep["first_frame"] == got[0].dropped and np.all(np.diff(ks) >= 1)
        assert got[-1].dropped == (ks[-1] - ks[0] + 1 - len(ks)) + got[0].dropped
        # (a frame the host read too late for — the pty's buffer still full — is dropped for
        # backpressure: counted in both)
        assert got[-1].backpressure <= got[-1].dropped
        if got[-1].dropped <= 2:
            break
        while head.next_frame(0.05) is not None:      # the stopped stream's last frames
            pass
    assert got[-1].dropped <= 2, f"{got[-1].dropped} frames dropped in each of 3 streams"
    starts = np.array([f.t_start_us for f in got])
    assert np.all(np.abs(np.diff(starts) - 10_000 * np.diff(ks)) <= 1)      # on the head's timer grid
    assert all(f.t_end_us - f.t_start_us == pytest.approx(10_000, abs=1) for f in got)
    assert stop["frames"] >= 40 and stop["dropped"] >= got[-1].dropped
    image = leg.expected(10_000)
    for f in got[::7]:
        assert [w.window_id for w in f.windows] == list(range(6))
        for w in f.windows:
            assert np.array_equal(w.pixels, _window_truth(image, spans, w))
    # frames arrive after their exposure ends, soon (unpaced pty): mid-exposure in host time
    lag = np.array([f.t_rx - f.t_mid_host for f in got])
    assert np.all(lag > 0.005) and np.median(lag) < 0.05
    assert head.next_frame(0.05) is None or head.next_frame(0.05) is None   # the stream has stopped


def test_stream_window_sets_for_named_frames_and_late_ones(head, leg):
    a = spans_grid(n_windows=2, rows=4, width=8, row0=100)
    b = spans_grid(n_windows=3, rows=4, width=8, row0=400)
    c = spans_grid(n_windows=4, rows=4, width=8, row0=700)
    head.set_windows(a)
    rep = head.start_stream(10_000, 10_000, PixelFormat.U16)
    try:
        k = rep["first_frame"]
        head.send_windows(b, k + 5)                  # well ahead: used from frame k+5 exactly
        frames = [head.next_frame(0.5) for _ in range(8)]
        head.send_windows(c, frames[-1].frame)        # a frame already read: late
        more = [head.next_frame(0.5) for _ in range(4)]
    finally:
        head.stop_stream()
    by_k = {f.frame: f for f in frames + more}
    assert len(by_k[k + 4].windows) == 2 and by_k[k + 4].set_frame == 0
    assert len(by_k[k + 5].windows) == 3 and by_k[k + 5].set_frame == k + 5
    late = [f for f in more if len(f.windows) == 4]
    assert late and late[0].set_frame == frames[-1].frame and late[0].late_sets == 1
    assert more[0].late_sets in (0, 1)
    replies = [r for _, r in head.window_set_replies]
    assert replies[-2]["frame"] == k + 5
    assert replies[-1]["frame"] == late[0].frame     # the head said where the late set went


def test_stream_start_rejections(head):
    with pytest.raises(perr.StreamPeriodError) as exc:
        head.start_stream(9_000, 10_000)
    assert exc.value.detail == 9_000
    with pytest.raises(perr.ExposureRangeError):
        head.start_stream(10_000, 5)
    assert head.stop_stream()["frames"] >= 0          # idle STOP_STREAM is fine


def test_new_client_ignores_late_replies_meant_for_an_earlier_one(leg):
    """The defect: an earlier client's TIME_SYNC replies still on the link matched a new
    client's first sequence numbers (both started at 1, host_us always 0), and the clock
    offset came out by the replies' age (251 ms in the report). The new client must only
    accept a TIME_SYNC reply echoing its own request's host time."""
    import os
    import tty

    old = os.open(leg.path, os.O_RDWR | os.O_NOCTTY)   # an old client that goes away
    try:
        tty.setraw(old)
        os.write(old, encode_frame(MsgType.SET_WINDOWS, 100, encode_spans(spans_grid(1, 2))))
        os.write(old, encode_frame(MsgType.SET_EXPOSURE, 101, encode_request(MsgType.SET_EXPOSURE,
                                                                             exposure_us=250_000)))
        os.write(old, encode_frame(MsgType.CAPTURE, 102))   # the head is busy for 250 ms
        for seq in range(1, 9):   # then answers these, late: seq from 1, host_us = 0
            os.write(old, encode_frame(MsgType.TIME_SYNC, seq, encode_request(MsgType.TIME_SYNC, host_us=0)))
    finally:
        os.close(old)
    link = SerialLink(leg.path)   # a new client, while the old replies are still to come
    try:
        client = HeadClient(link, timeout=1.0, first_seq=1)   # the worst case: the same seqs
        client.sync(8)
        client.set_exposure(10_000)
        err = client.sync_state.offset_at(time.monotonic()) - leg.true_offset_us(time.monotonic())
        assert abs(err) < 1000.0, f"clock offset {err / 1e3:.1f} ms wrong"
        assert client.stats["sync_echo_mismatch"] + client.stats["stale"] >= 1, (client.stats, err)
    finally:
        link.close()
    # without first_seq the first sequence number is random, not 1
    firsts = {HeadClient(link, first_seq=None).seq for _ in range(8)}
    assert len(firsts) > 1


def _random_span_set(rng):
    """A window set near the firmware's limits: mostly valid, with one kind of fault at a
    random place (off the sensor, empty, out of order, too many windows, a window or the
    frame over its pixel budget)."""
    n_win = int(rng.integers(1, 4) if rng.random() < 0.3 else rng.integers(1, 70))
    rows = int(rng.integers(1, 24))
    width = int(rng.integers(1, 130 if n_win < 4 else 60))
    spans = [[w, 10 + r, 8 * w, 8 * w + width] for w in range(n_win) for r in range(rows)]
    i = int(rng.integers(0, len(spans)))
    fault = rng.integers(0, 6)
    if fault == 1:
        spans[i][1 + int(rng.integers(0, 2)) * 2] = 5000            # row or col_stop off the sensor
    elif fault == 2:
        spans[i][3] = max(spans[i][2] - int(rng.integers(0, 2)), 0)   # empty
    elif fault == 3 and i:
        spans[i][0], spans[i][1] = spans[i - 1][0], spans[i - 1][1]   # same row twice: order
    elif fault == 4 and i:
        spans[i - 1], spans[i] = spans[i], spans[i - 1]
    return np.array(spans[:LIMITS["max_spans"]], np.int32)


def test_window_set_verdicts_match_the_firmware_on_random_sets(sky):
    """The emulator's window-set checks (whole-array) give the firmware's verdict — the same
    error and the same first offending span, or the same counts — on 300 random sets."""
    if not _firmware_built():
        pytest.skip("firmware host program not built (make -C firmware host)")
    legs = [EmulatorLeg(sky), FirmwareLeg(sky)]
    links = [SerialLink(leg.path) for leg in legs]
    try:
        heads = [HeadClient(link, timeout=1.0, retries=1) for link in links]
        for h in heads:
            h.reset()
        rng = np.random.default_rng(11)
        kinds = set()
        full = [[0, r, 0, 128] for r in range(16)]                       # max_window_pixels exactly
        edges = [full, full + [[0, 16, 0, 1]],
                 [[w, r, 0, 128] for w in range(4) for r in range(16)],   # the pixel budget exactly
                 [[w, r, 0, 128] for w in range(4) for r in range(16)] + [[4, 0, 0, 1]],
                 [[w, 0, 0, 1] for w in range(64)]]                      # max_windows exactly
        for spans in [np.array(e, np.int32) for e in edges] + [_random_span_set(rng) for _ in range(300)]:
            verdicts = []
            for h in heads:
                try:
                    r = h.set_windows(spans)
                    verdicts.append(("ok", r["n_windows"], r["n_spans"], r["n_pixels"]))
                except perr.FirmwareError as exc:
                    verdicts.append((type(exc).__name__, exc.detail))
            assert verdicts[0] == verdicts[1], spans.tolist()
            kinds.add(verdicts[0][0])
        assert {"ok", "SpanOutsideError", "SpanEmptyError", "SpanOrderError", "WindowCountError",
                "WindowTooLargeError", "PixelBudgetError"} <= kinds
    finally:
        for link in links:
            link.close()
        for leg in legs:
            leg.close()
