"""Line-rate model against hand-computed wire times (8N1 = 10 bits per byte)."""

import pytest
from gyrostar.transport.linkrate import PRESETS, preset


def test_uart_921k_wire_time_is_ten_bits_per_byte():
    p = preset("uart-921k")
    assert p.bytes_per_s == pytest.approx(92_160.0)
    # 2,800 bytes: 2800 * 10 / 921600 s + 3 character times of latency
    assert p.wire_time(2800) == pytest.approx(2800 * 10 / 921_600 + 30 / 921_600)


def test_utilisation_and_max_rate():
    p = preset("uart-3m")
    assert p.utilisation(1500, 100.0) == pytest.approx(0.5)
    assert p.max_frame_hz(1500, budget=0.8) == pytest.approx(160.0)


def test_usb_fs_is_below_its_theoretical_bulk_rate():
    p = PRESETS["usb-fs"]
    assert p.bytes_per_s < 19 * 64 * 1000  # 1.216 MB/s: 19 bulk packets per 1 ms frame
    assert p.latency_s >= 1e-3


def test_usb_hs_is_below_its_theoretical_bulk_rate_and_waits_a_microframe():
    p = PRESETS["usb-hs"]
    assert p.bytes_per_s < 13 * 512 * 8000  # 53.2 MB/s: 13 bulk packets per 125 µs microframe
    assert p.latency_s >= 125e-6
    # a streamed frame of 1.7 kB: the microframe plus 0.21 ms of bytes, against 2.9 ms on usb-fs
    assert p.wire_time(1700) == pytest.approx(125e-6 + 1700 / 8e6)
    assert p.wire_time(1700) < PRESETS["usb-fs"].wire_time(1700) / 8


def test_unknown_preset_names_the_known_ones():
    with pytest.raises(KeyError, match="uart-921k"):
        preset("uart-9600")
