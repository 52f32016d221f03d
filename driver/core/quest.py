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
from ..errors import ConfigError


@njit(cache=True)
def _det3(m):
    return (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]) - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
            + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))


@njit(cache=True)
def _quest_core(b_all, lam0, flip):
    """Unnormalised QUEST quaternion for the attitude profile matrix ``b_all`` with the
    references turned 180° about axis ``flip`` (-1: none): B' = B · R_flip."""
    bm = b_all.copy()
    if flip >= 0:
        for j in range(3):
            if j != flip:
                for i in range(3):
                    bm[i, j] = -bm[i, j]
    s = bm + bm.T
    sigma = bm[0, 0] + bm[1, 1] + bm[2, 2]
    z = np.array([bm[1, 2] - bm[2, 1], bm[2, 0] - bm[0, 2], bm[0, 1] - bm[1, 0]])
    kappa = (s[1, 1] * s[2, 2] - s[1, 2] * s[2, 1] + s[0, 0] * s[2, 2] - s[0, 2] * s[2, 0]
             + s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0])
    delta = _det3(s)
    sz = s @ z
    a = sigma * sigma - kappa
    bb = sigma * sigma + z @ z
    c = delta + z @ sz
    d = sz @ sz
    lam = lam0
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
    n = body_vecs.shape[0]
    if n < 1 or ref_vecs.shape[0] != n or weights.shape[0] != n or body_vecs.shape[1] != 3 \
            or ref_vecs.shape[1] != 3:
        raise ConfigError("quest needs body (n, 3), ref (n, 3) and weights (n,) with n >= 1")
    for i in range(n):
        if not weights[i] > 0.0:
            raise ConfigError("quest weights must be positive (1/σ², rad⁻²)")
    bm = np.zeros((3, 3))
    lam0 = 0.0
    for i in range(body_vecs.shape[0]):
        lam0 += weights[i]
        for j in range(3):
            for k in range(3):
                bm[j, k] += weights[i] * body_vecs[i, j] * ref_vecs[i, k]
    # The four candidates (no turn, 180° about x, y, z) share one scale factor (the
    # adjugate of λI − K), so the one with the largest |γ| is the best conditioned: its
    # scalar part is the largest component (≥ 1/2) of the unit quaternion.
    q = _quest_core(bm, lam0, -1)
    best = abs(q[3])
    for axis in range(3):
        qa = _quest_core(bm, lam0, axis)
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
        nb2 = bi[0] * bi[0] + bi[1] * bi[1] + bi[2] * bi[2]
        for j in range(3):
            for k in range(3):
                info[j, k] -= weights[i] * bi[j] * bi[k] / nb2
            info[j, j] += weights[i]
    det = _det3(info)
    tr = info[0, 0] + info[1, 1] + info[2, 2]
    cov = np.empty((3, 3))
    if abs(det) <= 1e-12 * max(1.0, tr) ** 3:
        cov[:, :] = np.inf
        return q, cov
    inv = 1.0 / det
    for j in range(3):
        for k in range(3):
            # cofactor (k, j) / det, indices cyclic
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            k1, k2 = (k + 1) % 3, (k + 2) % 3
            cov[j, k] = (info[k1, j1] * info[k2, j2] - info[k1, j2] * info[k2, j1]) * inv
    return q, cov
