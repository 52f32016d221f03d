"""Attitude multiplicative EKF (Lefferts, Markley & Shuster 1982): quaternion + gyro drift.

Global state: ``q`` (4,) ICRS → body, scalar last (``gyrostar.attitude``), and the gyro
drift ``b`` (3,) rad/s (``ω_mea = ω + b + η``). Error state (6,): ``a`` the small rotation
with ``q_true = δq(a) ⊗ q_est`` (body axes, rad; covariance equal to that of
``quat_error_angles``) and ``Δb = b_true − b_est``. Error dynamics
``ȧ = −[ω̂×] a − Δb``, ``Δḃ = w_u``; discrete over Δt:

    Φ = | exp(−[ω̂×]Δt)   −I Δt |    Q = | σ_v² Δt + σ_u² Δt³/3   −σ_u² Δt²/2 |
        | 0               I     |        | −σ_u² Δt²/2             σ_u² Δt     |

(σ_v rate white noise density rad/s/√Hz, σ_u drift random-walk density rad/s/√s).
A star measurement is the body unit vector ``b = A(q) r`` of a catalog vector r with
isotropic error σ (rad): ``H = [[b̂×]  0]``; the update is applied one star at a time
and reset into ``q`` (``q ← δq(a) ⊗ q``, ``b ← b + Δb``) after each image.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..attitude import quat_mult, quat_normalize, quat_to_dcm, rotvec_to_quat


@njit(cache=True)
def mekf_init(q0, b0, sigma_att, sigma_bias):
    """(q, b, P (6, 6)) with diagonal initial covariance (rad, rad/s)."""
    P = np.zeros((6, 6))
    for i in range(3):
        P[i, i] = sigma_att * sigma_att
        P[3 + i, 3 + i] = sigma_bias * sigma_bias
    return quat_normalize(q0.copy()), b0.copy(), P


@njit(cache=True)
def mekf_predict(q, b, P, omega_m, dt, sigma_v, sigma_u):
    """One gyro sample: q, b, P updated in place (q by the exact step for ω̂ = ω_m − b)."""
    w = omega_m - b
    qn = quat_normalize(quat_mult(rotvec_to_quat(w * dt), q))
    q[:] = qn
    # exp(−[ω×]Δt) = transpose of the rotation by ωΔt
    th = np.sqrt(w @ w) * dt
    wx = np.zeros((3, 3))
    wx[0, 1] = -w[2]
    wx[0, 2] = w[1]
    wx[1, 0] = w[2]
    wx[1, 2] = -w[0]
    wx[2, 0] = -w[1]
    wx[2, 1] = w[0]
    if th < 1e-8:
        e = np.eye(3) - wx * dt
    else:
        k = wx * dt / th
        e = np.eye(3) - np.sin(th) * k + (1.0 - np.cos(th)) * (k @ k)
    phi = np.eye(6)
    phi[:3, :3] = e
    for i in range(3):
        phi[i, 3 + i] = -dt
    Pn = phi @ P @ phi.T
    qv = sigma_v * sigma_v * dt + sigma_u * sigma_u * dt ** 3 / 3.0
    qc = -sigma_u * sigma_u * dt * dt / 2.0
    qb = sigma_u * sigma_u * dt
    for i in range(3):
        Pn[i, i] += qv
        Pn[i, 3 + i] += qc
        Pn[3 + i, i] += qc
        Pn[3 + i, 3 + i] += qb
    P[:, :] = 0.5 * (Pn + Pn.T)


@njit(cache=True)
def mekf_predict_blocks(q, b, P, omega_m, dt, sigma_v, sigma_u, E, T):
    """:func:`mekf_predict` by blocks, for the 400 Hz path: Φ = [[E, −Δt I], [0, I]] is
    applied to P = [[A, B], [Bᵀ, C]] 3×3 block by block (A' = (E A − Δt Bᵀ) Eᵀ − Δt (E B − Δt C),
    B' = E B − Δt C, C' = C), no 6×6 products and no temporaries; ``E``, ``T`` (3, 3) scratch."""
    w0 = omega_m[0] - b[0]
    w1 = omega_m[1] - b[1]
    w2 = omega_m[2] - b[2]
    w = np.empty(3)
    w[0] = w0 * dt
    w[1] = w1 * dt
    w[2] = w2 * dt
    q[:] = quat_normalize(quat_mult(rotvec_to_quat(w), q))
    th = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2) * dt
    # k = [ω×]Δt/θ; E = I − sin θ k + (1 − cos θ) k²  (small θ: I − [ω×]Δt)
    k01, k02, k12 = -w2 * dt, w1 * dt, -w0 * dt      # [ω×]Δt off-diagonals (k10 = −k01 ...)
    s1, s2 = 1.0, 0.0
    if th >= 1e-8:
        s1, s2 = np.sin(th), 1.0 - np.cos(th)
        k01 /= th
        k02 /= th
        k12 /= th
    K = ((0.0, k01, k02), (-k01, 0.0, k12), (-k02, -k12, 0.0))
    for i in range(3):
        for j in range(3):
            kk = K[i][0] * K[0][j] + K[i][1] * K[1][j] + K[i][2] * K[2][j]
            E[i, j] = (1.0 if i == j else 0.0) - s1 * K[i][j] + s2 * kk
    # T = E B − Δt C  (new cross block), then A' = (E A − Δt Bᵀ) Eᵀ − Δt T
    for i in range(3):
        for j in range(3):
            T[i, j] = E[i, 0] * P[0, 3 + j] + E[i, 1] * P[1, 3 + j] + E[i, 2] * P[2, 3 + j] - dt * P[3 + i, 3 + j]
    M = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            M[i, j] = E[i, 0] * P[0, j] + E[i, 1] * P[1, j] + E[i, 2] * P[2, j] - dt * P[3 + i, j]
    qv = sigma_v * sigma_v * dt + sigma_u * sigma_u * dt ** 3 / 3.0
    qc = -sigma_u * sigma_u * dt * dt / 2.0
    qb = sigma_u * sigma_u * dt
    for i in range(3):
        for j in range(i, 3):
            a = M[i, 0] * E[j, 0] + M[i, 1] * E[j, 1] + M[i, 2] * E[j, 2] - dt * T[i, j]
            a2 = M[j, 0] * E[i, 0] + M[j, 1] * E[i, 1] + M[j, 2] * E[i, 2] - dt * T[j, i]
            v = 0.5 * (a + a2)
            if i == j:
                v += qv
            P[i, j] = v
            P[j, i] = v
    for i in range(3):
        for j in range(3):
            P[i, 3 + j] = T[i, j] + (qc if i == j else 0.0)
            P[3 + j, i] = P[i, 3 + j]
        P[3 + i, 3 + i] += qb


@njit(cache=True)
def mekf_update(q, b, P, body_vecs, ref_vecs, sigmas, gate, accepted):
    """Update with identified stars: measured body unit vectors (n, 3), catalog ICRS
    vectors (n, 3), per-star σ (rad). Stars failing the χ² gate (2 dof on the tangent-plane
    innovation) are skipped; ``accepted`` (n,) uint8 is written. Returns the count used.
    """
    # H = [[b̂]×, 0] projected on the tangent plane: G = T·[b̂]× (2×3), the bias columns zero;
    # every product below is written out for that structure (no BLAS/LAPACK call per star)
    dx = np.zeros(6)
    n_ok = 0
    a = quat_to_dcm(q)
    bh = np.empty(3)
    G = np.empty((2, 3))
    PG = np.empty((6, 2))       # P Gᵀ over the attitude columns
    K = np.empty((6, 2))
    GP = np.empty((2, 6))       # G P[:3, :]
    M = np.empty((6, 6))
    for i in range(body_vecs.shape[0]):
        accepted[i] = 0
        r = ref_vecs[i]
        p0 = a[0, 0] * r[0] + a[0, 1] * r[1] + a[0, 2] * r[2]
        p1 = a[1, 0] * r[0] + a[1, 1] * r[1] + a[1, 2] * r[2]
        p2 = a[2, 0] * r[0] + a[2, 1] * r[1] + a[2, 2] * r[2]
        # predicted vector after the error-state corrections made so far in this image: b̂ − δθ × b̂
        bh[0] = p0 - (dx[1] * p2 - dx[2] * p1)
        bh[1] = p1 - (dx[2] * p0 - dx[0] * p2)
        bh[2] = p2 - (dx[0] * p1 - dx[1] * p0)
        nb = math.sqrt(bh[0] * bh[0] + bh[1] * bh[1] + bh[2] * bh[2])
        bh[0] /= nb
        bh[1] /= nb
        bh[2] /= nb
        zv = body_vecs[i]
        nz = math.sqrt(zv[0] * zv[0] + zv[1] * zv[1] + zv[2] * zv[2])
        nu0 = zv[0] / nz - bh[0]
        nu1 = zv[1] / nz - bh[1]
        nu2_ = zv[2] / nz - bh[2]
        # the measurement is 2-D: the tangent plane (two orthonormal axes ⟂ b̂): t1 = b̂ × x̂ (or × ŷ)
        t10, t11, t12 = 0.0, bh[2], -bh[1]
        if t11 * t11 + t12 * t12 < 0.1:
            t10, t11, t12 = -bh[2], 0.0, bh[0]
        nt = math.sqrt(t10 * t10 + t11 * t11 + t12 * t12)
        t10 /= nt
        t11 /= nt
        t12 /= nt
        t20 = bh[1] * t12 - bh[2] * t11
        t21 = bh[2] * t10 - bh[0] * t12
        t22 = bh[0] * t11 - bh[1] * t10
        # rows of T·[b̂]×, [b̂]× = [[0, −b2, b1], [b2, 0, −b0], [−b1, b0, 0]]
        G[0, 0] = t11 * bh[2] - t12 * bh[1]
        G[0, 1] = -t10 * bh[2] + t12 * bh[0]
        G[0, 2] = t10 * bh[1] - t11 * bh[0]
        G[1, 0] = t21 * bh[2] - t22 * bh[1]
        G[1, 1] = -t20 * bh[2] + t22 * bh[0]
        G[1, 2] = t20 * bh[1] - t21 * bh[0]
        y0 = t10 * nu0 + t11 * nu1 + t12 * nu2_
        y1 = t20 * nu0 + t21 * nu1 + t22 * nu2_
        for j in range(6):
            PG[j, 0] = P[j, 0] * G[0, 0] + P[j, 1] * G[0, 1] + P[j, 2] * G[0, 2]
            PG[j, 1] = P[j, 0] * G[1, 0] + P[j, 1] * G[1, 1] + P[j, 2] * G[1, 2]
        var = sigmas[i] * sigmas[i]
        s00 = G[0, 0] * PG[0, 0] + G[0, 1] * PG[1, 0] + G[0, 2] * PG[2, 0] + var
        s01 = G[0, 0] * PG[0, 1] + G[0, 1] * PG[1, 1] + G[0, 2] * PG[2, 1]
        s10 = G[1, 0] * PG[0, 0] + G[1, 1] * PG[1, 0] + G[1, 2] * PG[2, 0]
        s11 = G[1, 0] * PG[0, 1] + G[1, 1] * PG[1, 1] + G[1, 2] * PG[2, 1] + var
        det = s00 * s11 - s01 * s10
        if not det > 0.0:
            continue
        i00 = s11 / det
        i01 = -s01 / det
        i10 = -s10 / det
        i11 = s00 / det
        d2 = y0 * (i00 * y0 + i01 * y1) + y1 * (i10 * y0 + i11 * y1)
        if d2 > gate:
            continue
        for j in range(6):
            K[j, 0] = PG[j, 0] * i00 + PG[j, 1] * i10
            K[j, 1] = PG[j, 0] * i01 + PG[j, 1] * i11
            dx[j] += K[j, 0] * y0 + K[j, 1] * y1      # y is already taken at the corrected estimate
        # Joseph form: P ← (I − K H) P (I − K H)ᵀ + σ² K Kᵀ, with K H = [K G, 0]
        for c in range(6):
            GP[0, c] = G[0, 0] * P[0, c] + G[0, 1] * P[1, c] + G[0, 2] * P[2, c]
            GP[1, c] = G[1, 0] * P[0, c] + G[1, 1] * P[1, c] + G[1, 2] * P[2, c]
        for j in range(6):
            for c in range(6):
                M[j, c] = P[j, c] - (K[j, 0] * GP[0, c] + K[j, 1] * GP[1, c])
        for j in range(6):
            mg0 = M[j, 0] * G[0, 0] + M[j, 1] * G[0, 1] + M[j, 2] * G[0, 2]
            mg1 = M[j, 0] * G[1, 0] + M[j, 1] * G[1, 1] + M[j, 2] * G[1, 2]
            for c in range(6):
                P[j, c] = M[j, c] - (mg0 * K[c, 0] + mg1 * K[c, 1]) + var * (K[j, 0] * K[c, 0] + K[j, 1] * K[c, 1])
        accepted[i] = 1
        n_ok += 1
    # reset: fold the error state into the global state
    q[:] = quat_normalize(quat_mult(rotvec_to_quat(dx[:3]), q))
    b[:] = b + dx[3:]
    return n_ok
