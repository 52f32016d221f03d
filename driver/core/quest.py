"""QUEST snapshot attitude (Shuster & Oh 1981) with its covariance.

``quest(body_vecs, ref_vecs, weights) -> (q, cov)``

* ``body_vecs`` (n, 3): measured unit vectors in the body (camera) frame.
* ``ref_vecs``  (n, 3): the same stars' ICRS unit vectors (catalog).
* ``weights``   (n,):  inverse variances 1/σ_i² (rad⁻²) of each measured direction
  (QUEST measurement model: isotropic error of std σ_i in the plane ⟂ to the vector).
  Scaling all weights leaves ``q`` unchanged and scales ``cov``.
* ``q`` (4,): scalar-last quaternion mapping ICRS → body (``gyrostar.attitude``),
  minimising Wahba's loss Σ w_i |b_i − A(q) r_i|².
* ``cov`` (3, 3): covariance (rad²) of the small attitude error
  δθ = 2 vec(q_est ⊗ q_true⁻¹) in body axes: (Σ w_i (I − b_i b_iᵀ))⁻¹.

The largest eigenvalue of Davenport's K matrix comes from Newton–Raphson on QUEST's
characteristic quartic (start λ = Σ w); near-180° solutions are avoided with Shuster's
method of sequential rotations (the reference frame is turned 180° about x, y or z and
the best-conditioned of the four solutions is kept).
Fewer than two non-parallel vectors is an ill-posed problem: ``cov`` then contains inf.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..attitude import quat_mult, quat_normalize


@njit(cache=True)
def _quest_core(b, r, w, flip):
    """Unnormalised QUEST quaternion for references turned 180° about axis ``flip`` (-1: none)."""
    bm = np.zeros((3, 3))
    for i in range(b.shape[0]):
        r0, r1, r2 = r[i, 0], r[i, 1], r[i, 2]
        if flip == 0:
            r1, r2 = -r1, -r2
        elif flip == 1:
            r0, r2 = -r0, -r2
        elif flip == 2:
            r0, r1 = -r0, -r1
        for j in range(3):
            bm[j, 0] += w[i] * b[i, j] * r0
            bm[j, 1] += w[i] * b[i, j] * r1
            bm[j, 2] += w[i] * b[i, j] * r2
    s = bm + bm.T
    sigma = bm[0, 0] + bm[1, 1] + bm[2, 2]
    z = np.array([bm[1, 2] - bm[2, 1], bm[2, 0] - bm[0, 2], bm[0, 1] - bm[1, 0]])
    kappa = (s[1, 1] * s[2, 2] - s[1, 2] * s[2, 1] + s[0, 0] * s[2, 2] - s[0, 2] * s[2, 0]
             + s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0])
    delta = np.linalg.det(s)
    sz = s @ z
    a = sigma * sigma - kappa
    bb = sigma * sigma + z @ z
    c = delta + z @ sz
    d = sz @ sz
    lam = 0.0
    for i in range(w.shape[0]):
        lam += w[i]
    for _ in range(50):
        f = lam ** 4 - (a + bb) * lam ** 2 - c * lam + (a * bb + c * sigma - d)
        fp = 4.0 * lam ** 3 - 2.0 * (a + bb) * lam - c
        if fp == 0.0:
            break
        step = f / fp
        lam -= step
        if abs(step) <= 1e-15 * max(1.0, abs(lam)):
            break
    alpha = lam * lam - sigma * sigma + kappa
    beta = lam - sigma
    gamma = (lam + sigma) * alpha - delta
    x = alpha * z + beta * sz + s @ sz
    q = np.array([x[0], x[1], x[2], gamma])
    return q


@njit(cache=True)
def quest(body_vecs, ref_vecs, weights):
    """Attitude q (ICRS → body, scalar last) and its 3×3 error covariance (rad², body axes)."""
    # The four candidates (no turn, 180° about x, y, z) share one scale factor (the
    # adjugate of λI − K), so the one with the largest |γ| is the best conditioned: its
    # scalar part is the largest component (≥ 1/2) of the unit quaternion.
    q = _quest_core(body_vecs, ref_vecs, weights, -1)
    best = abs(q[3])
    for axis in range(3):
        qa = _quest_core(body_vecs, ref_vecs, weights, axis)
        if abs(qa[3]) > best:
            best = abs(qa[3])
            flip = np.zeros(4)
            flip[axis] = 1.0  # 180° about the reference axis: A = A' · R_axis
            q = quat_mult(qa, flip)
    if q @ q == 0.0:  # fully degenerate (one vector): any rotation about it fits
        q = np.array([0.0, 0.0, 0.0, 1.0])
    q = quat_normalize(q)
    info = np.zeros((3, 3))
    for i in range(body_vecs.shape[0]):
        bi = body_vecs[i]
        nb = np.sqrt(bi @ bi)
        for j in range(3):
            for k in range(3):
                info[j, k] -= weights[i] * bi[j] * bi[k] / (nb * nb)
            info[j, j] += weights[i]
    if abs(np.linalg.det(info)) <= 1e-12 * max(1.0, (info[0, 0] + info[1, 1] + info[2, 2])) ** 3:
        cov = np.full((3, 3), np.inf)
    else:
        cov = np.linalg.inv(info)
    return q, cov
