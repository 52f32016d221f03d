"""numba kernel of the loop's per-frame path: one image's update applied at its mid-exposure.

:func:`update_at_mid` does in one compiled call what
:meth:`gyrostar.loop.attitude_filter.AttitudeFilter.update` documents: the prior at
``t_mid`` from the attitude history, the directions carried to now, the MEKF update on
P − Q_Δ, the history corrected from ``t_mid`` on, the mid-exposure product and the one-lag
smoothed product of the frame before, and the walk since ``t_mid`` added back. Frames as in
:mod:`gyrostar.attitude` (q ICRS → body, [x, y, z, w]); angles rad, times s.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..attitude import quat_conj, quat_mult, quat_normalize, quat_propagate, quat_to_dcm, rotvec_to_quat
from ..core.mekf import mekf_update
from ..core.small_matrix import inv3_sym


@njit(cache=True)
def q_at_history(q, ts, hist_t, hist_q, ih, t):
    """Attitude at time ``t`` (s): the newest history entry at or before it, propagated to
    ``t`` with the current rate ``ts[1:4]`` (≤ one gyro period); ``q`` when there is none.
    ``ih``: the ring's [head, …, writes out of time order] (:class:`AttitudeFilter`)."""
    if ts[0] != ts[0]:
        return q.copy()
    best = _newest_at_or_before(hist_t, ih, t)
    if best < 0:
        return q.copy()
    return quat_propagate(hist_q[best], ts[1:4], t - hist_t[best])


@njit(cache=True)
def _newest_at_or_before(hist_t, ih, t):
    """Index of the history entry with the latest time ≤ ``t`` (the first of equal ones in
    ring order), −1 when none: walking back from the head while the ring is in time order
    (it stops at the first such entry), else over the whole ring."""
    H = hist_t.shape[0]
    if ih[2] == 0:
        h = ih[0]
        for j in range(H):
            i = (h - j) % H
            if hist_t[i] == -np.inf:
                return -1
            if hist_t[i] <= t:
                return i
        return -1
    best = -1
    best_t = -np.inf
    for i in range(H):
        if hist_t[i] <= t and hist_t[i] > best_t:
            best = i
            best_t = hist_t[i]
    return best


@njit(cache=True)
def _rt_p_r(rot, P):
    """rotᵀ · P[:3, :3] · rot (3×3): an attitude covariance from now's body axes to t_mid's."""
    out = np.empty((3, 3))
    tmp = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            tmp[i, j] = P[i, 0] * rot[0, j] + P[i, 1] * rot[1, j] + P[i, 2] * rot[2, j]
    for i in range(3):
        for j in range(3):
            out[i, j] = rot[0, i] * tmp[0, j] + rot[1, i] * tmp[1, j] + rot[2, i] * tmp[2, j]
    return out


@njit(cache=True)
def _smooth_previous(mid, smoothed, t_mid, q_prior, p_prior, q_post, p_post, gap_s):
    """One-lag Rauch–Tung–Striebel of the previous mid-exposure product ``mid`` with this
    frame (see ``AttitudeFilter.update``); writes ``smoothed``. Frames more than ``gap_s``
    apart pass the previous product on as filtered."""
    if not math.isfinite(mid[0]):
        return
    if t_mid - mid[0] > gap_s:
        smoothed[:] = mid
        return
    q_k = mid[1:5].copy()
    p_k = mid[5:].copy().reshape(3, 3)
    r = quat_to_dcm(quat_mult(q_prior, quat_conj(q_k)))       # body(mid_k) → body(mid_k+1), the gyro's
    d = quat_mult(q_post, quat_conj(q_prior))
    sgn = 1.0 if d[3] >= 0 else -1.0
    delta = np.array([2.0 * d[0] * sgn, 2.0 * d[1] * sgn, 2.0 * d[2] * sgn])
    inv = inv3_sym(p_prior)      # a covariance: symmetric, positive
    if inv[0, 0] != inv[0, 0]:
        return
    c = p_k @ np.ascontiguousarray(r.T) @ inv
    smoothed[0] = mid[0]
    smoothed[1:5] = quat_normalize(quat_mult(rotvec_to_quat(c @ delta), q_k))
    ps = p_k + c @ (p_post - p_prior) @ np.ascontiguousarray(c.T)
    for i in range(3):
        for j in range(3):
            smoothed[5 + 3 * i + j] = 0.5 * (ps[i, j] + ps[j, i])


@njit(cache=True)
def update_at_mid(q, b, P, ts, hist_t, hist_q, ih, prm, kappa, mid, smoothed, t_mid, b_mid, refs, sigmas, accepted,
                  min_used, gate, qd_margin, gap_s):
    """Apply one image (body unit vectors ``b_mid`` (n, 3) measured at ``t_mid``, catalog
    vectors ``refs`` (n, 3), σ ``sigmas`` (n,) rad) now; ``accepted`` (n,) uint8 written.
    State q, b, P, history and ``mid``/``smoothed`` in place (layouts of ``AttitudeFilter``).
    Returns the count of stars used (0: not applied, fewer than ``min_used`` passed)."""
    q_prior_mid = q_at_history(q, ts, hist_t, hist_q, ih, t_mid)
    rq = quat_mult(q, quat_conj(q_prior_mid))                       # body(t_mid) → body(now)
    rot = quat_to_dcm(rq)
    bvecs = np.ascontiguousarray(b_mid @ np.ascontiguousarray(rot.T))
    t_last = ts[0] if ts[0] == ts[0] else t_mid
    lag = max(t_last - t_mid, 0.0)
    # the rate-proportional error's share of the walk since t_mid: it grows from the last fix
    # (kernels.predict_batch), (σ_s |ω̂| a)² at an age a of the fix
    qr = 0.0
    s2w2 = 0.0
    t_fix = ts[4]
    if prm[5] > 0.0 and t_fix == t_fix:
        s2w2 = prm[5] * (ts[1] ** 2 + ts[2] ** 2 + ts[3] ** 2)
        qr = s2w2 * (max(t_last - t_fix, 0.0) ** 2 - max(t_mid - t_fix, 0.0) ** 2)
    qd = prm[1] ** 2 * lag + qr
    if qd > 0 and min(P[0, 0], P[1, 1], P[2, 2]) > qd_margin * qd:   # else: no usable prior at t_mid
        for i in range(3):
            P[i, i] -= qd
    else:
        qd = 0.0
    p_prior_mid = _rt_p_r(rot, P)
    q_old = q.copy()
    b_old = b.copy()
    P_old = P.copy()
    n = mekf_update(q, b, P, bvecs, refs, sigmas, gate, accepted)
    if 0 < n < min_used:
        q[:] = q_old
        b[:] = b_old
        P[:, :] = P_old
        n = 0
    if n:
        # the correction carried into the history from t_mid on (each entry keeps its gyro
        # rotation to now): a later-arriving earlier frame must not apply it a second time
        corr = quat_mult(quat_conj(q_old), q)
        H = hist_t.shape[0]
        if ih[2] == 0:                   # in time order: the entries from t_mid on are the newest
            for j in range(H):
                i = (ih[0] - j) % H
                if not hist_t[i] >= t_mid:
                    break
                hist_q[i] = quat_normalize(quat_mult(hist_q[i], corr))
        else:
            for i in range(H):
                if hist_t[i] >= t_mid:
                    hist_q[i] = quat_normalize(quat_mult(hist_q[i], corr))
        q_mid = quat_mult(quat_conj(rq), q)
        p_mid = _rt_p_r(rot, P)
        _smooth_previous(mid, smoothed, t_mid, q_prior_mid, p_prior_mid, q_mid, p_mid, gap_s)
        mid[0] = t_mid
        mid[1:5] = q_mid
        for i in range(3):
            for j in range(3):
                mid[5 + 3 * i + j] = p_mid[i, j]
    # back to now: the walk since t_mid, less what the gyro's low-pass takes out of it; an
    # applied update is the new fix, from which the rate-proportional error grows again
    back = 0.0
    if qd > 0:
        back = prm[1] ** 2 * max(lag - kappa, 0.0) + (s2w2 * lag * lag if n else qr)
    if n and not t_mid <= ts[4]:      # a newer fix (or the first: nan)
        ts[4] = t_mid
    for i in range(3):
        P[i, i] += back
    return n
