"""Per-run figures of one Monte Carlo run, from its 400 Hz outputs and the simulator's truth.

Everything here is numpy after the run. Errors follow :mod:`gyrostar.hil.analysis`
(``δθ = 2 vec(q_est ⊗ q_true⁻¹)``, body axes, x/y cross-boresight); the error of an output
is its cross-boresight magnitude ``hypot(δθx, δθy)`` in arcsec.

Pooled percentiles over many runs come from per-run histograms on a fixed logarithmic
grid (:data:`ERR_EDGES_ARCSEC`), which add exactly: the pooled p50/p95/p99 are those of all
outputs of all runs, to the grid's resolution (1.2 % in error).
"""

from __future__ import annotations

import numpy as np

from ...loop.record import FLAG_ATTITUDE_VALID, FLAG_IMAGE_UPDATE, MODE_COAST, MODE_TRACK, REASON_BLINDED, reason
from ..analysis import ARCSEC, attitude_errors

ERR_EDGES_ARCSEC = np.concatenate([[0.0], np.logspace(-2, 5, 1401)])   # 0.01″ … 1e5″, 0.5 %/bin
RATE_EDGES_DPS = np.array([0.0, 0.1, 1.0, 2.0, 5.0, 10.0, np.inf])
RATE_BINS = [f"{a:g}-{b:g}" for a, b in zip(RATE_EDGES_DPS[:-1], RATE_EDGES_DPS[1:])]
WRONG_ARCSEC = 60.0             # a wrong attitude is at least this far off (≈ 2 px) ...
WRONG_NEES = 41.45              # ... and outside its own covariance: χ²(2 dof) at P = 1e-9
LABEL_TOL_PX = 3.0              # a label off the common motion of the others by more is a wrong id


def hist_percentiles(hist: np.ndarray, qs=(50, 95, 99)) -> dict:
    """Percentiles (arcsec) of a histogram on :data:`ERR_EDGES_ARCSEC` (upper bin edge)."""
    n = float(hist.sum())
    if n == 0:
        return {f"p{q}": None for q in qs}
    c = np.cumsum(hist) / n
    return {f"p{q}": float(ERR_EDGES_ARCSEC[1 + int(np.searchsorted(c, q / 100.0))]) for q in qs}


def empty_metrics() -> dict:
    """The figures of a run that produced no outputs (a failed run's row carries these)."""
    return run_metrics(np.zeros(0, dtype=[("t", "f8")]), None, 0.0, None, {})


def run_metrics(out: np.ndarray, truth: np.ndarray, t0: float, camera, star_vec: dict) -> dict:
    """Figures of one run: ``out`` (loop records), ``truth`` (same rows), ``t0`` scenario start
    (host s), ``camera`` (:class:`gyrostar.camera.CameraModel`), ``star_vec`` id → ICRS unit vector."""
    res: dict = {"outputs": int(len(out))}
    hist = np.zeros(len(ERR_EDGES_ARCSEC) - 1, np.int64)
    rate_sq = np.zeros(len(RATE_BINS))
    rate_n = np.zeros(len(RATE_BINS), np.int64)
    res.update(err_hist=hist, rate_sq=rate_sq, rate_n=rate_n)
    if not len(out):
        res.update(err_1sigma_arcsec=np.nan, track_fraction=0.0, ttff_s=np.nan, wrong_attitude=False,
                   wrong_attitude_outputs=0, worst_arcsec=np.nan, wrong_id=False, coast_growth_arcsec_per_s=np.nan)
        return res
    err = attitude_errors(out, truth) * ARCSEC
    cross = np.hypot(err[:, 0], err[:, 1])
    valid = (out["flags"] & FLAG_ATTITUDE_VALID) != 0
    track = valid & (out["mode"] == MODE_TRACK)
    hist += np.histogram(np.minimum(cross[track], ERR_EDGES_ARCSEC[-1] * 0.999), ERR_EDGES_ARCSEC)[0]
    rate = np.linalg.norm(truth["omega"], axis=1) * (180.0 / np.pi)
    rb = np.clip(np.searchsorted(RATE_EDGES_DPS, rate[track], side="right") - 1, 0, len(RATE_BINS) - 1)
    np.add.at(rate_sq, rb, (err[track, 0] ** 2 + err[track, 1] ** 2) / 2.0)
    np.add.at(rate_n, rb, 1)
    res["err_1sigma_arcsec"] = float(np.sqrt(np.mean((err[track, 0] ** 2 + err[track, 1] ** 2) / 2))) \
        if track.any() else np.nan
    res["track_fraction"] = float(track.mean())
    first = np.flatnonzero(track)
    res["ttff_s"] = float(out["t"][first[0]] - t0) if first.size else np.nan
    # wrong attitude: a valid output far off and far outside the uncertainty it states (an
    # error its covariance admits is a degraded attitude, which the user sees, not a wrong one)
    var = np.maximum(out["cov"][:, 0, 0], 1e-30), np.maximum(out["cov"][:, 1, 1], 1e-30)
    nees = (err[:, 0] / ARCSEC) ** 2 / var[0] + (err[:, 1] / ARCSEC) ** 2 / var[1]
    bad = valid & (nees > WRONG_NEES) & (cross > WRONG_ARCSEC)
    res["wrong_attitude"] = bool(bad.any())
    res["wrong_attitude_outputs"] = int(bad.sum())
    res["worst_arcsec"] = float(cross[valid].max()) if valid.any() else np.nan
    res["wrong_id"] = bool(_wrong_labels(out, truth, camera, star_vec) > 0)
    res["coast_growth_arcsec_per_s"] = _coast_growth(out, cross, valid)
    return res


def _coast_growth(out: np.ndarray, cross: np.ndarray, valid: np.ndarray) -> float:
    """Largest error growth rate (″/s) over the run's COAST stretches of ≥ 0.25 s."""
    coast = valid & (out["mode"] == MODE_COAST)
    if not coast.any():
        return np.nan
    edges = np.flatnonzero(np.diff(np.concatenate([[0], coast.astype(np.int8), [0]])))
    worst = np.nan
    for a, b in zip(edges[::2], edges[1::2]):
        dt = out["t"][b - 1] - out["t"][a]
        if dt >= 0.25:
            g = (cross[b - 1] - cross[a]) / dt
            worst = g if not np.isfinite(worst) else max(worst, g)
    return float(worst)


def _wrong_labels(out: np.ndarray, truth: np.ndarray, camera, star_vec: dict) -> int:
    """Tracked labels whose catalog star, seen through the true attitude, is not where the
    loop tracks it, once the attitude error common to all labels is taken out (checked at
    every image update in TRACK with ≥ 3 labels).

    The loop tracks label j at ``uv_pred`` (its catalog star through the estimated attitude);
    the truth puts that star at ``uv_true``. A small attitude error moves every label alike
    (a shift plus a turn about the principal point: d = t + θ·(−y, x)); a wrong label is off
    that common motion by the distance to the star it really tracks."""
    from ...attitude import quat_to_dcm

    rows = np.flatnonzero(((out["flags"] & FLAG_IMAGE_UPDATE) != 0) & (out["mode"] == MODE_TRACK))
    wrong = 0
    for i in rows:
        n = int(out["n_stars"][i])
        ids = out["star_id"][i, :n]
        keep = ids >= 0
        if not keep.any():
            continue
        vec = np.array([star_vec[int(s)] for s in ids[keep] if int(s) in star_vec])
        if len(vec) != int(keep.sum()):
            wrong += int(keep.sum()) - len(vec)     # a label that is not a catalog star
            continue
        body = vec @ quat_to_dcm(truth["q"][i]).T
        uv, _ = camera.project(body)
        d = out["centroid_px"][i, :n][keep].astype(np.float64) - uv
        if len(d) < 3 or not np.isfinite(d).all():
            continue
        x, y = uv[:, 0] - camera.cx_px, uv[:, 1] - camera.cy_px
        a = np.zeros((2 * len(d), 3))
        a[0::2, 0] = 1.0
        a[1::2, 1] = 1.0
        a[0::2, 2] = -y
        a[1::2, 2] = x
        sol, *_ = np.linalg.lstsq(a, d.ravel(), rcond=None)
        res = (d.ravel() - a @ sol).reshape(-1, 2)
        wrong += int(np.count_nonzero(np.hypot(res[:, 0], res[:, 1]) > LABEL_TOL_PX))
    return wrong


MAX_OUTAGES = 16        # outages kept per run (longest first beyond that)


def empty_orbit_metrics() -> dict:
    """The orbit figures of a run that produced no outputs."""
    return {"availability": 0.0, "blinded_fraction": 0.0, "outages_s": [], "unrecovered_s": np.nan,
            "valid_err_hist": np.zeros(len(ERR_EDGES_ARCSEC) - 1, np.int64), "valid_wrong_outputs": 0,
            "spots_rejected_hit": 0, "frames_blinded": 0, "hits_expected": np.nan, "saa_seconds": 0.0}


def orbit_metrics(out: np.ndarray, truth: np.ndarray, t0: float, res: dict) -> dict:
    """Orbit figures of one run (``gyrostar eval loop --orbit``): ``availability`` (fraction of
    the run's outputs flagged valid), ``blinded_fraction`` (outputs whose reason code is
    ``blinded``), ``outages_s`` (each stretch after the first fix without a TRACK output, from its
    first non-TRACK output to the next TRACK one: the time to re-acquire), ``unrecovered_s`` (an
    outage still open at the end, nan: none), the error histogram of every valid output
    (TRACK and COAST), the valid outputs outside their own covariance (NEES > χ²(2) at P = 1e-9,
    whatever their size), the spots the loop rejected as hits and the frames it found blinded,
    and the hits the simulator put on the sensor (its mean rate × frames) and the seconds in the SAA."""
    m = empty_orbit_metrics()
    counters = res.get("counters") or {}
    m["spots_rejected_hit"] = int(counters.get("spots_rejected_hit", 0))
    m["frames_blinded"] = int(counters.get("frames_blinded", 0))
    tr = (res.get("environment") or {}).get("truth") or {}
    if tr.get("hits_per_frame"):
        m["hits_expected"] = float(np.mean(tr["hits_per_frame"]) * int(res.get("frames") or 0))
    m["saa_seconds"] = float(tr.get("saa_seconds") or 0.0)
    if not len(out):
        return m
    valid = (out["flags"] & FLAG_ATTITUDE_VALID) != 0
    m["availability"] = float(valid.mean())
    m["blinded_fraction"] = float(np.mean(reason(out["flags"]) == REASON_BLINDED))
    track = out["mode"] == MODE_TRACK
    first = np.flatnonzero(track)
    if first.size:
        t = out["t"]
        after = np.zeros(len(out), np.int8)
        after[first[0]:] = (~track[first[0]:]).astype(np.int8)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], after, [0]])))
        outages = []
        for a, b in zip(edges[::2], edges[1::2]):
            if b < len(out):
                outages.append(float(t[b] - t[a]))
            else:
                m["unrecovered_s"] = float(t[-1] - t[a])
        m["outages_s"] = sorted(outages, reverse=True)[:MAX_OUTAGES]
    err = attitude_errors(out, truth) * ARCSEC
    cross = np.hypot(err[:, 0], err[:, 1])
    m["valid_err_hist"] = np.histogram(np.minimum(cross[valid], ERR_EDGES_ARCSEC[-1] * 0.999), ERR_EDGES_ARCSEC)[0]
    var = np.maximum(out["cov"][:, 0, 0], 1e-30), np.maximum(out["cov"][:, 1, 1], 1e-30)
    nees = (err[:, 0] / ARCSEC) ** 2 / var[0] + (err[:, 1] / ARCSEC) ** 2 / var[1]
    m["valid_wrong_outputs"] = int(np.count_nonzero(valid & (nees > WRONG_NEES)))
    return m
