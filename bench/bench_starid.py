"""Star-identification speed, each figure against a baseline measured in the same run.

* ``pyramid_10deg_vs_cedar`` — Pyramid lost-in-space on 10°, 1024 px fields (Hipparcos
  V ≤ 6.5, 0.5 px noise, 2 false stars) against cedar-solve (``tetra3``
  ``solve_from_centroids`` with its shipped 10–30° database) on the same centroid sets;
  median per field. Skipped with the reason when cedar-solve is missing or unusable.
* ``extended_grid_track_vs_pyramid`` — tracking identification per frame (extended grid,
  qian2015 4° field, 1 px noise, 0.2 mag, gyro-predicted attitude after 1 s) against
  identifying the same frames lost-in-space with Pyramid.
* ``kvector_vs_searchsorted`` — one k-vector range query over the 10° pair table against
  two binary searches (``np.searchsorted``) on the same array; both inside numba loops.

Success figures are printed in the notes (a fast wrong answer is no answer).
"""

from __future__ import annotations

import statistics
import time

import numpy as np
from numba import njit


def _fields(method, n, seed):
    from gyrostar.attitude import quat_propagate, random_attitudes
    from gyrostar.starid import eval_starid as ev

    cfg = (ev.TrialConfig(method="pyramid", fov_deg=10.0, pixels=1024, mag_limit=6.5, pos_noise_px=0.5,
                          mag_noise=0.0, cat_pos_noise_px=0.0, cat_mag_noise=0.0, false_stars=2)
           if method == "pyramid" else ev.TrialConfig(method="extended-grid"))
    s = ev.setup(cfg)
    rng = np.random.default_rng(seed)
    out = []
    for q in random_attitudes(n, rng):
        if method == "pyramid":
            out.append((s["sky"].observe(s["camera"], q, cfg.mag_limit, 0.5, 0.0, 2, rng), None))
        else:
            omega = np.radians(rng.uniform(-0.3, 0.3, 3))
            q1 = quat_propagate(q, omega, 1.0)
            q_pred = ev._gyro_prediction(q, omega, cfg, rng)
            out.append((s["sky"].observe(s["camera"], q1, 7.5, 1.0, 0.2, 0, rng), q_pred))
    return s, out


def _time(fn, items):
    ts = []
    for it in items:
        t0 = time.perf_counter()
        fn(it)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts) * 1e6


def _pyramid_vs_cedar(n):
    from gyrostar.starid import eval_starid as ev
    from gyrostar.starid.synth import score

    s, fields = _fields("pyramid", n, 7)
    pyr = s["ident"]
    t3 = ev._cedar()
    ours = [score(pyr.identify(f.uv).ids, f.truth, f.alt) for f, _ in fields]
    ok = sum(c >= 2 and w == 0 for c, w in ours) / n
    us = _time(lambda f: pyr.identify(f[0].uv), fields)
    if isinstance(t3, str):
        return {"us": us, "baseline_us": None, "ratio": None, "note": f"peer skipped: {t3}; ours {100 * ok:.1f} % ok"}
    cam = s["camera"]
    peer = [ev.cedar_solve(t3, f.uv, cam, f.truth, f.alt) for f, _ in fields]
    pok = sum(p[1] for p in peer) / n
    base = statistics.median(p[2] for p in peer) * 1e3
    return {"us": us, "baseline_us": base, "ratio": base / us,
            "note": f"success ours {100 * ok:.1f} % vs cedar-solve {100 * pok:.1f} % ({n} fields)"}


def _track_vs_pyramid(n):
    from gyrostar.starid.pyramid import Pyramid
    from gyrostar.starid.synth import score

    s, fields = _fields("extended", n, 8)
    ext = s["ident"]
    from gyrostar.starid.index import load_index

    pyr = Pyramid(load_index("hip2", 7.5, 5.67, 0), s["camera"], sigma_px=1.0)
    ok = sum((lambda cw: cw[0] >= 2 and cw[1] == 0)(score(ext.identify(f.uv, qp).ids, f.truth, f.alt))
             for f, qp in fields) / n
    pok = sum((lambda cw: cw[0] >= 2 and cw[1] == 0)(score(pyr.identify(f.uv).ids, f.truth, f.alt))
              for f, _ in fields) / n
    us = _time(lambda it: ext.identify(it[0].uv, it[1]), fields)
    base = _time(lambda it: pyr.identify(it[0].uv), fields)
    return {"us": us, "baseline_us": base, "ratio": base / us,
            "note": f"success extended grid {100 * ok:.1f} % vs Pyramid {100 * pok:.1f} % on the same frames"}


def _kvector(n):
    from gyrostar.starid.index import load_index
    from gyrostar.starid.kvector import query

    @njit
    def kv_loop(y, k, m, q, los, width):
        acc = 0
        for lo in los:
            s, e = query(y, k, m, q, lo, lo + width)
            acc += e - s
        return acc

    @njit
    def bs_loop(y, los, width):
        acc = 0
        for lo in los:
            s = np.searchsorted(y, lo, side="left")
            e = np.searchsorted(y, lo + width, side="right")
            acc += e - s
        return acc

    ix = load_index("hip2", 6.5, 14.15, 0)
    y = ix.pair_theta
    los = np.random.default_rng(1).uniform(0.0, y[-1], n)
    width = 7e-4
    a = kv_loop(y, ix.kv, ix.kv_m, ix.kv_q, los, width)
    b = bs_loop(y, los, width)
    assert a == b
    t0 = time.perf_counter()
    kv_loop(y, ix.kv, ix.kv_m, ix.kv_q, los, width)
    t1 = time.perf_counter()
    bs_loop(y, los, width)
    t2 = time.perf_counter()
    us, base = (t1 - t0) / n * 1e6, (t2 - t1) / n * 1e6
    return {"us": us, "baseline_us": base, "ratio": base / us,
            "note": f"{ix.n_pairs} pairs; same ranges returned"}


def run(quick: bool) -> dict:
    n = 60 if quick else 300
    return {
        "pyramid_10deg_vs_cedar": _pyramid_vs_cedar(n),
        "extended_grid_track_vs_pyramid": _track_vs_pyramid(n),
        "kvector_vs_searchsorted": _kvector(20000 if quick else 200000),
    }
