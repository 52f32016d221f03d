"""Run figures from output records and simulator truth (numpy, after the run).

Errors follow :mod:`gyrostar.attitude`: ``δθ = 2 vec(q_est ⊗ q_true⁻¹)`` in body axes;
x and y are cross-boresight, z is roll. "1σ cross-boresight" is the per-axis RMS over
both cross-boresight axes, ``sqrt(mean((δθx² + δθy²) / 2))``, over samples in TRACK mode
with a valid attitude.
"""

from __future__ import annotations

import numpy as np

from ..loop.record import FLAG_ATTITUDE_VALID, FLAG_UPDATE_APPLIED, MODE_NAMES, MODE_TRACK

ARCSEC = 180.0 / np.pi * 3600.0


def quat_error_angles_many(q_est: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """δθ (n, 3) rad for arrays of quaternions [x, y, z, w] (vectorised attitude.quat_error_angles)."""
    p = q_true * np.array([-1.0, -1.0, -1.0, 1.0])
    q = q_est
    x = p[:, 3] * q[:, 0] + q[:, 3] * p[:, 0] - (q[:, 1] * p[:, 2] - q[:, 2] * p[:, 1])
    y = p[:, 3] * q[:, 1] + q[:, 3] * p[:, 1] - (q[:, 2] * p[:, 0] - q[:, 0] * p[:, 2])
    z = p[:, 3] * q[:, 2] + q[:, 3] * p[:, 2] - (q[:, 0] * p[:, 1] - q[:, 1] * p[:, 0])
    w = q[:, 3] * p[:, 3] - (q[:, 0] * p[:, 0] + q[:, 1] * p[:, 1] + q[:, 2] * p[:, 2])
    s = np.where(w >= 0.0, 2.0, -2.0)
    return np.stack([s * x, s * y, s * z], axis=1)


def attitude_errors(out: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """δθ (n, 3) rad of each output against the truth at the same sample."""
    return quat_error_angles_many(out["q"], truth["q"])


def tracking_mask(out: np.ndarray) -> np.ndarray:
    return (out["mode"] == MODE_TRACK) & ((out["flags"] & FLAG_ATTITUDE_VALID) != 0)


def summarize(out: np.ndarray, truth: np.ndarray | None, gyro_hz: float) -> dict:
    """The figures every run reports (see ``gyrostar run --json``)."""
    res: dict = {}
    n = len(out)
    res["outputs"] = n
    res["mode_seconds"] = {name: round(float(np.count_nonzero(out["mode"] == m)) / gyro_hz, 3)
                           for m, name in MODE_NAMES.items()}
    lat = out["latency_us"][np.isfinite(out["latency_us"])].astype(float)
    res["latency_p50_ms"] = float(np.percentile(lat, 50)) / 1e3 if lat.size else None
    res["latency_p99_ms"] = float(np.percentile(lat, 99)) / 1e3 if lat.size else None
    res["latency_max_ms"] = float(lat.max()) / 1e3 if lat.size else None
    if truth is not None and len(truth) == n and n:
        err = attitude_errors(out, truth) * ARCSEC
        m = tracking_mask(out)
        if np.any(m):
            e = err[m]
            res["attitude_error_arcsec_1sigma"] = float(np.sqrt(np.mean((e[:, 0] ** 2 + e[:, 1] ** 2) / 2)))
            res["attitude_error_arcsec_x_y_roll_rms"] = [float(v) for v in np.sqrt(np.mean(e ** 2, axis=0))]
            res["attitude_error_arcsec_cross_p99"] = float(np.percentile(np.hypot(e[:, 0], e[:, 1]), 99))
        else:
            res["attitude_error_arcsec_1sigma"] = None
        coast = out["mode"] != MODE_TRACK
        valid = (out["flags"] & FLAG_ATTITUDE_VALID) != 0
        if np.any(coast & valid):
            res["coast_error_arcsec_max"] = float(np.max(np.hypot(err[coast & valid, 0], err[coast & valid, 1])))
        b_err = (out["bias"][-1] - truth["bias"][-1]) * 180 / np.pi
        res["bias_error_dps_final"] = [float(v) for v in b_err]
        res["track_fraction"] = float(np.mean(m))
    return res


def nees_at_updates(out: np.ndarray, truth: np.ndarray) -> dict:
    """Normalised estimation error squared per cross-boresight axis (x, y), err²/cov, on the
    first output after each image update (``nees_after_update``) and on the output just
    before it (``nees_before_update``, the last prior), TRACK outputs only. A covariance
    that means what it says gives 1 on each axis."""
    m = tracking_mask(out)
    after = np.flatnonzero(m & ((out["flags"] & FLAG_UPDATE_APPLIED) != 0))
    after = after[after > 0]
    before = after - 1
    before = before[m[before]]
    res = {}
    for key, idx in (("nees_after_update", after), ("nees_before_update", before)):
        if len(idx) < 10:
            res[key] = None
            continue
        err = attitude_errors(out[idx], truth[idx])
        cov = out["cov"][idx]
        res[key] = [float(np.mean(err[:, a] ** 2 / cov[:, a, a])) for a in (0, 1)]
    return res


def mid_exposure_errors(out: np.ndarray, truth_at) -> dict:
    """The mid-exposure products against truth at their own timestamps, once per frame
    (TRACK): filtered (``t_mid``/``q_mid``/``cov_mid``) and smoothed with the next frame
    (``*_mid_s``): cross-boresight 1σ (arcsec), the same at rest, NEES per axis.
    ``truth_at(t)`` → TRUTH_DTYPE rows."""
    res: dict = {}
    track = tracking_mask(out)
    tracked_frames = np.unique(out["t_mid"][track & np.isfinite(out["t_mid"])])
    for tag, suffix in (("mid_exposure", ""), ("mid_exposure_smoothed", "_s")):
        tcol = out["t_mid" + suffix]
        m = track & np.isfinite(tcol)
        if suffix:      # the frames the filtered figure counts (a frame filtered in COAST is not)
            m &= np.isin(tcol, tracked_frames)
        if not np.any(m):
            res[f"{tag}_error_arcsec_1sigma"] = None
            continue
        rows = np.flatnonzero(m)
        tm = tcol[rows]
        rec = out[rows[np.flatnonzero(np.r_[True, tm[1:] != tm[:-1]])]]   # each frame's first output
        tr = truth_at(rec["t_mid" + suffix])
        err = quat_error_angles_many(rec["q_mid" + suffix], tr["q"])
        e = err * ARCSEC
        cov = rec["cov_mid" + suffix]
        rest = np.linalg.norm(tr["omega"], axis=1) < REST_RAD_S
        cross = (e[:, 0] ** 2 + e[:, 1] ** 2) / 2
        res[f"{tag}_error_arcsec_1sigma"] = float(np.sqrt(np.mean(cross)))
        res[f"{tag}_error_arcsec_1sigma_at_rest"] = float(np.sqrt(np.mean(cross[rest]))) if rest.any() else None
        res[f"{tag}_frames"] = int(len(rec))
        res[f"{tag}_frames_at_rest"] = int(rest.sum())
        res[f"nees_{tag}"] = [float(np.mean(err[:, a] ** 2 / cov[:, a, a])) for a in (0, 1)]
    return res


REST_RAD_S = 0.01 * np.pi / 180.0    # "at rest": true body rate below 0.01 °/s


def dcm_many(q: np.ndarray) -> np.ndarray:
    """Attitude matrices A(q) (n, 3, 3), inertial → body, of quaternions (n, 4) [x, y, z, w]:
    :func:`gyrostar.attitude.quat_to_dcm` of each."""
    from ..attitude import quat_to_dcm

    return np.array([quat_to_dcm(x) for x in q]).reshape(len(q), 3, 3)


def tracked_centroid_errors(out: np.ndarray, truth_rows, cat_ids: np.ndarray, cat_vectors: np.ndarray,
                            camera_params: np.ndarray, every: int = 10) -> np.ndarray:
    """[t, du, dv] (n, 3), px: each tracked star's output centroid minus its true position
    (its catalog direction through the truth attitude and the camera ``camera_params``), at
    every ``every``-th TRACK output with stars; ``truth_rows(t)`` gives the truth at output
    times. Stars missing from the catalog (``cat_ids``, ``cat_vectors``) or falling off the
    sensor are left out. Rows in output order, stars in slot order."""
    from ..camera import project_many

    sel = np.flatnonzero((out["n_stars"] > 0) & (out["mode"] == MODE_TRACK))[::every]
    if not len(sel):
        return np.zeros((0, 3))
    q_true = truth_rows(out["t"][sel])["q"]
    n_stars = out["n_stars"][sel].astype(np.int64)
    row, slot = np.nonzero(np.arange(out["star_id"].shape[1])[None, :] < n_stars[:, None])
    ids = out["star_id"][sel][row, slot]
    order = np.argsort(cat_ids, kind="stable")
    sorted_ids = np.asarray(cat_ids)[order]
    at = np.minimum(np.searchsorted(sorted_ids, ids), len(sorted_ids) - 1)
    known = sorted_ids[at] == ids
    row, slot, k = row[known], slot[known], order[at[known]]
    body = np.einsum("nij,nj->ni", dcm_many(q_true)[row], cat_vectors[k])
    uv, on_sensor = project_many(np.asarray(camera_params, np.float64), np.ascontiguousarray(body))
    row, slot, uv = row[on_sensor], slot[on_sensor], uv[on_sensor]
    c = out["centroid_px"][sel][row, slot].astype(np.float64)
    return np.column_stack([out["t"][sel][row], c[:, 0] - uv[:, 0], c[:, 1] - uv[:, 1]])
