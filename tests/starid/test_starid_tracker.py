"""Tracker state machine: acquisition by Pyramid, tracking by extended grid, fallback."""

import math

import numpy as np
import pytest
from gyrostar.attitude import quat_propagate, random_attitudes
from gyrostar.camera import camera_preset
from gyrostar.catalog import load_catalog
from gyrostar.errors import ConfigError
from gyrostar.mocks.star_lists import Sky, score
from gyrostar.starid.extended import ExtendedIdentifier
from gyrostar.starid.index import load_index
from gyrostar.starid.pyramid import Pyramid
from gyrostar.starid.tracker import Mode, StarTracker


@pytest.fixture(scope="module")
def parts():
    cam = camera_preset("qian2015")
    pyr = Pyramid(load_index("hip2", 7.5, 5.67, 0), cam, sigma_px=0.5)
    ext = ExtendedIdentifier(load_index("hip2", 8.0, 5.67, 0), cam, sigma_px=0.5, mag_max=7.5)
    return cam, pyr, ext, Sky(load_catalog("hip2", 8.5))


def test_acquire_track_and_recover_from_a_jump(parts):
    cam, pyr, ext, sky = parts
    rng = np.random.default_rng(3)
    # start in a rich field so that Pyramid acquires
    for q in random_attitudes(50, rng):
        if len(sky.observe(cam, q, 7.5, 0.0, 0.0, 0, rng).uv) >= 12:
            break
    tr = StarTracker(pyr, ext)
    omega = np.radians([0.3, -0.2, 0.1])
    dt = 0.5
    for k in range(12):
        if k == 8:  # an unmodelled 3° jump: tracking must fail over to Pyramid
            q = quat_propagate(q, np.radians([3.0, 0.0, 0.0]), 1.0)
        f = sky.observe(cam, q, 7.5, 0.5, 0.1, 0, rng)
        gyro = omega + math.radians(1.0 / 3600.0)
        r = tr.update(f.uv, gyro, dt)
        c, w = score(r.ids, f.truth, f.alt)
        assert w == 0
        if r.ok:
            assert c >= 2 and tr.mode is Mode.TRACKING
        q = quat_propagate(q, omega, dt)
    assert tr.counts["acquired"] >= 1 and tr.counts["tracked"] >= 6
    assert tr.counts["fallback"] >= 1  # the jump


def test_bad_gyro_input_and_lost_state(parts):
    cam, pyr, ext, sky = parts
    tr = StarTracker(pyr, ext)
    with pytest.raises(ConfigError):
        tr.predict(np.zeros(3), 1.0)  # no attitude yet
    tr.mode, tr.q = Mode.TRACKING, np.array([0.0, 0.0, 0.0, 1.0])
    with pytest.raises(ConfigError):
        tr.predict(np.array([np.nan, 0, 0]), 1.0)
    with pytest.raises(ConfigError):
        tr.predict(dq=np.array([0.0, 0.0, 1.0]))
    r = tr.update(np.array([[10.0, 10.0]]), np.zeros(3), 1.0)
    assert not r.ok and tr.mode is Mode.LOST and tr.q is None
