"""Per-run Monte Carlo figures against hand-built output records with known truth."""

import math

import numpy as np
import pytest
from gyrostar.attitude import quat_from_boresight, quat_mult, quat_to_dcm
from gyrostar.camera import camera_preset
from gyrostar.hil.montecarlo.metrics import run_metrics
from gyrostar.loop import record as R

ARC = math.pi / 180 / 3600
CAM = camera_preset("xing2012")


def _small_rotation(ax, ay):
    """q for a small rotation by (ax, ay, 0) rad about the body axes."""
    v = np.array([ax, ay, 0.0]) / 2
    return np.array([*v, math.sqrt(1 - v @ v)])


def _records(n=400, err_arcsec=(3.0, -4.0), modes=None):
    q0 = quat_from_boresight(1.0, 0.4, 0.2)
    truth = np.zeros(n, R.TRUTH_DTYPE)
    truth["t"] = 100.0 + np.arange(n) / 400.0
    truth["q"] = q0
    out = np.zeros(n, R.OUTPUT_DTYPE)
    out["star_id"] = -1
    out["t"] = truth["t"]
    out["q"] = quat_mult(_small_rotation(err_arcsec[0] * ARC, err_arcsec[1] * ARC), q0)
    out["mode"] = R.MODE_TRACK if modes is None else modes
    out["flags"] = R.FLAG_ATTITUDE_VALID
    out["cov"][:, 0, 0] = out["cov"][:, 1, 1] = (5 * ARC) ** 2
    out["flags"][::4] |= R.FLAG_IMAGE_UPDATE
    # three catalog stars in the field, tracked where the truth puts them
    body = np.array([[0.01, 0.02, 1.0], [-0.03, 0.01, 1.0], [0.02, -0.025, 1.0]])
    body /= np.linalg.norm(body, axis=1)[:, None]
    icrs = body @ quat_to_dcm(q0)          # A maps ICRS → body: v_icrs = Aᵀ b
    uv, _ = CAM.project(body)
    out["n_stars"] = 3
    out["star_id"][:, :3] = [11, 22, 33]
    out["centroid_px"][:, :3] = uv
    return out, truth, {11: icrs[0], 22: icrs[1], 33: icrs[2]}


def test_errors_fix_time_and_no_wrong_flags_on_a_good_run():
    out, truth, vec = _records()
    out["mode"][:40] = R.MODE_ACQUIRE
    out["flags"][:40] = 0
    m = run_metrics(out, truth, 99.5, CAM, vec)
    # constant (3, -4)″ error: 1σ per axis = sqrt((9 + 16) / 2)
    assert m["err_1sigma_arcsec"] == pytest.approx(math.sqrt(12.5), rel=1e-3)
    assert m["ttff_s"] == pytest.approx(0.5 + 40 / 400.0)
    assert m["err_hist"].sum() == 360 and m["rate_n"][0] == 360
    assert not m["wrong_attitude"] and not m["wrong_id"]


def test_a_swapped_label_is_a_wrong_id():
    out, truth, vec = _records()
    out["star_id"][200:, [0, 1]] = [22, 11]      # two labels swapped from sample 200 on
    assert run_metrics(out, truth, 99.5, CAM, vec)["wrong_id"]


def test_a_far_off_track_attitude_is_wrong_but_an_honest_coast_is_not():
    out, truth, vec = _records(err_arcsec=(90.0, 0.0))
    m = run_metrics(out, truth, 99.5, CAM, vec)
    assert m["wrong_attitude"]
    # the same error while coasting with a covariance that admits it (σ 60″): not wrong
    out, truth, vec = _records(err_arcsec=(90.0, 0.0), modes=R.MODE_COAST)
    out["cov"][:, 0, 0] = out["cov"][:, 1, 1] = (60 * ARC) ** 2
    out["star_id"] = -1
    assert not run_metrics(out, truth, 99.5, CAM, vec)["wrong_attitude"]
    # ... but outside its own covariance (σ 5″) it is
    out["cov"][:, 0, 0] = out["cov"][:, 1, 1] = (5 * ARC) ** 2
    assert run_metrics(out, truth, 99.5, CAM, vec)["wrong_attitude"]


def test_an_attitude_error_moves_all_labels_alike_and_is_not_a_wrong_id():
    out, truth, vec = _records(err_arcsec=(120.0, -80.0))
    # the loop tracks each label where its estimated attitude puts it: 4 px off, all alike
    icrs = np.array([vec[11], vec[22], vec[33]])
    uv_est, _ = CAM.project(icrs @ quat_to_dcm(out["q"][0]).T)
    out["centroid_px"][:, :3] = uv_est
    m = run_metrics(out, truth, 99.5, CAM, vec)
    assert not m["wrong_id"]
    assert m["wrong_attitude"]          # 144″ off with a stated σ of 5″
