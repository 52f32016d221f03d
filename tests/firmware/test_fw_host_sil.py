"""The firmware's host program on a pty, driven through gyrostar.head.client (software in the loop)."""

import os
import time

import numpy as np
import pytest
from gyrostar.fwtools import build, wirecount
from gyrostar.protocol import MsgType, PixelFormat, errors
from gyrostar.protocol.framing import encode_frame

pytest.importorskip("gyrostar.head.client")
from gyrostar.head import HeadClient  # noqa: E402
from gyrostar.mocks.firmware_host import FirmwareHost  # noqa: E402
from gyrostar.transport.serial_link import SerialLink  # noqa: E402

W = H = 1024


@pytest.fixture(scope="module")
def head():
    build.build("host")
    host = FirmwareHost(W, H, planes=2)
    host.start()
    rng = np.random.default_rng(1)
    light = rng.integers(0, 1100, (H, W)).astype(np.uint16)  # some above 1023: the ADC clips
    dark = rng.integers(30, 60, (H, W)).astype(np.uint16)
    host.pixels.write_frame(light, dark)
    link = wirecount.CountingLink(SerialLink(host.path))
    client = HeadClient(link, timeout=1.0)
    yield host, client, link, light, dark
    link.link.close()
    host.close()


def test_info_ping_and_clock(head):
    host, client, *_ = head
    info = client.get_info()
    assert (info["width"], info["height"], info["port"], info["planes"]) == (W, H, 1, 2)
    rtts = [client.ping(bytes(range(16))) for _ in range(20)]
    assert np.median(rtts) < 0.05
    # the MCU clock of the host port is CLOCK_MONOTONIC in us, as time.monotonic
    sync = client.sync(4)
    assert sync.ready


def test_windowed_capture_pixels_and_timing(head):
    host, client, link, light, dark = head
    spans = np.array([[0, 100, 200, 206], [0, 101, 200, 207], [0, 102, 201, 207],
                      [5, 900, 1018, 1024], [5, 901, 1017, 1024]], dtype=np.int32)
    rep = client.set_windows(spans)
    assert (rep["n_windows"], rep["n_spans"], rep["n_pixels"]) == (2, 5, 6 + 7 + 6 + 6 + 7)
    client.set_exposure(5000)
    for fmt in (PixelFormat.U16, PixelFormat.PACKED10):
        t0 = time.monotonic()
        cap = client.capture(pixel_format=fmt)
        assert time.monotonic() - t0 >= 0.005
        assert cap.t_end_us - cap.t_start_us >= 5000
        assert cap.sensor_frame == host.pixels.frame
        for w, wid in zip(cap.windows, (0, 5)):
            rows = spans[spans[:, 0] == wid]
            want = np.concatenate([light[r, c0:c1] for _, r, c0, c1 in rows]).clip(0, 1023)
            assert w.window_id == wid
            assert np.array_equal(w.pixels, want)
            assert w.sum == int(want.sum())
    dcap = client.capture(dark=True, pixel_format=PixelFormat.U16)
    assert dcap.plane == 1
    assert np.array_equal(dcap.windows[0].pixels[:6], dark[100, 200:206])


def test_new_frame_is_seen_and_full_frame_matches(head):
    host, client, link, light, dark = head
    light2 = np.roll(light, 3, axis=1)
    frame = host.pixels.write_frame(light2, dark)
    image, sensor_frame = client.full_frame(pixel_format=PixelFormat.PACKED10)
    assert sensor_frame == frame
    assert np.array_equal(image, light2.clip(0, 1023))
    host.pixels.write_frame(light, dark)


def test_rejections_reach_the_driver_as_exceptions(head):
    host, client, *_ = head
    with pytest.raises(errors.SpanOutsideError) as info:
        client.set_windows(np.array([[1, 3, 1000, 1030]]))
    assert info.value.detail == 0
    with pytest.raises(errors.ExposureRangeError):
        client.set_exposure(5)
    with pytest.raises(errors.PixelBudgetError):
        client.set_windows(np.array([[w, r, 0, 1000] for w in range(5) for r in range(2)]))


def test_corrupt_bytes_are_counted_and_link_recovers(head):
    host, client, link, *_ = head
    before = client.telemetry()
    bad = bytearray(encode_frame(MsgType.PING, 999, b"hello"))
    bad[4] ^= 0x10
    link.send(bytes(bad) + b"\x07\x07\x07\x00" + os.urandom(40).replace(b"\x00", b"\x01") + b"\x00")
    assert client.ping(b"ok") < 1.0
    after = client.telemetry()
    assert after["crc_errors"] + after["framing_errors"] >= before["crc_errors"] + before["framing_errors"] + 2
    assert after["crc_errors"] >= before["crc_errors"] + 1


def test_ten_star_trajectory_windows_move_under_one_percent_of_a_full_frame(head):
    """Acceptance: 10 stars' trajectory windows at 5 deg/s (xing2012 optics, 10 ms) vs a full frame."""
    host, client, link, light, dark = head
    client.set_exposure(10000)
    spans, smear = wirecount.star_trajectory_windows(10, rate_dps=5.0, exposure_s=0.010, focal_mm=100.0,
                                                     pitch_um=15.0, width=W, height=H, k=6, seed=4)
    assert 5.7 < smear < 5.9  # 100 mm * 5 deg/s * 10 ms / 15 um = 5.8 px
    for fmt in (PixelFormat.PACKED10, PixelFormat.U16):
        m = wirecount.measure_capture_bytes(client, link, spans, fmt)
        assert m["n_windows"] == 10
        assert np.array_equal(m["image"], light.clip(0, 1023))
        assert m["ratio"] <= 0.01, m
