"""Verification of an identification by QUEST residuals: a wrong match is never kept silently.

Given measured body unit vectors ``b`` (n, 3), navigation-star vectors ``ref`` and a match
``match`` (n,) (navigation-star index, -1 for none), :func:`verify_matches` solves QUEST on
the matched pairs, measures each residual angle ∠(b_i, A(q) r_i) (rad) and, while the
worst exceeds ``tol``, drops it and solves again. At least two stars must survive, and
(for two stars) their measured and catalog separations must agree within ``tol``.
The result is ``(q, match, n_ok, max_residual)``; ``n_ok < 2`` means rejected (``match``
then all -1). Same conventions as :func:`gyrostar.core.quest.quest` (q ICRS → body).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..attitude import quat_to_dcm
from ..core.quest import quest
from .index import cone_query


@njit(cache=True)
def residuals(q, b, ref, match):
    """Residual angle (rad) of each matched star (0 for unmatched)."""
    a = quat_to_dcm(q)
    res = np.zeros(b.shape[0])
    for i in range(b.shape[0]):
        s = match[i]
        if s < 0:
            continue
        r = ref[s]
        d = 0.0
        for j in range(3):
            d += b[i, j] * (a[j, 0] * r[0] + a[j, 1] * r[1] + a[j, 2] * r[2])
        res[i] = np.arccos(min(1.0, max(-1.0, d)))
    return res


@njit(cache=True)
def solve(b, ref, match):
    """QUEST attitude (ICRS → body) on the matched pairs (equal weights)."""
    m = 0
    for i in range(match.shape[0]):
        if match[i] >= 0:
            m += 1
    bb = np.empty((m, 3))
    rr = np.empty((m, 3))
    k = 0
    for i in range(match.shape[0]):
        if match[i] >= 0:
            bb[k] = b[i]
            rr[k] = ref[match[i]]
            k += 1
    q, _ = quest(bb, rr, np.ones(m))
    return q


@njit(cache=True)
def verify_matches(b, ref, match, tol):
    """QUEST + residual test with iterative rejection. Returns ``(q, match, n_ok, max_res)``."""
    out = match.copy()
    q = np.array([0.0, 0.0, 0.0, 1.0])
    # a catalog star may explain one measured star only
    for i in range(out.shape[0]):
        for j in range(i + 1, out.shape[0]):
            if out[i] >= 0 and out[i] == out[j]:
                out[i] = -1
                out[j] = -1
    while True:
        n = 0
        for i in range(out.shape[0]):
            if out[i] >= 0:
                n += 1
        if n < 2:
            out[:] = -1
            return q, out, 0, np.inf
        q = solve(b, ref, out)
        res = residuals(q, b, ref, out)
        worst = -1
        wres = 0.0
        for i in range(out.shape[0]):
            if out[i] >= 0 and res[i] > wres:
                wres = res[i]
                worst = i
        if wres <= tol:
            if n == 2:
                # two stars: only their separation is a real check
                i0 = -1
                i1 = -1
                for i in range(out.shape[0]):
                    if out[i] >= 0:
                        if i0 < 0:
                            i0 = i
                        else:
                            i1 = i
                tb = np.arccos(min(1.0, max(-1.0, b[i0] @ b[i1])))
                tr = np.arccos(min(1.0, max(-1.0, ref[out[i0]] @ ref[out[i1]])))
                if abs(tb - tr) > tol:
                    out[:] = -1
                    return q, out, 0, np.inf
            return q, out, n, wres
        out[worst] = -1


@njit(cache=True)
def consistent(b, ref, sig, k_sigma, tol_min):
    """Which of n measured stars agree with each other, whatever a prior says: bool (n,).
    ``b`` (n, 3) measured and ``ref`` (n, 3) catalog unit vectors, ``sig`` (n,) centroid σ
    (rad). With n ≥ 3, :func:`verify_matches` over all of them at the tolerance
    max(``k_sigma`` × the median σ, ``tol_min``) rad; fewer stars are all kept."""
    n = sig.shape[0]
    out = np.ones(n, np.bool_)
    if n < 3:
        return out
    srt = np.sort(sig)
    med = srt[n // 2] if n % 2 else (srt[n // 2 - 1] + srt[n // 2]) / 2
    _, match, n_ok, _ = verify_matches(b, ref, np.arange(n), max(k_sigma * med, tol_min))
    for i in range(n):
        out[i] = n_ok > 0 and match[i] >= 0
    return out


@njit(cache=True)
def drop_ambiguous(b, q, vec, vmag, vstart, vstars, vvec, vh, vg, fov_radius, tol, match):
    """Unmatch (in place) every star with more than one catalog star within ``tol`` of its
    direction under attitude ``q``: a close pair cannot be told apart by position, so
    naming either could be wrong. Returns the number of stars dropped."""
    a = quat_to_dcm(q)
    near = cone_query(vvec, vstars, vstart, vh, vg, a[2].copy(), fov_radius + tol, vec.shape[0])
    cos_tol = np.cos(tol)
    dropped = 0
    for i in range(b.shape[0]):
        if match[i] < 0:
            continue
        v0 = a[0, 0] * b[i, 0] + a[1, 0] * b[i, 1] + a[2, 0] * b[i, 2]
        v1 = a[0, 1] * b[i, 0] + a[1, 1] * b[i, 1] + a[2, 1] * b[i, 2]
        v2 = a[0, 2] * b[i, 0] + a[1, 2] * b[i, 1] + a[2, 2] * b[i, 2]
        hits = 0
        for t in range(near.shape[0]):
            s = near[t]
            if v0 * vec[s, 0] + v1 * vec[s, 1] + v2 * vec[s, 2] >= cos_tol:
                hits += 1
        if hits > 1:
            match[i] = -1
            dropped += 1
    return dropped


@njit(cache=True)
def body_to_icrs(a, b):
    """Body unit vectors ``b`` (n, 3) in ICRS under the attitude matrix ``a`` (ICRS → body): ``b @ a``."""
    n = b.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        for j in range(3):
            out[i, j] = a[0, j] * b[i, 0] + a[1, j] * b[i, 1] + a[2, j] * b[i, 2]
    return out


@njit(cache=True)
def drop_shared(b, q, vec, tol, match):
    """Unmatch (in place) every star whose catalog star has a second observed star within
    ``tol`` of it under attitude ``q``: either spot could be the star's. Returns the number
    of stars dropped."""
    n = b.shape[0]
    cos_tol = np.cos(tol)
    icrs = body_to_icrs(quat_to_dcm(q), b)
    drop = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        s = match[i]
        if s < 0:
            continue
        within = 0
        for j in range(n):
            if icrs[j, 0] * vec[s, 0] + icrs[j, 1] * vec[s, 1] + icrs[j, 2] * vec[s, 2] >= cos_tol:
                within += 1
        drop[i] = within >= 2
    dropped = 0
    for i in range(n):
        if drop[i]:
            match[i] = -1
            dropped += 1
    return dropped


@njit(cache=True)
def loo_reject(b, ref, match, tol):
    """Leave-one-out test (in place): each matched star's residual under the attitude solved
    from the others; the worst, if beyond ``tol``, is unmatched. Returns True if one was.

    With few stars a wrong match bends the joint solution until its own residual looks
    small; predicted from the others it cannot hide."""
    worst = -1
    wres = tol
    for i in range(match.shape[0]):
        s = match[i]
        if s < 0:
            continue
        match[i] = -1
        q = solve(b, ref, match)
        match[i] = s
        a = quat_to_dcm(q)
        r = ref[s]
        d = 0.0
        for j in range(3):
            d += b[i, j] * (a[j, 0] * r[0] + a[j, 1] * r[1] + a[j, 2] * r[2])
        res = np.arccos(min(1.0, max(-1.0, d)))
        if res > wres:
            wres = res
            worst = i
    if worst >= 0:
        match[worst] = -1
        return True
    return False
