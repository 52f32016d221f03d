"""Tracked stars' centroid errors against the truth: the offsets put into the outputs come back."""

import numpy as np
from gyrostar.attitude import quat_to_dcm
from gyrostar.camera import camera_preset, project_point
from gyrostar.hil.analysis import dcm_many, tracked_centroid_errors
from gyrostar.loop import record as R


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def test_offsets_come_back_in_order_and_unknown_or_off_sensor_stars_are_left_out():
    cam = camera_preset("qian2015")
    params = cam.as_array()
    q_true = _unit([0.01, -0.02, 0.003, 1.0])
    a = quat_to_dcm(q_true)
    # catalog directions (inertial) of stars at chosen body directions: 3 on the 512 px sensor, 1 behind it
    body = np.array([_unit([0.01, 0.02, 1.0]), _unit([-0.03, 0.01, 1.0]), _unit([0.0, -0.015, 1.0]),
                     _unit([0.0, 0.0, -1.0])])
    cat_ids = np.array([900, 17, 4242, 55], np.int64)         # not sorted: the look-up sorts
    cat_vectors = body @ a                                    # A·v = body  ⇔  v = Aᵀ·body
    uv_true = np.array([project_point(params, b)[:2] for b in body])

    out = R.empty(3)
    out["t"] = [1.0, 2.0, 3.0]
    out["mode"] = [R.MODE_TRACK, R.MODE_ACQUIRE, R.MODE_TRACK]
    out["n_stars"] = [4, 2, 2]
    offsets = np.array([[0.25, -0.5], [1.0, 0.125], [-0.75, 0.0625]])
    # row 0: stars 900, 17, 55 (behind the camera), 31337 (not in the catalog); row 2: 4242, 900
    out["star_id"][0, :4] = [900, 17, 55, 31337]
    out["centroid_px"][0, 0] = uv_true[0] + offsets[0]
    out["centroid_px"][0, 1] = uv_true[1] + offsets[1]
    out["centroid_px"][0, 2:4] = 100.0
    out["star_id"][1, :2] = [900, 17]                         # ACQUIRE: not counted
    out["star_id"][2, :2] = [4242, 900]
    out["centroid_px"][2, 0] = uv_true[2] + offsets[2]
    out["centroid_px"][2, 1] = uv_true[0] - offsets[0]
    out["star_id"][2, 2] = 17                                 # beyond n_stars: not counted

    def truth_rows(t):
        rows = np.zeros(len(t), R.TRUTH_DTYPE)
        rows["t"] = t
        rows["q"] = q_true
        return rows

    err = tracked_centroid_errors(out, truth_rows, cat_ids, cat_vectors, params, every=1)
    want = np.array([[1.0, *offsets[0]], [1.0, *offsets[1]], [3.0, *offsets[2]], [3.0, *(-offsets[0])]])
    # centroids are float32 in the record: exact to its rounding of ~500 px values
    np.testing.assert_allclose(err, want, atol=1e-4, rtol=0)
    assert len(tracked_centroid_errors(out, truth_rows, cat_ids, cat_vectors, params, every=2)) == 2  # row 0 only
    out["mode"] = R.MODE_COAST
    assert tracked_centroid_errors(out, truth_rows, cat_ids, cat_vectors, params).shape == (0, 3)


def test_dcm_many_is_quat_to_dcm_for_each():
    q = np.random.default_rng(4).normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    assert np.array_equal(dcm_many(q), np.array([quat_to_dcm(x) for x in q]))
