"""Gyro truth and error model: bias, noise level, filter, quantisation, saturation."""

import math

import numpy as np
import pytest
from gyrostar.errors import ConfigError
from gyrostar.mocks import gyro_truth as gt
from gyrostar.mocks.trajectory import Constant, Jitter

DEG = math.pi / 180


def test_xing2012_drift_and_noise():
    s = gt.simulate_gyro(Constant((0.0, 0.0, 0.0)), 20.0, "xing2012", seed=1)
    assert s.t.shape == (8000,) and s.raw.dtype == np.int16
    err_dps = np.degrees(s.omega_meas - s.omega_true)
    assert err_dps.mean(axis=0) == pytest.approx([0.02] * 3, abs=0.004)
    # white noise 0.014 deg/s/rtHz through a 47 Hz 2nd-order Butterworth: noise bandwidth
    # = (pi/2)/sin(pi/4) / 2 * 47 Hz = 1.11 * 47 Hz -> sigma = 0.014 * sqrt(52.2) = 0.101 deg/s
    assert err_dps.std(axis=0) == pytest.approx([0.101] * 3, rel=0.1)
    assert np.allclose(np.degrees(s.bias), 0.02)


def test_quantisation_and_saturation():
    p = gt.gyro_params("bmi088", range_dps=125.0, bias_sigma_dps=0.0, noise_density_dps_rthz=0.0,
                       scale_factor_sigma_ppm=0.0, misalignment_sigma_mrad=0.0, bias_instability_dph=0.0,
                       rrw_dps_per_rts=0.0)
    s = gt.simulate_gyro(Constant((math.radians(0.1), math.radians(200.0), math.radians(-300.0))), 0.2, p)
    lsb = 125.0 / 32768
    assert p.lsb_dps == lsb
    assert np.all(s.raw[20:, 0] == round(0.1 / lsb))
    assert np.all(s.raw[:, 1] == 32767) and np.all(s.raw[:, 2] == -32768)
    assert np.allclose(np.degrees(s.omega_meas[20:, 0]), round(0.1 / lsb) * lsb)


def test_filter_gain_at_47hz():
    b, a = gt.butterworth2(47.0, 1600.0)
    z = np.exp(-1j * 2 * np.pi * np.array([0.0, 47.0]) / 1600.0)
    hz = (b[0] + b[1] * z + b[2] * z**2) / (a[0] + a[1] * z + a[2] * z**2)
    assert abs(hz[0]) == pytest.approx(1.0, abs=1e-12)
    assert abs(hz[1]) == pytest.approx(1 / math.sqrt(2), abs=1e-9)
    # a 10 Hz jitter passes nearly unattenuated, a 150 Hz one is strongly cut
    p = gt.gyro_params("xing2012", noise_density_dps_rthz=0.0, bias_dps=(0.0, 0.0, 0.0), range_dps=0.0)
    prof = Jitter(Constant((0.0, 0.0, 0.0)), (DEG, DEG, 0.0), (10.0, 150.0, 1.0))
    s = gt.simulate_gyro(prof, 2.0, p)
    amp = np.degrees(s.omega_meas[400:]).std(axis=0) * math.sqrt(2)
    assert amp[0] == pytest.approx(0.99, abs=0.03)
    assert amp[1] < 0.1


def test_qian2015_drift():
    s = gt.simulate_gyro(Constant((0.0, 0.0, 0.0)), 50.0, "qian2015", seed=2)
    assert s.raw is None
    err_dph = np.degrees(s.omega_meas - s.omega_true) * 3600
    assert err_dph.mean(axis=0) == pytest.approx([1.0] * 3, abs=0.02)
    assert err_dph.std(axis=0) == pytest.approx([0.5] * 3, rel=0.03)


def test_bmi088_draws_scale_and_misalignment():
    s = gt.simulate_gyro(Constant((math.radians(50.0), 0.0, 0.0)), 1.0, "bmi088", seed=4)
    meas = np.degrees(s.omega_meas[100:].mean(axis=0) - s.bias[100:].mean(axis=0))
    expect = np.degrees((np.diag(1 + s.scale) @ s.misalignment) @ np.array([math.radians(50.0), 0, 0]))
    assert meas == pytest.approx(expect, abs=0.02)
    assert abs(s.scale).max() > 0 and not np.allclose(s.misalignment, np.eye(3))


def test_bad_parameters():
    with pytest.raises(ConfigError):
        gt.gyro_params("nope")
    with pytest.raises(ConfigError):
        gt.gyro_params("bmi088", odr_hz=300.0)
    with pytest.raises(ConfigError):
        gt.gyro_params("bmi088", nonsense=1)
    with pytest.raises(ConfigError):
        gt.simulate_gyro(Constant((0, 0, 0)), -1.0)


def test_raw_at_other_range_matches_rerun():
    prof = Constant((math.radians(3.0), math.radians(-40.0), math.radians(0.7)))
    a = gt.simulate_gyro(prof, 0.5, gt.gyro_params("bmi088", range_dps=2000.0), seed=9)
    b = gt.simulate_gyro(prof, 0.5, gt.gyro_params("bmi088", range_dps=125.0), seed=9)
    assert np.array_equal(a.raw_at_range(125.0), b.raw)
    assert np.array_equal(a.raw_at_range(2000.0), a.raw)
    with pytest.raises(ConfigError):
        a.raw_at_range(0.0)
