"""Star-identification speed, each figure against a baseline measured in the same run.

* ``pyramid_<case>_vs_tetra3rs`` — Pyramid lost-in-space against tetra3rs (Rust) on the
  same centroid sets in this process, its database generated for the same field: 10° and
  20° fields (1024 px, Hipparcos V ≤ 6.5, 0.5 px noise, 2 false stars) and 10° with 1 px
  noise and 5 false stars at random brightness ranks; median per field (``ratio``) and
  p99 (``p99_ratio``), wall; the same on CPU time (``cpu_ratio``, ``cpu_p99_ratio``).
* ``pyramid_10deg_vs_cedar`` — the 10° case against cedar-solve with its shipped 10–30°
  database. A missing peer is skipped with the reason.
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


def _fields(n, seed):
    """Tracking frames (qian2015, 1 px, 0.2 mag) with their gyro-predicted attitudes."""
    from gyrostar.attitude import quat_propagate, random_attitudes
    from gyrostar.hil.evaluation import eval_starid as ev

    cfg = ev.TrialConfig(method="extended-grid")
    s = ev.setup(cfg)
    rng = np.random.default_rng(seed)
    out = []
    for q in random_attitudes(n, rng):
        omega = np.radians(rng.uniform(-0.3, 0.3, 3))
        q1 = quat_propagate(q, omega, 1.0)
        q_pred = ev.gyro_prediction(q, omega, cfg, rng)
        out.append((s["sky"].observe(s["camera"], q1, 7.5, 1.0, 0.2, 0, rng), q_pred))
    return s, out


def _time(fn, items):
    ts = []
    for it in items:
        t0 = time.perf_counter()
        fn(it)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts) * 1e6


# lost-in-space cases against the peers: the issue-19 fields (Hipparcos, ideal pinhole)
_LIS = {
    "10deg": dict(fov_deg=10.0, mag_limit=6.5, pos_noise_px=0.5, false_stars=2),
    "20deg": dict(fov_deg=20.0, mag_limit=6.5, pos_noise_px=0.5, false_stars=2),
    "10deg_5false_1px": dict(fov_deg=10.0, mag_limit=6.5, pos_noise_px=1.0, false_stars=5),
}


def _pyramid_vs_peer(case, peer, n):
    """Ours and the peer on the same fields in this process (``eval_starid.run_chunk``)."""
    from gyrostar.hil.evaluation import eval_starid as ev

    cfg = ev.TrialConfig(method="pyramid", pixels=1024, mag_noise=0.0, cat_pos_noise_px=0.0, cat_mag_noise=0.0,
                         peer=peer, **_LIS[case])
    r = ev.run_chunk(cfg, 7, n)
    ms = r["ms"]
    ours = (f"ours {100 * r['success'].mean():.1f} % solved, {int(r['wrong'].sum())} with a wrong label, "
            f"p99 {np.percentile(ms, 99) * 1e3:.0f} µs")
    if "peer_reason" in r:
        return {"us": float(np.median(ms)) * 1e3, "baseline_us": None, "ratio": None,
                "note": f"peer skipped: {r['peer_reason']}; {ours}"}
    pm = r["peer_ms"]
    us, base = float(np.median(ms)) * 1e3, float(np.median(pm)) * 1e3
    p99, bp99 = float(np.percentile(ms, 99)) * 1e3, float(np.percentile(pm, 99)) * 1e3
    cpu, pcpu = r["cpu_ms"], r["peer_cpu_ms"]
    return {"us": us, "baseline_us": base, "ratio": base / us, "p99_us": p99, "baseline_p99_us": bp99,
            "p99_ratio": bp99 / p99, "cpu_ratio": float(np.median(pcpu) / np.median(cpu)),
            "cpu_p99_ratio": float(np.percentile(pcpu, 99) / np.percentile(cpu, 99)),
            "note": f"{n} fields; {ours}; {r['peer_name']} {100 * r['peer_correct'].mean():.1f} % right, "
                    f"{100 * np.mean(r['peer_solved'] & ~r['peer_correct']):.1f} % wrong, p99 {bp99:.0f} µs"}


def _track_vs_pyramid(n):
    from gyrostar.mocks.star_lists import score
    from gyrostar.starid.pyramid import Pyramid

    s, fields = _fields(n, 8)
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
        **{f"pyramid_{case}_vs_tetra3rs": _pyramid_vs_peer(case, "tetra3rs", 4 * n) for case in _LIS},
        "pyramid_10deg_vs_cedar": _pyramid_vs_peer("10deg", "cedar-solve", n),
        "extended_grid_track_vs_pyramid": _track_vs_pyramid(n),
        "kvector_vs_searchsorted": _kvector(20000 if quick else 200000),
    }
