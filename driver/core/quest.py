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
the best-conditioned of the four solutions, the largest |γ| at the shared λ, is built).
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
def _flipped(bm, flip):
    """S = B' + B'ᵀ (its 6 distinct entries), σ = tr B', z, κ (sum of S's principal 2×2
    minors) and Δ = det S of the attitude profile matrix with the references turned 180°
    about axis ``flip`` (-1: none): B' = B · R_flip. Scalars only."""
    c0 = -1.0 if (flip >= 0 and flip != 0) else 1.0
    c1 = -1.0 if (flip >= 0 and flip != 1) else 1.0
    c2 = -1.0 if (flip >= 0 and flip != 2) else 1.0
    b00, b01, b02 = bm[0, 0] * c0, bm[0, 1] * c1, bm[0, 2] * c2
    b10, b11, b12 = bm[1, 0] * c0, bm[1, 1] * c1, bm[1, 2] * c2
    b20, b21, b22 = bm[2, 0] * c0, bm[2, 1] * c1, bm[2, 2] * c2
    s00, s11, s22 = b00 + b00, b11 + b11, b22 + b22
    s01, s02, s12 = b01 + b10, b02 + b20, b12 + b21
    sigma = b00 + b11 + b22
    z0, z1, z2 = b12 - b21, b20 - b02, b01 - b10
    kappa = s11 * s22 - s12 * s12 + s00 * s22 - s02 * s02 + s00 * s11 - s01 * s01
    delta = s00 * (s11 * s22 - s12 * s12) - s01 * (s01 * s22 - s12 * s02) + s02 * (s01 * s12 - s11 * s02)
    return s00, s01, s02, s11, s12, s22, sigma, z0, z1, z2, kappa, delta


@njit(cache=True)
def _largest_eigenvalue(bm, lam0):
    """λ_max of Davenport's K: Newton–Raphson on QUEST's characteristic quartic from λ₀ = Σw
    (the 180° turns of the references leave K's eigenvalues as they are)."""
    s00, s01, s02, s11, s12, s22, sigma, z0, z1, z2, kappa, delta = _flipped(bm, -1)
    sz0 = s00 * z0 + s01 * z1 + s02 * z2
    sz1 = s01 * z0 + s11 * z1 + s12 * z2
    sz2 = s02 * z0 + s12 * z1 + s22 * z2
    a = sigma * sigma - kappa
    bb = sigma * sigma + (z0 * z0 + z1 * z1 + z2 * z2)
    c = delta + (z0 * sz0 + z1 * sz1 + z2 * sz2)
    d = sz0 * sz0 + sz1 * sz1 + sz2 * sz2
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
    return lam


@njit(cache=True)
def _gamma(bm, lam, flip):
    """γ = (λ + σ) α − Δ of the references turned about ``flip``: the candidate's
    unnormalised scalar part."""
    _, _, _, _, _, _, sigma, _, _, _, kappa, delta = _flipped(bm, flip)
    return (lam + sigma) * (lam * lam - sigma * sigma + kappa) - delta


@njit(cache=True)
def _quest_core(bm, lam, flip):
    """Unnormalised QUEST quaternion (x = α z + β S z + S² z, γ) for the attitude profile
    matrix ``bm`` with the references turned 180° about axis ``flip`` (-1: none), at the
    largest eigenvalue ``lam``."""
    s00, s01, s02, s11, s12, s22, sigma, z0, z1, z2, kappa, delta = _flipped(bm, flip)
    sz0 = s00 * z0 + s01 * z1 + s02 * z2
    sz1 = s01 * z0 + s11 * z1 + s12 * z2
    sz2 = s02 * z0 + s12 * z1 + s22 * z2
    alpha = lam * lam - sigma * sigma + kappa
    beta = lam - sigma
    out = np.empty(4)
    out[0] = alpha * z0 + beta * sz0 + (s00 * sz0 + s01 * sz1 + s02 * sz2)
    out[1] = alpha * z1 + beta * sz1 + (s01 * sz0 + s11 * sz1 + s12 * sz2)
    out[2] = alpha * z2 + beta * sz2 + (s02 * sz0 + s12 * sz1 + s22 * sz2)
    out[3] = (lam + sigma) * alpha - delta
    return out


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
    # scalar part is the largest component (≥ 1/2) of the unit quaternion. They share λ
    # too: one Newton solve, four γ, one candidate built.
    lam = _largest_eigenvalue(bm, lam0)
    best_axis = -1
    best = abs(_gamma(bm, lam, -1))
    for axis in range(3):
        g = abs(_gamma(bm, lam, axis))
        if g > best:
            best, best_axis = g, axis
    q = _quest_core(bm, lam, best_axis)
    if best_axis >= 0:
        flip = np.zeros(4)
        flip[best_axis] = 1.0  # 180° about the reference axis: A = A' · R_axis
        q = quat_mult(q, flip)
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
