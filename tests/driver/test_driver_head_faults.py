"""Head client against the emulator with link faults: corrupt, dropped and delayed bytes, disconnects."""

import time

import numpy as np
import pytest
from gyrostar.attitude import quat_from_boresight
from gyrostar.errors import DeviceError
from gyrostar.head import HeadClient, HeadTimeoutError
from gyrostar.mocks.faults import ByteFaults
from gyrostar.protocol import MsgType
from gyrostar.transport import SerialLink


@pytest.fixture(scope="module")
def sky():
    from gyrostar.catalog import load_catalog
    from gyrostar.mocks.sky import Sky

    return Sky(load_catalog("hip2", 7.5), "xing2012", seed=5)


@pytest.fixture
def rig(sky):
    from gyrostar.mocks.head_emulator import ConstantRateScene, HeadEmulator

    faults = ByteFaults(seed=11)
    em = HeadEmulator(sky, ConstantRateScene(quat_from_boresight(2.0, 0.5, 0.0), (0.0, 0.0, 0.01)), faults=faults,
                      noise=False)
    link = SerialLink(em.start())
    yield em, faults, link
    link.close()
    em.stop()


def test_corrupted_and_dropped_bytes_are_retried(rig):
    em, faults, link = rig
    head = HeadClient(link, timeout=0.1, retries=12)
    head.set_windows(np.array([[w, 500 + r, 40 * w, 40 * w + 20] for w in range(10) for r in range(5)]))
    head.capture(fetch=False)
    clean = head.window_data()
    faults.corrupt_p, faults.drop_p = 2e-4, 1e-4
    for i in range(150):
        echo = bytes((i + k) & 0xFF for k in range(200))
        head.ping(echo)  # a damaged reply is dropped (CRC/COBS) and the request sent again
    for _ in range(3):
        again = head.window_data()
        assert [w.window_id for w in again] == [w.window_id for w in clean]
        assert all(np.array_equal(a.pixels, b.pixels) for a, b in zip(again, clean))
    assert faults.injected["corrupt"] > 0 and faults.injected["drop"] > 0
    assert head.stats["retries"] > 0 and head.stats["corrupt"] + head.stats["retries"] > 0


def test_delayed_reply_times_out_then_stale_reply_is_ignored(rig):
    em, faults, link = rig
    head = HeadClient(link, timeout=0.05, retries=1)
    faults.delay_s = 0.2
    t0 = time.monotonic()
    with pytest.raises(HeadTimeoutError, match=r"no valid reply to GET_INFO after 2 attempt\(s\) of 50 ms"):
        head.get_info()
    assert 0.09 < time.monotonic() - t0 < 0.5
    faults.delay_s = 0.0
    time.sleep(0.5)  # the two late replies arrive now
    assert head.ping(b"after") < 0.5
    assert head.stats["stale"] >= 2  # late answers to the timed-out attempts were recognised by seq


def test_firmware_error_codes_map_to_exceptions(rig):
    from gyrostar.protocol import errors as perr

    em, faults, link = rig
    head = HeadClient(link)
    with pytest.raises(perr.FirmwareError) as exc:
        head.set_gain(4000)
    assert isinstance(exc.value, DeviceError) and type(exc.value).__name__ == "GainRangeError"
    assert "gain outside the firmware's limits" in str(exc.value) and "detail 4000" in str(exc.value)


def test_disconnect_is_a_device_error(rig):
    em, faults, link = rig
    head = HeadClient(link, timeout=0.1, retries=1)
    head.ping()
    em.disconnect()
    with pytest.raises(DeviceError):
        for _ in range(5):
            head.ping()


def test_emulator_renders_only_the_windows_and_honours_exposure(rig):
    em, faults, link = rig
    head = HeadClient(link, timeout=1.0)
    spans = np.array([[0, 100 + r, 100, 110] for r in range(10)])
    head.set_windows(spans)
    before = em.rendered_pixels
    for us in (1000, 40_000):
        head.set_exposure(us)
        t0 = time.monotonic()
        cap = head.capture(fetch=False)
        assert time.monotonic() - t0 >= us * 1e-6 and cap.t_end_us - cap.t_start_us >= us
    assert em.rendered_pixels - before == 2 * 100 and em.full_renders == 0
    assert head.request(MsgType.PING, b"x")[0]["echo"] == b"x"
