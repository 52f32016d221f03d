"""Star-identification safety: false stars and magnitude noise never yield a wrong attitude.

``python -m gyrostar.hil.reliability.starid_safety [--trials 10000] [--seed 1]``. Each trial
draws a random attitude, 0–5 false stars (uniform over the sensor, as bright as real ones)
and noisy magnitudes and centroids (:class:`gyrostar.mocks.star_lists.Sky`), and runs the image
through :class:`gyrostar.starid.tracker.StarTracker` — Pyramid lost-in-space and the
extended-grid tracking identifier, each verified by QUEST residuals: even trials start
LOST (Pyramid), odd trials are TRACKING from the previous image 0.1–1 s earlier with a
gyro-propagated attitude (rate ≤ 1 °/s, drift 1 °/h), falling back to Pyramid. The
measured magnitudes go with the centroids, so both identifiers' per-star checks
(:class:`gyrostar.starid.star_check.StarCheck`, σ_m = the magnitude noise) test position
and brightness of every label.

An attitude output (``ok``) is *wrong* when any star it identified is not the true one
(scored against the simulator's truth, blends counted right for either member), or its
boresight points more than ``WRONG_BORESIGHT_PX`` pixels (≈ 280″ on the qian2015 camera)
from the true boresight. Roll about the boresight is reported, not judged: with a 4° field
its noise from 0.5 px centroids is hundreds of arcsec even for a right identification.
Also reported: identification rate, error percentiles. Exit status 1 if any wrong
attitude was output.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time

import numpy as np

WRONG_BORESIGHT_PX = 10.0
MAX_FALSE = 5


def _with_checks(sp: dict, se: dict, cfg) -> tuple:
    """The two identifiers with per-star checks that know the magnitude noise."""
    from ...starid.star_check import StarCheck

    f = sp["camera"].focal_length_px
    pyr, ext = sp["ident"], se["ident"]
    pyr = dataclasses.replace(pyr, check=StarCheck(pyr.sigma_px, f, cfg.total_mag_noise, cfg.mag_limit, min_stars=3))
    ext = dataclasses.replace(ext, check=StarCheck(ext.sigma_px, f, cfg.total_mag_noise, cfg.mag_limit, min_stars=2))
    return pyr, ext


def _configs(mag_noise: float, pos_noise: float):
    from ..evaluation.eval_starid import TrialConfig

    base = dict(preset="qian2015", catalog="hip2", mag_limit=7.5, pos_noise_px=pos_noise, mag_noise=mag_noise)
    return TrialConfig(method="pyramid", **base), TrialConfig(method="extended-grid", **base)


def boresight_and_roll_arcsec(q_est, q_true) -> tuple[float, float]:
    """(angle between estimated and true boresights, roll error about it), arcsec."""
    from ...attitude import quat_error_angles

    e = quat_error_angles(np.asarray(q_est, float), np.asarray(q_true, float)) * 180.0 / math.pi * 3600.0
    return float(math.hypot(e[0], e[1])), float(abs(e[2]))


def run(trials: int = 10000, seed: int = 1, mag_noise: float = 0.3, pos_noise: float = 0.5) -> dict:
    from ...attitude import quat_propagate, random_attitudes
    from ...mocks.star_lists import score
    from ...starid.tracker import Mode, StarTracker
    from ..evaluation.eval_starid import setup

    cfg_p, cfg_e = _configs(mag_noise, pos_noise)
    sp, se = setup(cfg_p), setup(cfg_e)
    cam, sky = sp["camera"], sp["sky"]
    px_arcsec = 180.0 / math.pi * 3600.0 / cam.focal_length_px
    pyr, ext = _with_checks(sp, se, cfg_p)
    tracker = StarTracker(lost_in_space=pyr, tracking=ext)
    rng = np.random.default_rng(seed)
    pn, mn = cfg_p.total_pos_noise, cfg_p.total_mag_noise
    n_out = n_wrong = n_wrong_ids = 0
    by_false = {k: {"trials": 0, "outputs": 0, "wrong": 0} for k in range(MAX_FALSE + 1)}
    errs = []
    worst = None
    wrong_list: list[dict] = []
    t0 = time.perf_counter()
    for i, q in enumerate(random_attitudes(trials, rng)):
        n_false = int(rng.integers(0, MAX_FALSE + 1))
        tracking = i % 2 == 1
        omega = dt = None
        if tracking:
            # the previous image (no false stars) gives the tracker its attitude; the gyro carries it
            axis = rng.normal(size=3)
            omega = axis / np.linalg.norm(axis) * math.radians(rng.uniform(0.0, 1.0))
            dt = float(rng.uniform(0.1, 1.0))
            tracker.reset()
            prev = sky.observe(cam, q, cfg_p.mag_limit, pn, mn, 0, rng)
            tracker.update(prev.uv, mag=prev.mag)
            q_true = quat_propagate(q, omega, dt)
            drift = rng.normal(0.0, math.radians(1.0 / 3600.0), 3)
            frame = sky.observe(cam, q_true, cfg_p.mag_limit, pn, mn, n_false, rng)
            if tracker.mode is Mode.TRACKING:
                r = tracker.update(frame.uv, omega=omega + drift, dt=dt, mag=frame.mag)
            else:
                r = tracker.update(frame.uv, mag=frame.mag)
        else:
            tracker.reset()
            q_true = q
            frame = sky.observe(cam, q_true, cfg_p.mag_limit, pn, mn, n_false, rng)
            r = tracker.update(frame.uv, mag=frame.mag)
        by_false[n_false]["trials"] += 1
        if not r.ok:
            continue
        n_out += 1
        by_false[n_false]["outputs"] += 1
        err, roll = boresight_and_roll_arcsec(r.q, q_true)
        errs.append((err, roll))
        _, w = score(r.ids, frame.truth, frame.alt)
        n_wrong_ids += int(w > 0)
        if w > 0 or err > WRONG_BORESIGHT_PX * px_arcsec:
            n_wrong += 1
            by_false[n_false]["wrong"] += 1
            if len(wrong_list) < 50:
                c, _ = score(r.ids, frame.truth, frame.alt)
                wrong_list.append({"trial": i, "method": r.method, "tracking": tracking, "n_false": n_false,
                                   "identified": r.n_identified, "right_ids": int(c), "wrong_ids": int(w),
                                   "centroids": int(len(frame.uv)), "boresight_err_arcsec": round(err, 1),
                                   "status": r.status})
            if worst is None or err > worst["boresight_err_arcsec"]:
                worst = {"trial": i, "boresight_err_arcsec": err, "wrong_ids": int(w), "method": r.method,
                         "n_false": n_false}
    errs = np.asarray(errs).reshape(-1, 2)
    return {
        "trials": trials, "seed": seed, "mag_noise": mag_noise, "pos_noise_px": pos_noise,
        "camera": cfg_p.preset, "catalog": cfg_p.catalog, "mag_limit": cfg_p.mag_limit,
        "false_stars": f"0–{MAX_FALSE} (uniform)",
        "wrong_boresight_threshold_arcsec": WRONG_BORESIGHT_PX * px_arcsec,
        "attitudes_output": n_out, "wrong_attitudes": n_wrong, "outputs_with_wrong_ids": n_wrong_ids,
        "output_fraction": n_out / trials if trials else 0.0,
        "boresight_err_arcsec_median": float(np.median(errs[:, 0])) if len(errs) else None,
        "boresight_err_arcsec_p99": float(np.percentile(errs[:, 0], 99)) if len(errs) else None,
        "boresight_err_arcsec_max": float(errs[:, 0].max()) if len(errs) else None,
        "roll_err_arcsec_median": float(np.median(errs[:, 1])) if len(errs) else None,
        "roll_err_arcsec_max": float(errs[:, 1].max()) if len(errs) else None,
        "star_check": {k: getattr(pyr.check, k) for k in ("sigma_px", "mag_sigma", "mag_limit", "p_reject",
                                                           "p_detect_min", "v_safe")},
        "by_false_stars": by_false, "worst": worst, "wrong_outputs": wrong_list, "tracker_counts": dict(tracker.counts),
        "wall_s": round(time.perf_counter() - t0, 1), "pass": n_wrong == 0,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m gyrostar.hil.reliability.starid_safety",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=10000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--mag-noise", type=float, default=0.3, help="magnitude noise, 1σ (mag)")
    ap.add_argument("--pos-noise", type=float, default=0.5, help="centroid noise, 1σ per axis (px)")
    a = ap.parse_args(argv)
    s = run(a.trials, a.seed, a.mag_noise, a.pos_noise)
    print(json.dumps(s, indent=1))
    return 0 if s["pass"] else 1


if __name__ == "__main__":
    sys.exit(main())
