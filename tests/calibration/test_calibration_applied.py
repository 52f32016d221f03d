"""A calibration file reaching the loop: the gyro mapped into camera axes and time, the camera
model from [camera], the file identified by its hash, a real head refused without a camera."""

import hashlib
import math

import numpy as np
import pytest
from gyrostar.calibration import apply, calfile
from gyrostar.camera import camera_preset
from gyrostar.errors import ConfigError
from gyrostar.gyro import GyroSamples
from gyrostar.gyro.calibrated import CalibratedGyro
from gyrostar.hil import config as hc
from gyrostar.hil.flatsat import camera_bias, loop_params


class _ListGyro:
    """Appends fixed rows (t, rate) per read, like a FIFO holding them."""

    odr_hz = 400.0
    range_dps = 500.0

    def __init__(self, t, rate):
        self.t, self.rate = t, rate
        self.k = 0

    def read(self, out, event_time=None, event_clock=None):
        n = min(2, len(self.t) - self.k)
        out.t[out.n:out.n + n] = self.t[self.k:self.k + n]
        out.rate[out.n:out.n + n] = self.rate[self.k:self.k + n]
        out.n += n
        self.k += n
        return n


def test_calibrated_gyro_maps_axes_bias_and_time():
    rng = np.random.default_rng(3)
    t = np.arange(5) * 0.0025
    w = rng.normal(size=(5, 3))
    c = math.cos(0.01)
    s = math.sin(0.01)
    m = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.diag([1.001, 0.999, 1.002])
    b = np.array([1e-3, -2e-3, 5e-4])
    g = CalibratedGyro(_ListGyro(t, w), m, b, 0.002)
    out = GyroSamples(16)
    out.n = 1                                  # rows already there stay untouched
    out.rate[0] = [9.0, 9.0, 9.0]
    while g.read(out):
        pass
    assert out.n == 6 and np.all(out.rate[0] == 9.0)
    for i in range(5):
        expect = m @ (w[i] - b)                # hand-computed ω_camera = M (ω_meas − b)
        assert np.allclose(out.rate[1 + i], expect, rtol=0, atol=1e-15)
        assert out.t[1 + i] == pytest.approx(t[i] + 0.002, abs=1e-15)


def test_run_calibration_camera_gyro_and_hash(tmp_path):
    path = tmp_path / "cal.toml"
    nom = camera_preset("xing2012")
    calfile.write_section(path, "camera", calfile.CameraCal(6640.0, (515.5, 508.5), k1=0.3,
                                                            principal_point_sigma_px=(0.05, 0.08)), "test")
    calfile.write_section(path, "alignment", calfile.AlignmentCal((0.0, 0.0, math.sin(0.0025), math.cos(0.0025)),
                                                                  0.002), "test")
    rc = apply.load_for_run(path)
    assert rc.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()
    assert str(path) in rc.describe() and rc.sha256[:16] in rc.describe()
    cam = rc.camera(nom, real_head=False)
    assert (cam.focal_length_px, cam.cx_px, cam.cy_px, cam.k1) == pytest.approx((6640.0, 515.5, 508.5, 0.3))
    real = rc.camera(None, real_head=True)         # a real head: from the file alone
    assert real.focal_length_px == pytest.approx(6640.0) and (real.width_px, real.height_px) == (1024, 1024)
    m, b, dt = rc.gyro_map()
    assert dt == 0.002 and np.allclose(b, 0.0)
    # A(q) of gyrostar.attitude maps gyro-frame components to camera-frame ones (passive form)
    assert np.allclose(m, [[math.cos(0.005), math.sin(0.005), 0], [-math.sin(0.005), math.cos(0.005), 0], [0, 0, 1]])
    again = apply.from_meta(rc.meta())             # replay rebuilds it from the log's META text
    assert again.sha256 == rc.sha256 and again.cal == rc.cal
    # the principal point's σ reaches the loop as its pointing bias (run and replay alike)
    assert camera_bias(rc) == camera_bias(again) == (0.05, 0.08)
    assert camera_bias(apply.load_for_run(None)) == (0.0, 0.0)
    cfg = hc.load_flatsat(None)
    assert loop_params(cfg, camera_bias_px=camera_bias(rc)).camera_bias_px == (0.05, 0.08)
    assert loop_params(cfg).camera_bias_px == (0.0, 0.0)


def test_real_head_without_camera_table_names_the_key(tmp_path):
    with pytest.raises(ConfigError, match="camera.focal_length_px"):
        apply.load_for_run(None).camera(None, real_head=True)
    path = tmp_path / "cal.toml"
    calfile.write_section(path, "alignment", calfile.AlignmentCal((0.0, 0.0, 0.0, 1.0), 0.0), "test")
    with pytest.raises(ConfigError, match="camera.focal_length_px"):
        apply.load_for_run(path).camera(None, real_head=True)
    with pytest.raises(ConfigError, match="does not exist"):
        apply.load_for_run(tmp_path / "nope.toml")


def test_hot_pixels_repaired_in_window_readouts_and_frames():
    from types import SimpleNamespace

    from gyrostar.calibration.hot_pixels import HotPixelRepair, repair_frame

    spans = np.array([[0, 10, 4, 9], [0, 11, 4, 9], [1, 30, 0, 3]], np.int32)
    vals = np.array([10, 11, 900, 13, 14,      # row 10, cols 4..8: col 6 hot
                     20, 21, 22, 23, 800,      # row 11: col 8 hot (span edge: one neighbour)
                     700, 31, 32], np.uint16)  # row 30, cols 0..2: col 0 hot
    hot = np.array([[6, 10], [8, 11], [0, 30], [500, 500]])

    class Port:
        step_gate = None

        def __init__(self):
            self.res = None

        def submit_windows(self, s):
            self.res = SimpleNamespace(kind="windows", values=vals.copy(), error=None)

        def submit_frame(self, post=None):
            self.res = SimpleNamespace(kind="frame", measured=post(frame))

        def poll(self):
            return self.res

    port = Port()
    head = HotPixelRepair(port, hot, 1024)
    head.step_gate = "gate"                       # attributes the runner sets reach the port
    assert port.step_gate == "gate"
    head.submit_windows(spans)
    got = head.poll().values
    expect = vals.copy()
    expect[2] = (11 + 13) // 2
    expect[9] = 23
    expect[10] = 31
    assert np.array_equal(got, expect) and head.repaired == 3
    frame = np.full((600, 1024), 50, np.uint16)
    frame[500, 500] = 4000
    head.submit_frame(lambda img: img[500, 500])
    assert head.poll().measured == 50
    assert repair_frame(frame, np.array([500]), np.array([500]))[500, 500] == 50


def test_hot_pixels_repaired_in_streamed_frames_before_measuring():
    """The streaming head's ``submit_windows(spans, frame, post)``: ``post`` sees the pixels
    with the hot ones replaced (the head port measures on its worker, no poll-time hook)."""
    from gyrostar.calibration.hot_pixels import HotPixelRepair

    spans = np.array([[0, 10, 4, 9]], np.int32)
    vals = np.array([10, 11, 900, 13, 14], np.uint16)      # col 6 of row 10 hot

    class StreamingPort:
        def __init__(self):
            self.sent = []

        def submit_windows(self, s, frame=0, post=None):
            self.sent.append(frame)
            return post(vals.copy()) if post is not None else frame

    port = StreamingPort()
    head = HotPixelRepair(port, np.array([[6, 10]]), 1024)
    seen = head.submit_windows(spans, 7, lambda v: v.copy())
    assert port.sent == [7]
    assert list(seen) == [10, 11, 12, 13, 14] and head.repaired == 1
    assert head.submit_windows(spans, 8) == 8 and port.sent == [7, 8]     # no post: passed through


def test_hot_pixels_repaired_in_the_heads_spot_windows():
    """The default lost-in-space image is the head's FIND_SPOTS result, not a frame: its spot
    windows are repaired like any readout, so a spot the head found on a hot pixel has no
    signal left (the spot finder leaves it out) and a star's centroid is not pulled by one."""
    from types import SimpleNamespace

    from gyrostar.calibration.hot_pixels import HotPixelRepair
    from gyrostar.head import Capture, SpotCapture
    from gyrostar.head.client import spot_spans
    from gyrostar.loop.acquire import spots_from_windows
    from gyrostar.protocol.payloads import WindowPixels

    bg, box = 100.0, 7
    star = (200, 300)                    # (row, column) of a star at a pixel centre
    spots = np.array([[200, 300, 5000], [40, 700, 3000]])      # the star, then a hot pixel the head took
    spans = spot_spans(spots, box, 1024, 1024)
    rows, cols = np.mgrid[0:1024, 0:1024][:, :, :]
    image = np.full((1024, 1024), bg)
    image += 4000.0 * np.exp(-((rows - star[0]) ** 2 + (cols - star[1]) ** 2) / (2 * 1.2 ** 2))
    image[40, 700] += 3000.0             # hot, alone in its window
    image[201, 302] += 2500.0            # hot, in the star's window (one off the centre)
    windows = []
    for wid in (1, 2):
        px = np.concatenate([image[r, c0:c1] for _, r, c0, c1 in spans[spans[:, 0] == wid]])
        px = np.rint(px).astype(np.uint16)
        windows.append(WindowPixels(wid, int(px.sum()), px))
    cap = Capture(1, 1, 0, 10_000, 10_000, 16, 2, int(sum(len(w.pixels) for w in windows)), 1, 0.005, windows)
    sc = SpotCapture(cap, spots, box, spans, bg, 3.0, bg + 18.0, 2)

    def lost_in_space(s):                # what the loop's lost-in-space post does with a spot list
        values = np.concatenate([w.pixels for w in s.capture.windows])
        return spots_from_windows(s.spans, values, s.background_dn, s.sigma_dn, 40)

    class Port:
        def submit_frame(self, post=None):
            self.res = SimpleNamespace(kind="frame", measured=post(sc))

        def poll(self):
            return self.res

    raw = lost_in_space(sc)
    assert len(raw) == 2 and abs(raw[0, 0] - star[1]) > 0.1      # unrepaired: the hot pixel is a "star"
    head = HotPixelRepair(Port(), np.array([[700, 40], [302, 201], [5, 5]]), 1024)
    head.submit_frame(lost_in_space)
    found = head.poll().measured
    assert len(found) == 1                                         # the hot pixel's spot is gone
    assert abs(found[0, 0] - star[1]) < 0.02 and abs(found[0, 1] - star[0]) < 0.02


def test_camera_sigma_is_the_largest_and_never_zero_with_a_camera_table(tmp_path):
    """The loop's camera-model σ: the largest of the [camera] fit residual, loop.camera_sigma_px
    and the scenario's (HARDWARE.md step 5's ``camera_sigma_px = 2.0`` was ignored for a table's
    residual_rms_px of 0.0: a star σ of 0.27″ instead of 17.9″)."""
    from gyrostar.hil.flatsat import camera_sigma

    def cal(residual):
        path = tmp_path / f"cal_{residual}.toml"
        calfile.write_section(path, "camera", calfile.CameraCal(6666.7, (511.5, 511.5), residual_rms_px=residual),
                              "test")
        return apply.load_for_run(path)

    cfg, scen = hc.load_flatsat(None), hc.load_scenario("demo")
    assert camera_sigma(cfg, scen, apply.load_for_run(None)) == 0.0       # the simulator's exact model
    with pytest.raises(ConfigError, match=r"camera\.residual_rms_px = 0.*loop\.camera_sigma_px"):
        camera_sigma(cfg, scen, cal(0.0))                                  # nominal table, no σ: refused
    cfg.loop.camera_sigma_px = 2.0
    assert camera_sigma(cfg, scen, cal(0.0)) == 2.0                        # step 5 takes effect
    assert camera_sigma(cfg, scen, cal(0.02)) == 2.0                       # raising it always does
    assert camera_sigma(cfg, scen, cal(3.5)) == 3.5                        # never below the fit's residual
    scen.camera_sigma_px = 2.5
    assert camera_sigma(cfg, scen, cal(0.02)) == 2.5
    assert camera_sigma(cfg, scen, apply.load_for_run(None)) == 2.5
