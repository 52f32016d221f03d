"""Motion smear: rendered centroid vs the analytic exposure-average position (noise off)."""

import math

import numpy as np
import pytest
from gyrostar.mocks.sim_preset import load_preset
from gyrostar.mocks.sky import Sky
from sim_helpers import IDENTITY_Q, one_star_catalog


def _rodrigues(axis, angle):
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def analytic_average(s0, omega, t_exp, f_px, c, n=20001):
    """Exposure-average pixel position of a star under constant body rate, by dense quadrature.

    A fixed star's body direction obeys ds/dt = -omega x s, i.e. s(t) = R(-omega t) s0.
    """
    w = np.linalg.norm(omega)
    ts = np.linspace(0.0, t_exp, n)
    pos = []
    for t in ts:
        s = s0 if w == 0 else _rodrigues(omega / w, -w * t) @ s0
        pos.append([c + f_px * s[0] / s[2], c + f_px * s[1] / s[2]])
    pos = np.array(pos)
    wts = np.full(n, 1.0)
    wts[0] = wts[-1] = 0.5
    return (wts[:, None] * pos).sum(0) / wts.sum()


@pytest.mark.parametrize("rate_dps", [0.0, 1.0, 5.0, 10.0])
def test_smeared_centroid_matches_exposure_average(rate_dps):
    preset = load_preset("xing2012")
    cam = preset.camera
    s0 = np.array([0.02, -0.015, 1.0])  # ~130 px right, ~100 px up: roll matters here
    s0 /= np.linalg.norm(s0)
    sky = Sky(one_star_catalog(s0, 4.0), preset, seed=0)
    omega = np.radians(rate_dps) * np.array([0.6, -0.5, 0.62]) / np.linalg.norm([0.6, -0.5, 0.62])
    exp = sky.expose(IDENTITY_Q, omega)
    sig = sky.signal_frame(exp)
    rows, cols = np.indices(sig.shape)
    cen = np.array([(sig * cols).sum(), (sig * rows).sum()]) / sig.sum()
    truth = analytic_average(s0, omega, preset.detector.exposure_s, cam.focal_length_px, cam.cx_px)
    print(f"smear {rate_dps:4.1f} deg/s: centroid - analytic average = {cen - truth} px")
    assert np.abs(cen - truth).max() < 0.01
    # the simulator's own truth agrees too
    assert np.abs(exp.truth.uv[0] - truth).max() < 1e-3
    # and the spot really moved: smear length = |omega| F t (cross-boresight part) in px
    if rate_dps:
        assert exp.paths.shape[1] > 1


def test_smear_length_and_direction_at_10dps():
    preset = load_preset("xing2012")
    sky = Sky(one_star_catalog([0.0, 0.0, 1.0], 4.0), preset)
    omega = np.radians([0.0, 10.0, 0.0])  # +y rate: stars move towards -x (V_x = -w_y F)
    exp = sky.expose(IDENTITY_Q, omega)
    path = exp.paths[0]
    length = path[-1, 0] - path[0, 0]
    expected = -math.radians(10.0) * 0.010 * preset.camera.focal_length_px * (1 - 1 / path.shape[0])
    assert length == pytest.approx(expected, rel=1e-3)
    assert np.allclose(path[:, 1], preset.camera.cy_px, atol=1e-6)
