"""Gyro scale and alignment fits refuse data that do not determine them (a tracker at rest):
exit 1, one line, nothing written; well-excited noisy data still fit, within their 1-σ."""

import numpy as np
import pytest
from gyrostar.attitude import quat_propagate
from gyrostar.calibration import calfile
from gyrostar.calibration.align_fit import fit_alignment
from gyrostar.calibration.scale_fit import SIGMA_MAX, NotDetermined, fit_rate_table, fit_slews
from gyrostar.cli.main import main

ARW = 1.7e-4                       # BMI088 angle random walk, rad/√s
FS = 400.0                         # gyro output rate, Hz
S_TRUE = np.array([[1.003, 0.002, 0.0], [-0.001, 0.998, 0.001], [0.0, 0.0015, 1.001]])


def _rest_slew(seconds=10.0, seed=2):
    """A tracker nearly at rest (0.01 °/s drift): BMI088-like gyro noise, 10 Hz attitudes with
    5″ noise; as ``gyrostar replay --export calib`` writes it (t, rate, t_cam, q_cam)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / FS)
    w = np.radians([0.01, -0.005, 0.007])
    rate = w + rng.normal(0.0, ARW * np.sqrt(FS), (len(t), 3))
    t_cam = np.arange(0.5, seconds - 0.5, 0.1)
    q = np.empty((len(t_cam), 4))
    for i, tc in enumerate(t_cam):
        q[i] = quat_propagate(np.array([0.0, 0.0, 0.0, 1.0]), w + rng.normal(0, 25e-6 / tc, 3), tc)
    return t, rate, t_cam, q


def test_slew_fit_refuses_a_tracker_at_rest():
    t, rate, t_cam, q = _rest_slew()
    from gyrostar.calibration.scale_fit import attitude_increments, integrate_gyro

    idx = np.arange(0, len(t_cam), 5)
    with pytest.raises(NotDetermined, match="do not determine") as err:
        fit_slews(attitude_increments(q[idx]), integrate_gyro(t, rate, t_cam[idx]), np.diff(t_cam[idx]))
    assert err.value.exit_code == 1
    with pytest.raises(NotDetermined, match="alignment: the data do not determine it"):
        fit_alignment(t, rate, t_cam, q, lag=2)


def test_slew_fit_accepts_noisy_but_exciting_slews():
    """Rates of ±0.2 rad/s about every axis, gyro noise of a BMI088: S within 4σ of the truth."""
    rng = np.random.default_rng(1)
    w_true = rng.normal(0, 0.2, (400, 3))
    dt = np.full(400, 0.5)
    g = (w_true @ S_TRUE.T) * dt[:, None] + rng.normal(0, ARW * np.sqrt(0.5), (400, 3))
    fit = fit_slews(w_true * dt[:, None], g, dt)
    assert fit.sensitivity_sigma.max() < SIGMA_MAX
    assert np.all(np.abs(fit.sensitivity - S_TRUE) < 4 * fit.sensitivity_sigma + 1e-5)


def test_rate_table_refuses_implausible_scales():
    """Runs whose means do not follow the table (a wrong table_rate, here ×2): a scale of 2."""
    table = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.0]])
    with pytest.raises(NotDetermined, match="fitted gyro scales 2, 2, 2"):
        fit_rate_table(table, 2.0 * table)
    assert fit_rate_table(table, table @ S_TRUE.T).sensitivity == pytest.approx(S_TRUE)


@pytest.mark.parametrize("target", ["gyro-scale", "alignment"])
def test_calibrate_refuses_rest_data_and_writes_nothing(tmp_path, capsys, target):
    t, rate, t_cam, q = _rest_slew()
    npz = tmp_path / "rest.npz"
    np.savez(npz, t=t, rate=rate, t_cam=t_cam, q_cam=q)
    out = tmp_path / "cal.toml"
    code = main(["calibrate", target, str(npz), "--out", str(out), "--no-plots", "--report", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip()
    assert code == 1, err
    assert len(err.splitlines()) == 1 and "do not determine" in err and "nothing written" in err
    assert not out.exists()
    calfile.write_section(out, "camera", calfile.CameraCal(6700.0, (511.0, 512.5)), source="test")
    before = out.read_bytes()
    assert main(["calibrate", target, str(npz), "--out", str(out), "--no-plots",
                 "--report", str(tmp_path / "r")]) == 1
    assert out.read_bytes() == before
