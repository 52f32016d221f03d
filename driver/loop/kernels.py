"""numba kernels of the coupled loop's per-sample path (no Python objects per sample)."""

from __future__ import annotations

import numpy as np
from numba import njit

from ..attitude import quat_mult, quat_normalize, quat_to_dcm, rotvec_to_quat
from ..camera import project_point
from ..core.mekf import mekf_predict_blocks
from ..gyro.convert import FLAG_GAP, FLAG_SATURATED, FLAG_STUCK_AXIS
from .record import FLAG_BIAS_CONVERGED, FLAG_GYRO_GAP, FLAG_GYRO_SATURATED, FLAG_GYRO_STUCK


@njit(cache=True)
def project_refs(params, q, refs):
    """Catalog vectors (n, 3) → pixel (u, v) (n, 2) and on-sensor flags under attitude q."""
    a = quat_to_dcm(q)
    n = refs.shape[0]
    uv = np.empty((n, 2))
    ok = np.empty(n, dtype=np.bool_)
    for i in range(n):
        u, v, good = project_point(params, a @ refs[i])
        uv[i, 0] = u
        uv[i, 1] = v
        ok[i] = good
    return uv, ok


@njit(cache=True)
def predict_batch(smp_t, smp_rate, smp_flags, n, q, b, P, ts, hist_t, hist_q, ih, prm, flags_first, flags_base,
                  mode, refs, ids, cam, slots, uv_track, mid, smoothed, out):
    """One FIFO batch through the 400 Hz path: for every sample predict the attitude MEKF
    (:func:`gyrostar.core.mekf.mekf_predict_blocks`), keep the attitude history, project the
    tracked stars and write the output record — no Python object per sample.

    smp_t (s), smp_rate (rad/s, body), smp_flags (gyro sample flags): the batch, first ``n``.
    q, b, P: filter state, in place. ts (5,): [t of the last sample (s, nan: none), ω̂ (rad/s),
    t of the last fix (s)] in place. hist_t (H,), hist_q (H, 4): history ring; ih (3,) int64: [ring head, output seq,
    writes out of time order (counted here)]
    in place (ts[4] set here to the first sample's time while there is no fix).
    prm: [gyro period s, σ_v rad/s/√Hz, σ_u rad/s/√s, bias-converged variance (rad/s)², gyro
    group delay τ s, σ_s² (rate-proportional error, rad/rad: a constant error, so the angle
    it adds since the last fix grows linearly, (σ_s |ω̂| a)² at an age a of the fix; the
    step's rate noise density is √(σ_v² + σ_s² |ω̂|² (2a + dt)))]. A sample stamped t measured the rate at t − τ: the
    filter and its history run on t − τ, and each record's attitude is carried on to t
    with the current rate (``t`` stays the sample's stamp). flags_first: flags only the
    first output carries (overrun, gyro gap); flags_base: flags every output carries.
    refs (k, 3), ids (k,): tracked stars' catalog vectors and ids (k = 0 when the attitude is
    not valid); cam: camera array. slots (k,) int64: their track slots; uv_track (S, 2):
    the tracks' centroid table, rows ``slots`` set to their centroids at the last sample
    (px). mid (14,): the mid-exposure product [t_mid, q_mid, cov_mid] copied to every record;
    smoothed (14,): the frame before, smoothed with it (``*_mid_s`` fields). out:
    OUTPUT_DTYPE records, first ``n`` written (every field but ``latency_us``).
    Returns the count of samples with a stuck gyro axis.
    """
    period = prm[0]
    tau = prm[4]
    H = hist_t.shape[0]
    k = refs.shape[0]
    stuck = 0
    w = np.empty(3)
    E = np.empty((3, 3))
    T = np.empty((3, 3))
    wt = np.empty(3)
    vb = np.empty(3)
    for i in range(n):
        t = smp_t[i] - tau
        dt = period if ts[0] != ts[0] else t - ts[0]
        if not 0.0 < dt < 2.0:      # across a FIFO gap: propagate over one period (P grows with the gap flag)
            dt = period
        ts[0] = t
        for j in range(3):
            w[j] = smp_rate[i, j]
        sv = prm[1]
        if prm[5] > 0.0:
            if ts[4] != ts[4]:      # no fix yet: the error grows from the first sample
                ts[4] = t - dt
            fix_age = max(t - dt - ts[4], 0.0)
            wn2 = (w[0] - b[0]) ** 2 + (w[1] - b[1]) ** 2 + (w[2] - b[2]) ** 2
            # (σ_s |ω̂| τ)² grows by σ_s² |ω̂|² (2τ + dt) dt over this step
            sv = np.sqrt(sv * sv + prm[5] * wn2 * (2.0 * fix_age + dt))
        mekf_predict_blocks(q, b, P, w, dt, sv, prm[2], E, T)
        if t <= hist_t[ih[0]]:
            ih[2] += 1          # the history is out of time order from here: searches scan all of it
        h = (ih[0] + 1) % H
        ih[0] = h
        hist_t[h] = t
        for j in range(4):
            hist_q[h, j] = q[j]
        for j in range(3):
            ts[1 + j] = w[j] - b[j]
        flags = flags_base
        if i == 0:
            flags |= flags_first
        g = smp_flags[i]
        if g & FLAG_GAP:
            flags |= FLAG_GYRO_GAP
        if g & FLAG_SATURATED:
            flags |= FLAG_GYRO_SATURATED
        if g & FLAG_STUCK_AXIS:
            flags |= FLAG_GYRO_STUCK
            stuck += 1
        if max(P[3, 3], max(P[4, 4], P[5, 5])) < prm[3]:
            flags |= FLAG_BIAS_CONVERGED
        r = out[i]
        r.t = smp_t[i]
        r.seq = ih[1]
        ih[1] += 1
        r.mode = mode
        r.flags = flags
        if tau > 0.0:
            for j in range(3):
                wt[j] = ts[1 + j] * tau
            qo = quat_normalize(quat_mult(rotvec_to_quat(wt), q))
        else:
            qo = q
        for j in range(4):
            r.q[j] = qo[j]
        for j in range(3):
            r.omega[j] = ts[1 + j]
            r.bias[j] = b[j]
        for a in range(6):
            for c in range(6):
                r.cov[a, c] = P[a, c]
        if k > 0:
            A = quat_to_dcm(qo)
            for s in range(k):
                for j in range(3):       # A @ refs[s] into scratch (no allocation per star)
                    vb[j] = A[j, 0] * refs[s, 0] + A[j, 1] * refs[s, 1] + A[j, 2] * refs[s, 2]
                u, v, _ = project_point(cam, vb)
                r.star_id[s] = ids[s]
                r.centroid_px[s, 0] = u
                r.centroid_px[s, 1] = v
                if i == n - 1:
                    uv_track[slots[s], 0] = u
                    uv_track[slots[s], 1] = v
        for s in range(k, r.star_id.shape[0]):
            r.star_id[s] = -1
            r.centroid_px[s, 0] = 0.0
            r.centroid_px[s, 1] = 0.0
        r.n_stars = k
        r.t_mid = mid[0]
        for j in range(4):
            r.q_mid[j] = mid[1 + j]
        r.t_mid_s = smoothed[0]
        for j in range(4):
            r.q_mid_s[j] = smoothed[1 + j]
        for a in range(3):
            for c in range(3):
                r.cov_mid[a, c] = mid[5 + 3 * a + c]
                r.cov_mid_s[a, c] = smoothed[5 + 3 * a + c]
    return stuck
