"""Gyro–camera alignment and time offset: exact synthetic case, and the alignment command
on the simulator's sky and gyro."""

import json

import numpy as np
import pytest
from gyrostar.attitude import quat_propagate
from gyrostar.calibration.align_fit import fit_alignment, rotation_angle, wahba_svd
from gyrostar.calibration.intrinsics import rotvec_dcm
from gyrostar.cli.main import main

ARCSEC = np.pi / 180 / 3600


def test_wahba_svd_recovers_a_rotation():
    rng = np.random.default_rng(1)
    r = rotvec_dcm(np.array([[0.3, -1.2, 2.0]]))[0]
    a = rng.standard_normal((20, 3))
    assert rotation_angle(wahba_svd(a, a @ r.T), r) < 1e-12


def test_alignment_noiseless_recovers_rotation_offset_and_bias(sine_slew):
    t, q, omega = sine_slew(2000.0, 40.0)
    r = rotvec_dcm(np.radians([[1.0, -2.0, 30.0]]))[0]
    dt_true, bias = 3.7e-3, np.radians([0.05, -0.02, 0.01])
    tg = np.arange(0.2, 39.8, 1 / 400.0)
    wg = omega(tg + dt_true) @ r + bias  # gyro axes: R maps gyro → camera
    k = np.arange(100, len(t) - 100, 20)  # camera at 100 Hz
    fit = fit_alignment(tg, wg, t[k], q[k], lag=5)
    assert rotation_angle(fit.rotation, r) / ARCSEC < 0.5
    assert fit.time_offset == pytest.approx(dt_true, abs=2e-5)
    np.testing.assert_allclose(fit.bias, bias, atol=2e-6)


def test_gyro_scale_and_cross_axis_errors_do_not_shift_the_time_offset():
    """A BMI088-class gyro (3300 ppm scale, 3.3 mrad cross-axis) on slews with ramps of
    different signs: a rotation-only fit explains the scale error on a 4 °/s ramp by a time
    shift (ms); with the general gyro map the offset, the rotation factor of the map and the
    bias come out exact (noise-free), and the map itself is the true one."""
    fs = 2000.0
    t = np.arange(0, 60, 1 / fs)
    # triangle waves ±4 °/s, 6 s period, one phase per axis: ω and ω̇ correlated on every ramp
    peak = np.radians(4.0) * np.array([1.0, 0.6, 0.8])
    phase = np.array([0.0, 1.1, 2.3])

    def omega(tt):
        return peak * np.interp(np.mod(tt[:, None] + phase, 6.0), [0.0, 3.0, 6.0], [-1.0, 1.0, -1.0])

    w = omega(t)
    q = np.empty((len(t), 4))
    q[0] = [0, 0, 0, 1]
    for i in range(1, len(t)):
        q[i] = quat_propagate(q[i - 1], 0.5 * (w[i] + w[i - 1]), 1 / fs)
    r = rotvec_dcm(np.radians([[0.212, -0.15, 0.15]]))[0]
    s_err = np.diag(1.0 + np.array([3300e-6, -2500e-6, 1800e-6])) @ (np.eye(3) + np.array(
        [[0.0, -3.3e-3, 2.0e-3], [3.3e-3, 0.0, -1.5e-3], [-2.0e-3, 1.5e-3, 0.0]]))
    dt_true, bias = -2.775e-3, np.radians([0.02, -0.02, 0.02])
    tg = np.arange(0.2, 59.8, 1 / 400.0)
    wg = omega(tg + dt_true) @ r @ s_err.T + bias      # ω_g = S Rᵀ ω_camera + b
    k = np.arange(100, len(t) - 100, 20)               # camera at 100 Hz
    fit = fit_alignment(tg, wg, t[k], q[k], lag=5)
    m_true = r @ np.linalg.inv(s_err)
    u, _, vt = np.linalg.svd(m_true)
    assert rotation_angle(fit.rotation, u @ vt) / ARCSEC < 1.0
    assert fit.time_offset == pytest.approx(dt_true, abs=2e-5)
    np.testing.assert_allclose(fit.gyro_map, m_true, atol=1e-5)          # 10 ppm; the errors are 1500–3300
    np.testing.assert_allclose(fit.bias, bias, atol=2e-6)


def test_gyro_noise_limit_matches_the_scatter_of_the_rotation(sine_slew):
    """With a noiseless camera and a white-noise gyro of known ARW N, the rotation's scatter
    over noise draws is the fit's gyro-only 1-σ (``rotation_sigma_gyro``), and the fit's own
    1-σ (from its residuals) agrees with it: the limit a slew sets, whatever the camera."""
    arw = 1.7277e-4                                   # BMI088 N, rad/√s
    t, q, omega = sine_slew(2000.0, 30.0)
    r = rotvec_dcm(np.radians([[0.2, -0.3, 0.1]]))[0]
    tg = np.arange(0.2, 29.8, 1 / 400.0)
    k = np.arange(100, len(t) - 100, 20)               # camera at 100 Hz
    rng = np.random.default_rng(5)
    errs, fits = [], []
    for _ in range(30):
        wg = omega(tg) @ r + rng.normal(0.0, arw * np.sqrt(400.0), (len(tg), 3))
        fit = fit_alignment(tg, wg, t[k], q[k], lag=5, max_offset=4e-3, arw=arw)
        d = fit.rotation @ r.T                          # small rotation: its rotation vector
        errs.append(0.5 * np.array([d[2, 1] - d[1, 2], d[0, 2] - d[2, 0], d[1, 0] - d[0, 1]]))
        fits.append(fit)
    scatter = np.sqrt(np.mean(np.square(errs), axis=0))
    limit = fits[0].rotation_sigma_gyro
    assert np.all(limit / ARCSEC > 20.0)                # N / (ω⊥ √T): tens of arcsec here
    np.testing.assert_allclose(scatter, limit, rtol=0.4)       # 30 draws: ±13 % 1-σ on an RMS
    np.testing.assert_allclose(np.mean([f.rotation_sigma for f in fits], axis=0), limit, rtol=0.25)


def test_alignment_simulated_meets_acceptance(tmp_path, capsys):
    # 240 s of slews at 10 Hz; a gyro with 1/4 of the BMI088 noise density keeps the
    # ARW-limited rotation error at σ ≈ N/(ω⊥√T) ≈ 2.5″ per axis, so 20″ is an 8-σ bound
    # (the CLI default, BMI088 noise over 1200 s, is the field case: σ ≈ 4″ per axis).
    code = main(["calibrate", "alignment", "--simulate", "--seed", "5", "--duration", "240", "--json", "--no-plots",
                 "--report", str(tmp_path), "--set", "scale_factor_sigma_ppm=0", "--set", "misalignment_sigma_mrad=0",
                 "--set", "noise_density_dps_rthz=0.0035"])
    out = json.loads(capsys.readouterr().out)
    par = out["parameters"]
    assert par["alignment_error_arcsec"]["value"] < 20.0
    assert abs(par["time_offset_ms"]["error"]) < 0.5
    assert out["filter_delay_ms"] > 1.0  # the gyro's filter lag is part of the offset found
    assert code == 0
