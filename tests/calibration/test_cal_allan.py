"""Allan deviation and IEEE 952 fits against noise of known coefficients, and the
gyro-static command on the simulator's gyro model."""

import json

import numpy as np
import pytest
from gyrostar.calibration.allan import allan_deviation, fit_noise_terms, markov_avar
from gyrostar.cli.main import main
from gyrostar.errors import ConfigError


def test_white_noise_gives_arw_of_sample_sigma():
    # white rate noise of σ per sample at fs: AVAR = σ²/(fs τ), so N = σ/√fs (IEEE 952)
    fs, sigma = 400.0, 0.01
    x = sigma * np.random.default_rng(3).standard_normal(int(fs * 1800))
    terms = fit_noise_terms(allan_deviation(x, fs), model="flicker")
    assert terms.arw == pytest.approx(sigma / np.sqrt(fs), rel=0.03)
    assert terms.bias_instability < 0.2 * sigma / np.sqrt(fs)  # nothing there to find


def test_white_plus_random_walk_recovers_both():
    fs, n_coef, k_coef = 100.0, 1e-3, 2e-5
    rng = np.random.default_rng(4)
    n = int(fs * 3 * 3600)
    x = n_coef * np.sqrt(fs) * rng.standard_normal(n) + np.cumsum(k_coef / np.sqrt(fs) * rng.standard_normal(n))
    terms = fit_noise_terms(allan_deviation(x, fs), model="flicker")
    assert terms.arw == pytest.approx(n_coef, rel=0.03)
    assert terms.rrw == pytest.approx(k_coef, rel=0.35)  # few long clusters: a loose but real bound


def test_markov_allan_variance_formula_matches_an_ar1_process():
    # discrete first-order Gauss–Markov (AR(1)) of σ = 1, T_c = 5 s at 20 Hz, 40,000 T_c long
    fs, tc = 20.0, 5.0
    phi = np.exp(-1.0 / (fs * tc))
    rng = np.random.default_rng(5)
    from scipy.signal import lfilter

    drive = np.sqrt(1 - phi**2) * rng.standard_normal(int(fs * tc * 40000))
    x = lfilter([1.0], [1.0, -phi], drive)
    c = allan_deviation(x, fs)
    sel = (c.tau > 1.0) & (c.tau < 200.0)
    model = np.sqrt(markov_avar(c.tau[sel], tc))
    assert np.all(np.abs(c.adev[sel] / model - 1.0) < 0.05)
    peak = c.tau[sel][np.argmax(c.adev[sel])]
    assert 1.4 * tc < peak < 2.5 * tc  # IEEE 952: peak at ≈ 1.89 T_c


def test_bad_records_are_rejected():
    with pytest.raises(ConfigError):
        allan_deviation(np.zeros(5), 400.0)
    with pytest.raises(ConfigError):
        allan_deviation(np.array([0.0, np.nan] * 100), 400.0)


def test_gyro_static_simulated_recovers_arw_and_bias_instability(tmp_path, capsys):
    # The simulator's BMI088 chain (47 Hz Butterworth, 2000 °/s quantisation) with a
    # bias wander that a 0.6 h record can measure: σ_GM 40 °/h, T_c 2 s, noise density
    # 0.005 °/s/√Hz. Sound length for a 2-σ 10 % check is ≈ 0.25 h (gyro_sim.sound_static_hours);
    # 0.6 h makes it ≈ 3 σ on each of the three independent axes.
    code = main(["calibrate", "gyro-static", "--simulate", "--seed", "7", "--hours", "0.6", "--json", "--no-plots",
                 "--report", str(tmp_path), "--set", "bias_instability_dph=40", "--set", "bias_tau_s=2",
                 "--set", "noise_density_dps_rthz=0.005"])
    out = json.loads(capsys.readouterr().out)
    par = out["parameters"]
    for name in ("arw", "bias_instability"):
        rel = np.abs(np.asarray(par[name]["value"]) / np.asarray(par[name]["truth"]) - 1.0)
        assert np.all(rel < 0.10), (name, rel)
    assert out["hours_for_2sigma_bias_check"] < 0.6 / 2.0
    bias_err = np.abs(np.asarray(par["bias_dps"]["value"]) - np.asarray(par["bias_dps"]["truth"]))
    assert np.all(bias_err < 1e-3)  # deg/s
    assert code == 0
    assert (tmp_path / "calibration.toml").exists()


def test_gyro_static_from_a_log_file_with_temperature(tmp_path, capsys):
    from gyrostar.calibration import calfile

    fs, hours = 100.0, 0.5
    rng = np.random.default_rng(9)
    n = int(fs * hours * 3600)
    t = np.arange(n) / fs
    temp = 20.0 + 10.0 * t / t[-1]
    coeff = np.array([1e-4, -2e-4, 5e-5])  # rad/s per °C
    rate = 0.002 + np.outer(temp - 25.0, coeff) + 1e-3 * rng.standard_normal((n, 3))
    path = tmp_path / "static.npz"
    np.savez(path, t=t, rate=rate, temperature=temp)
    code = main(["calibrate", "gyro-static", str(path), "--json", "--no-plots", "--report", str(tmp_path / "r")])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and "truth" not in out["parameters"]["arw"]
    tc = np.radians(out["parameters"]["bias_temp_coeff_dps_per_c"]["value"])
    np.testing.assert_allclose(tc, coeff, atol=3e-6)
    cal = calfile.load(tmp_path / "r" / "calibration.toml")
    assert cal.gyro_static.temperature_c == pytest.approx(25.0, abs=0.01)
    np.testing.assert_allclose(cal.gyro_static.bias_rps, 0.002, atol=1e-4)


def test_recording_through_the_bmi088_driver_and_emulator():
    # the --live path (driver FIFO reading, frame-count time base) on the register model
    from gyrostar.calibration.gyro_log import record
    from gyrostar.clock import SimulatedClock
    from gyrostar.gyro import Bmi088Gyro
    from gyrostar.hil.calibrate.gyro_static import analyse
    from gyrostar.mocks.bmi088_model import Bmi088GyroModel
    from gyrostar.mocks.fake_rates import ProfileRates
    from gyrostar.transport import I2CBus, I2CRegisters

    clock = SimulatedClock(10.0)
    source = ProfileRates(amp_dps=(0.0, 0.0, 0.0), bias_dps=(0.05, -0.03, 0.01), noise_dps_rt_hz=0.014, seed=3)
    model = Bmi088GyroModel(clock, source)
    gyro = Bmi088Gyro(I2CRegisters(I2CBus(model.smbus(), name="sim"), 0x68), clock=clock)
    rec = record(gyro, clock, 120.0, range_dps=125.0)
    assert rec.fs == pytest.approx(400.0, rel=1e-3)
    assert len(rec.t) == pytest.approx(48000, abs=100)
    a = analyse(rec)
    np.testing.assert_allclose(np.degrees(a["bias"]), [0.05, -0.03, 0.01], atol=2e-3)
    arw = np.array([x.arw for x in a["terms"]])
    np.testing.assert_allclose(arw, np.radians(0.014) / np.sqrt(2.0), rtol=0.1)
