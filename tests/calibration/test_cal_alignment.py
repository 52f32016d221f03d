"""Gyro–camera alignment and time offset: exact synthetic case, and the alignment command
on the simulator's sky and gyro."""

import json

import numpy as np
import pytest
from gyrostar.attitude import dcm_to_quat, quat_propagate, quat_to_dcm
from gyrostar.calibration.align_fit import fit_alignment, rotation_angle, wahba_svd
from gyrostar.calibration.intrinsics import rotvec_dcm
from gyrostar.cli.main import main
from gyrostar.errors import ConfigError

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


def _rest_to_rest(turns_deg, rate_dps=200.0, soft_dps=20.0, soft_s=0.4, ramp_s=0.2, rest_s=1.3, fs=2000.0):
    """Body rate (n, 3) rad/s at ``fs`` Hz for slews about single axes (``turns_deg``: (k, 3),
    one non-zero entry each) from rest to rest, ``rest_s`` between: up to ``soft_dps`` in
    ``soft_s`` (gently: the frames there are measured), on to ``rate_dps`` in ``ramp_s``,
    cruise, back to rest in ``ramp_s``; returns (t, rate, at_rest)."""
    pieces, rest = [], []
    for turn in np.asarray(turns_deg, float):
        n_rest = int(rest_s * fs)
        pieces.append(np.zeros((n_rest, 3)))
        rest.append(np.ones(n_rest, bool))
        ang = float(np.abs(turn).sum())
        cruise = (ang - soft_dps * soft_s / 2 - (soft_dps + rate_dps) * ramp_s / 2 - rate_dps * ramp_s / 2) / rate_dps
        knots_t = np.cumsum([0.0, soft_s, ramp_s, cruise, ramp_s])
        t = np.arange(int(knots_t[-1] * fs)) / fs
        prof = np.interp(t, knots_t, [0.0, soft_dps, rate_dps, rate_dps, 0.0])
        pieces.append(np.radians(prof)[:, None] * np.sign(turn)[None, :])
        rest.append(np.zeros(len(t), bool))
    pieces.append(np.zeros((int(rest_s * fs), 3)))
    rest.append(np.ones(int(rest_s * fs), bool))
    w = np.concatenate(pieces)
    return np.arange(len(w)) / fs, w, np.concatenate(rest)


def test_rest_to_rest_slews_weigh_each_window_by_its_noise():
    """Fast slews between rests, the camera seen only below 20 °/s (as the loop measures):
    the windows across a slew span seconds and carry the gyro's N²·T, the others
    a few frames; frames under the hard accelerations are left out (the gentle start of each
    slew keeps the time offset observable). The fit's 1-σ of the rotation then matches its scatter over noise draws
    (as a whole: across a 150° turn the camera's noisy roll at one end lands on a
    cross-boresight axis at the other, which the per-axis noise model does not follow), and
    a turn of more than 180° (no unique rotation vector) is left out rather than bending the
    map."""
    arw, fs = 1.7277e-4, 2000.0
    turns = [[150, 0, 0], [0, 150, 0], [0, 0, 150], [-150, 0, 0], [0, -150, 0], [0, 0, -150]] * 3 + [[200, 0, 0]]
    t, w, rest = _rest_to_rest(turns, fs=fs)
    q = np.empty((len(t), 4))
    q[0] = [0, 0, 0, 1]
    for i in range(1, len(t)):
        q[i] = quat_propagate(q[i - 1], 0.5 * (w[i] + w[i - 1]), 1 / fs)
    r = rotvec_dcm(np.radians([[0.212, -0.15, 0.15]]))[0]
    tg = np.arange(0.05, t[-1] - 0.05, 1 / 400.0)
    rate = np.column_stack([np.interp(tg, t, w[:, a]) for a in range(3)]) @ r      # gyro axes
    k = np.arange(0, len(t), 20)                                                     # 100 Hz, where the loop
    k = k[np.linalg.norm(w[k], axis=1) < np.radians(20.0)]                           # measures (< 20 °/s)
    k = k[(t[k] > 0.1) & (t[k] < t[-1] - 0.1)]
    rng = np.random.default_rng(11)
    cam_sigma = np.array([5.0, 5.0, 30.0]) * ARCSEC                                  # cross-boresight, roll
    errs, fits = [], []
    for _ in range(20):
        noise = rotvec_dcm(rng.normal(0.0, 1.0, (len(k), 3)) * cam_sigma)
        qn = np.array([dcm_to_quat(nz @ quat_to_dcm(qq)) for nz, qq in zip(noise, q[k])])
        wg = rate + rng.normal(0.0, arw * np.sqrt(400.0), rate.shape)
        fit = fit_alignment(tg, wg, t[k], qn, lag=2, max_offset=4e-3, arw=arw)
        d = fit.rotation @ r.T
        errs.append(0.5 * np.array([d[2, 1] - d[1, 2], d[0, 2] - d[2, 0], d[1, 0] - d[0, 1]]))
        fits.append(fit)
    scatter = np.sqrt(np.mean(np.sum(np.square(errs), axis=1)))        # RMS of the error's norm
    sigma = np.sqrt(np.mean([np.sum(f.rotation_sigma ** 2) for f in fits]))
    limit = np.sqrt(np.sum(fits[0].rotation_sigma_gyro ** 2))
    assert scatter / ARCSEC < 12.0                               # 18 slews of 150°: a few arcsec per axis
    assert 0.7 < scatter / sigma < 1.4                           # 20 draws of 3 axes: ±10 % 1-σ on the RMS
    assert 0.5 < limit / sigma < 1.0                             # the gyro's share, the camera's the rest
    # the frames on the hard ramps (1000 °/s², under 20 °/s at the end of each slew) are out:
    # 2 per slew at 100 Hz over 0.02 s, in windows of 2 frames
    every = fit_alignment(tg, wg, t[k], qn, lag=2, max_offset=4e-3, arw=arw, max_accel=np.inf)
    assert every.n_windows - fits[-1].n_windows >= len(turns) // 2


def test_camera_epochs_all_under_hard_acceleration_are_refused_naming_it(sine_slew):
    t, q, omega = sine_slew(2000.0, 20.0)
    tg = np.arange(0.2, 19.8, 1 / 400.0)
    k = np.arange(100, len(t) - 100, 20)
    with pytest.raises(ConfigError, match="°/s² of angular acceleration"):
        fit_alignment(tg, omega(tg), t[k], q[k], lag=5, max_accel=np.radians(0.1))
