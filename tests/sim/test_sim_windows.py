"""Full-frame and windowed (row-span) renders give identical pixels; span validation."""

import math

import numpy as np
import pytest
from gyrostar.attitude import quat_from_boresight
from gyrostar.catalog import load_catalog
from gyrostar.errors import ConfigError
from gyrostar.mocks.sky import Sky


@pytest.fixture(scope="module")
def sky():
    return Sky(load_catalog("hip2", 7.0), "xing2012", seed=11)


def _spans_around(uv, half=7, w=1024, h=1024):
    spans = []
    for wid, (u, v) in enumerate(uv):
        r0, c0 = int(round(v)) - half, int(round(u)) - half
        for r in range(max(r0, 0), min(r0 + 2 * half + 1, h)):
            a, b = max(c0, 0), min(c0 + 2 * half + 1, w)
            if b > a:
                spans.append((wid, r, a, b))
    return np.array(spans, dtype=np.int32)


@pytest.mark.parametrize("rate_dps,frame", [((0, 0, 0), 0), ((3.0, -2.0, 1.0), 5), ((10.0, 0.0, 4.0), 123)])
def test_windows_identical_to_full_frame(sky, rate_dps, frame):
    q = quat_from_boresight(math.radians(83.8), math.radians(-5.4), 0.4)
    omega = np.radians(rate_dps)
    img, truth = sky.render_frame(q, omega, frame=frame)
    uv = truth.uv[truth.in_field][:10]
    assert len(uv) >= 5
    spans = _spans_around(uv)
    # add a span crossing the sensor edge region and a span far from stars
    spans = np.vstack([spans, np.array([[99, 0, 0, 40], [99, 1023, 1000, 1024]], dtype=np.int32)])
    pix, truth2 = sky.render_windows(spans, q, omega, frame=frame)
    ref = np.concatenate([img[r, a:b] for _, r, a, b in spans])
    assert pix.dtype == np.uint16 and pix.shape == ref.shape
    assert np.array_equal(pix, ref)
    assert np.array_equal(truth.uv, truth2.uv)
    # the windows hold star light (well above the background level)
    assert pix.max() > 200
    # the emulators' pixels-only path reads the same pixels
    assert np.array_equal(sky.window_pixels(spans, q, omega, frame=frame), ref)


def test_window_pixels_with_glints_and_segment_rates_equal_the_full_frame():
    """Piecewise-constant rates over 8 segments (the emulated head's input) and stray-light
    glints: the pixels-only path reads the full frame's pixels exactly."""
    glints = np.array([[300.0, 700.0, 3.0], [812.4, 95.6, 5.5]])
    sky = Sky(load_catalog("hip2", 7.0), "xing2012", seed=3, false_spots=glints)
    q = quat_from_boresight(math.radians(210.0), math.radians(35.0), -1.1)
    omega = np.radians([[2.0 + 0.3 * k, -1.5, 0.7 * k] for k in range(8)])
    img, truth = sky.render_frame(q, omega, frame=77)
    uv = np.vstack([truth.uv[truth.in_field][:8], glints[:, :2]])
    spans = _spans_around(uv, half=6)
    ref = np.concatenate([img[r, a:b] for _, r, a, b in spans])
    pix = sky.window_pixels(spans, q, omega, frame=77)
    assert np.array_equal(pix, ref)
    assert pix.max() > 500          # the glints' windows are lit


def test_noise_depends_on_frame_and_seed(sky):
    q = quat_from_boresight(1.0, 0.3, 0.0)
    a, _ = sky.render_frame(q, np.zeros(3), frame=1)
    b, _ = sky.render_frame(q, np.zeros(3), frame=2)
    c, _ = sky.render_frame(q, np.zeros(3), frame=1)
    assert np.array_equal(a, c)
    assert np.mean(a != b) > 0.5
    other = Sky(sky.catalog, sky.preset, seed=12)
    d, _ = other.render_frame(q, np.zeros(3), frame=1)
    assert np.mean(a != d) > 0.5


def test_quats_input_equals_rates(sky):
    from gyrostar.mocks.trajectory import Constant, integrate

    q = quat_from_boresight(2.0, -0.5, 0.1)
    omega = np.radians([2.0, 1.0, -3.0])
    qs = integrate(q, Constant(tuple(omega)), np.linspace(0, 0.010, 5))
    e1 = sky.expose(q, omega)
    e2 = sky.expose(q, quats=qs)
    assert np.allclose(e1.paths, e2.paths, atol=1e-9)


def test_bad_spans_rejected(sky):
    q = quat_from_boresight(0.0, 0.0, 0.0)
    for bad in ([[0, 5, 10, 10]], [[0, 1024, 0, 5]], [[0, 5, -1, 5]], [[1, 5, 0, 4], [0, 6, 0, 4]],
                np.zeros((2, 3), dtype=np.int32), [[0.5, 1, 2, 3]]):
        with pytest.raises(ConfigError):
            sky.render_windows(np.asarray(bad), q, np.zeros(3))
        with pytest.raises(ConfigError):
            sky.window_pixels(np.asarray(bad), q, np.zeros(3))
    with pytest.raises(ConfigError):
        sky.render_frame(np.array([0, 0, 0, 2.0]), np.zeros(3))


def test_threads_sharing_one_sky_get_serial_results(sky):
    from concurrent.futures import ThreadPoolExecutor

    q = quat_from_boresight(math.radians(83.8), math.radians(-5.4), 0.4)
    omega = np.radians([2.0, 1.0, 0.5])
    serial = [sky.render_frame(q, omega, frame=k)[0] for k in range(4)]
    with ThreadPoolExecutor(4) as pool:
        threaded = list(pool.map(lambda k: sky.render_frame(q, omega, frame=k)[0], range(4)))
    assert all(np.array_equal(a, b) for a, b in zip(serial, threaded))


def test_near_field_selection_matches_brute_force(sky):
    rng = np.random.default_rng(4)
    bore = np.array([0.3, -0.2, 0.93])
    bore /= np.linalg.norm(bore)
    for step in range(30):  # a slow drift (tracking), then a jump (re-selection)
        if step == 20:
            bore = -bore
        bore = bore + rng.normal(0, 0.003, 3)
        bore /= np.linalg.norm(bore)
        reach = math.radians(6.5)
        got = sky.near(bore, reach)
        ref = np.flatnonzero(sky.catalog.vectors @ bore > math.cos(reach))
        assert np.array_equal(got, ref)
