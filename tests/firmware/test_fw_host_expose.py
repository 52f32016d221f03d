"""The host program's exposure hand-shake: it announces each exposure start to the sensor
and serves only the frame rendered for that exposure (firmware/port/posix/hal_posix.h)."""

import select
import threading
import time

import numpy as np
import pytest
from gyrostar.fwtools import build
from gyrostar.protocol import errors

pytest.importorskip("gyrostar.head.client")
from gyrostar.head import HeadClient  # noqa: E402
from gyrostar.mocks.firmware_host import FirmwareHost  # noqa: E402
from gyrostar.transport.serial_link import SerialLink  # noqa: E402

W, H = 64, 48
EXPOSURE_US = 5000


class SlowSensor:
    """Renders each announced exposure ``delay_s`` after its announcement (or never, when
    ``delay_s`` is None) as a flat frame of value ``100 + number``."""

    def __init__(self, host: FirmwareHost, delay_s):
        self.host, self.delay_s = host, delay_s
        self.seen, self.published = [], []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        socks = self.host.exposures
        while not self._stop.is_set():
            if not select.select([socks], [], [], 0.05)[0]:
                continue
            exp = socks.latest()
            if exp is None:
                continue
            self.seen.append((exp, time.monotonic()))
            if self.delay_s is None:
                continue
            time.sleep(self.delay_s)
            frame = self.host.pixels.write_frame(np.full((H, W), 100 + exp.number, np.uint16), exposure=exp.tag)
            self.published.append((exp, frame))
            socks.published(exp)

    def stop(self):
        self._stop.set()
        self._thread.join(timeout=2.0)


@pytest.fixture
def rig(request):
    build.build("host")
    # the frame may come up to 200 ms after the exposure ends: the sensor here is a Python
    # thread of this test, and a loaded machine may hold it up for tens of ms
    host = FirmwareHost(W, H, planes=1, expose=True, expose_wait_ms=200)
    host.start()
    host.pixels.write_frame(np.full((H, W), 7, np.uint16))     # a frame of no exposure
    sensor = SlowSensor(host, request.param)
    link = SerialLink(host.path)
    client = HeadClient(link, timeout=1.0)
    client.set_exposure(EXPOSURE_US)
    client.sync(4)
    client.set_windows(np.array([[3, 10, 20, 26]], np.int32))
    yield host, sensor, client
    sensor.stop()
    link.close()
    host.close()


@pytest.mark.parametrize("rig", [0.0, 0.015], indirect=True)
def test_capture_serves_its_own_exposure(rig):
    host, sensor, client = rig
    for k in range(1, 4):
        t0 = time.monotonic()
        cap = client.capture()
        took = time.monotonic() - t0
        exp, frame = sensor.published[-1]
        # the announcement is the exposure CAPTURE reports, and the frame read is its render
        assert (exp.number, exp.t_start_us, exp.exposure_us) == (k, cap.t_start_us, EXPOSURE_US)
        assert t0 < exp.t_start < t0 + took
        assert cap.sensor_frame == frame
        assert np.all(cap.windows[0].pixels == 100 + k)
        # a render later than the exposure end is waited for (never the previous frame)
        assert took >= max(EXPOSURE_US * 1e-6, sensor.delay_s)


@pytest.mark.parametrize("rig", [None], indirect=True)
def test_missing_frame_fails_the_capture(rig):
    host, sensor, client = rig
    t0 = time.monotonic()
    with pytest.raises(errors.SensorBusyError):
        client.capture()
    took = time.monotonic() - t0
    assert len(sensor.seen) == 1
    # it waited the exposure plus --expose-wait-ms (200 ms) for the frame before giving up
    assert took >= EXPOSURE_US * 1e-6 + 0.200
    host.stop()
    assert "1 exposures, 1 frames late, 0 announcements unsent" in host.stderr_tail
