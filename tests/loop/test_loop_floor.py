"""The attitude floor against a brute-force scalar Kalman filter and hand limits."""

import math

import numpy as np
import pytest
from gyrostar.loop.floor import ARCSEC, FloorInputs, attitude_floor, pointing_bias_arcsec


def _simulated_floor(q, r, T, d, n=4000):
    """Iterate the scalar filter to steady state and average σ² over an output cycle."""
    p = r
    for _ in range(n):
        p_minus = p + q * T
        p = p_minus * r / (p_minus + r)
    t = np.linspace(d, d + T, 2001)
    return math.sqrt(np.mean(p + q * t)) / ARCSEC, math.sqrt(p) / ARCSEC


@pytest.mark.parametrize("T,d", [(0.010, 0.0025), (0.0153, 0.0116), (0.1, 0.05)])
def test_closed_form_matches_the_iterated_filter(T, d):
    arw = 0.014 * math.pi / 180 / math.sqrt(2)
    r = (0.06 * 30.94 * ARCSEC) ** 2 / 11
    f = attitude_floor(arw, r, T, d)
    out, mid = _simulated_floor(arw ** 2, r, T, d)
    assert f["floor_arcsec"] == pytest.approx(out, rel=1e-3)
    assert f["floor_mid_exposure_arcsec"] == pytest.approx(mid, rel=1e-6)


def test_no_gyro_noise_leaves_no_floor_and_no_stars_no_correction():
    assert attitude_floor(0.0, 1e-10, 0.01, 0.005)["floor_arcsec"] == 0.0
    # r → ∞: the output walks freely; the floor grows without bound with the cycle
    assert attitude_floor(1e-4, 1e6, 0.01, 0.0)["floor_arcsec"] > 1e3


def test_inputs_average_the_run():
    fi = FloorInputs()
    for k in range(11):
        fi.add(10.0 + 0.01 * k, 10.0 + 0.01 * k + 0.004, 4e-12, 8)
    s = fi.summary(1.7e-4)
    assert s["floor_inputs"]["frame_period_ms"] == pytest.approx(10.0)
    assert s["floor_inputs"]["exposure_to_output_ms_mean"] == pytest.approx(4.0)
    assert s["floor_arcsec"] == pytest.approx(attitude_floor(1.7e-4, 4e-12, 0.01, 0.004)["floor_arcsec"])


def test_lowpass_share_shortens_every_window():
    arw, r = 1.7e-4, (0.7 * ARCSEC) ** 2
    kappa = 1.0 / (2.0 * math.sqrt(2.0) * math.pi * 47.0)
    a = attitude_floor(arw, r, 0.016, 0.011, kappa)
    b = attitude_floor(arw, r, 0.016 - kappa, 0.011 - kappa / 2, 0.0)   # same windows, written out
    assert a["floor_mid_exposure_arcsec"] == pytest.approx(b["floor_mid_exposure_arcsec"], rel=1e-12)
    assert a["floor_arcsec"] < attitude_floor(arw, r, 0.016, 0.011)["floor_arcsec"]


def test_pointing_bias_is_the_attitude_turn_a_principal_point_shift_gives():
    """Stars seen through a camera model whose principal point is off by (δc, δr) px give a
    QUEST attitude turned by δr/f about camera x and δc/f about camera y (0.5 % in a
    9° field): so a principal point known to 1σ (σc, σr) is a pointing bias of σr/f, σc/f."""
    import dataclasses

    from gyrostar.attitude import quat_conj, quat_mult
    from gyrostar.camera import camera_preset
    from gyrostar.core.quest import quest

    cam = camera_preset("xing2012")
    rng = np.random.default_rng(4)
    uv = rng.uniform(50, 974, size=(30, 2))
    refs = cam.unproject(uv)                       # the true directions (identity attitude)
    for dc, dr in ((0.3, 0.0), (0.0, -0.2), (0.15, 0.25)):
        off = dataclasses.replace(cam, cx_px=cam.cx_px + dc, cy_px=cam.cy_px + dr)
        q, _ = quest(off.unproject(uv), refs, np.ones(len(uv)))
        e = quat_mult(q, quat_conj(np.array([0.0, 0.0, 0.0, 1.0])))
        angle = 2.0 * e[:3] * np.sign(e[3]) / ARCSEC
        want = pointing_bias_arcsec((abs(dc), abs(dr)), cam.focal_length_px)
        np.testing.assert_allclose(np.abs(angle[:2]), want, rtol=5e-3, atol=0.01)
    assert pointing_bias_arcsec((0.05, 0.08), 6640.0) == pytest.approx([0.08 / 6640 / ARCSEC, 0.05 / 6640 / ARCSEC])
