"""Joint spot filter: every tracked star's position plus one shared gyro drift.

State ``X = [x_0, y_0, …, x_{n−1}, y_{n−1}, b_x, b_y, b_z]`` (size 2n + 3; px from the
principal point, rad/s), covariance ``P`` (2n + 3)². Each star follows the spot model of
``spot_ekf`` (same Φ blocks, first-order or pinhole); the drift is shared, and so is the
gyro's white noise: the process noise couples the stars,
``Q_ij = σ_ω² Δt² G_i G_jᵀ`` (``G_i = ∂V_i/∂ω``), which is what lets one star's centroid
correct its neighbours between images. A slot is used only while ``active[i]`` is set;
inactive slots have zero rows/columns in P and are skipped.

Costs: predict O(N²) (block-sparse Φ, no dense N³ products); the image update processes
stars one after the other (2-D measurements, independent noise: exact) with a χ² gate
per star, O(N²) each.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .motion import MODEL_PINHOLE, step_spot
from .spot_ekf import transition


@njit(cache=True)
def joint_init(n_slots, bias, sigma_bias):
    """Empty filter with ``n_slots`` star slots: (X, P, active uint8 (n_slots,))."""
    n = 2 * n_slots + 3
    X = np.zeros(n)
    X[n - 3:] = bias
    P = np.zeros((n, n))
    for j in range(n - 3, n):
        P[j, j] = sigma_bias * sigma_bias
    return X, P, np.zeros(n_slots, dtype=np.uint8)


@njit(cache=True)
def joint_add_star(X, P, active, slot, x, y, var_px2):
    """Start tracking a star in ``slot`` at (x, y) px with variance ``var_px2`` (uncorrelated)."""
    i = 2 * slot
    for j in range(P.shape[0]):
        P[i, j] = P[i + 1, j] = P[j, i] = P[j, i + 1] = 0.0
    X[i] = x
    X[i + 1] = y
    P[i, i] = P[i + 1, i + 1] = var_px2
    active[slot] = 1


@njit(cache=True)
def joint_drop_star(X, P, active, slot):
    """Stop tracking ``slot`` (its state and covariance are cleared)."""
    i = 2 * slot
    for j in range(P.shape[0]):
        P[i, j] = P[i + 1, j] = P[j, i] = P[j, i + 1] = 0.0
    X[i] = X[i + 1] = 0.0
    active[slot] = 0


@njit(cache=True)
def joint_predict(X, P, active, omega_m, dt, f_px, sigma_rate, sigma_bias_rw, model, work):
    """One gyro sample for all active stars, in place. ``work``: scratch (N, N) + (n, 2, 5) blocks.

    Pass ``work = joint_workspace(n_slots)`` (allocated once).
    """
    n_slots = active.shape[0]
    N = X.shape[0]
    b0 = N - 3
    M = work[0]
    blocks = work[1]  # per slot: rows 0..1 of Φ restricted to [x, y, bx, by, bz] + G (2x3) in [2:4]
    xs = np.empty(5)
    for s in range(n_slots):
        if active[s] == 0:
            continue
        xs[0] = X[2 * s]
        xs[1] = X[2 * s + 1]
        xs[2] = X[b0]
        xs[3] = X[b0 + 1]
        xs[4] = X[b0 + 2]
        phi, _psi, g = transition(xs, omega_m, dt, f_px, model)
        for r in range(2):
            for c in range(5):
                blocks[s, r, c] = phi[r, c]
            for c in range(3):
                blocks[s, 2 + r, c] = g[r, c]
    # state: each star moves with ω = ω_m − b
    wx = omega_m[0] - X[b0]
    wy = omega_m[1] - X[b0 + 1]
    wz = omega_m[2] - X[b0 + 2]
    for s in range(n_slots):
        if active[s] == 0:
            continue
        x, y = X[2 * s], X[2 * s + 1]
        if model == MODEL_PINHOLE:
            X[2 * s], X[2 * s + 1] = step_spot(x, y, wx, wy, wz, dt, f_px, model)
        else:
            X[2 * s] = x + (wz * y - wy * f_px) * dt
            X[2 * s + 1] = y + (-wz * x + wx * f_px) * dt
    # M = Φ P (rows)
    for s in range(n_slots):
        i = 2 * s
        if active[s] == 0:
            continue
        for r in range(2):
            a0 = blocks[s, r, 0]
            a1 = blocks[s, r, 1]
            c0 = blocks[s, r, 2]
            c1 = blocks[s, r, 3]
            c2 = blocks[s, r, 4]
            for j in range(N):
                M[i + r, j] = (a0 * P[i, j] + a1 * P[i + 1, j] + c0 * P[b0, j] + c1 * P[b0 + 1, j]
                               + c2 * P[b0 + 2, j])
    for j in range(N):
        M[b0, j] = P[b0, j]
        M[b0 + 1, j] = P[b0 + 1, j]
        M[b0 + 2, j] = P[b0 + 2, j]
    # P = M Φᵀ (columns)
    for s in range(n_slots):
        i = 2 * s
        if active[s] == 0:
            continue
        for r in range(2):
            a0 = blocks[s, r, 0]
            a1 = blocks[s, r, 1]
            c0 = blocks[s, r, 2]
            c1 = blocks[s, r, 3]
            c2 = blocks[s, r, 4]
            for k in range(N):
                P[k, i + r] = (a0 * M[k, i] + a1 * M[k, i + 1] + c0 * M[k, b0] + c1 * M[k, b0 + 1]
                               + c2 * M[k, b0 + 2])
    for k in range(N):
        P[k, b0] = M[k, b0]
        P[k, b0 + 1] = M[k, b0 + 1]
        P[k, b0 + 2] = M[k, b0 + 2]
    # process noise: common gyro white noise couples every pair of stars
    q = sigma_rate * sigma_rate * dt * dt
    for s in range(n_slots):
        if active[s] == 0:
            continue
        for t in range(n_slots):
            if active[t] == 0:
                continue
            for r in range(2):
                for c in range(2):
                    P[2 * s + r, 2 * t + c] += q * (blocks[s, 2 + r, 0] * blocks[t, 2 + c, 0]
                                                    + blocks[s, 2 + r, 1] * blocks[t, 2 + c, 1]
                                                    + blocks[s, 2 + r, 2] * blocks[t, 2 + c, 2])
    qb = sigma_bias_rw * sigma_bias_rw * dt
    for j in range(b0, N):
        P[j, j] += qb


def joint_workspace(n_slots: int):
    """Scratch buffers for ``joint_predict`` (allocate once per filter)."""
    n = 2 * n_slots + 3
    return (np.zeros((n, n)), np.zeros((n_slots, 4, 5)))


@njit(cache=True)
def joint_update(X, P, active, z, r_var, gate, accepted, nis):
    """Image update with centroids ``z`` (n_slots, 2) px (NaN = not measured), in place.

    ``r_var`` (n_slots, 2) per-axis measurement variances (px²). Stars are processed in
    slot order; a star whose normalised innovation exceeds ``gate`` (χ², 2 dof) is
    skipped. Writes ``accepted`` (uint8) and ``nis`` per slot; returns the count accepted.
    """
    N = X.shape[0]
    n_ok = 0
    K = np.empty((N, 2))
    hp0 = np.empty(N)
    hp1 = np.empty(N)
    for s in range(active.shape[0]):
        accepted[s] = 0
        nis[s] = np.nan
        if active[s] == 0 or not (np.isfinite(z[s, 0]) and np.isfinite(z[s, 1]) and np.isfinite(r_var[s, 0])
                                  and np.isfinite(r_var[s, 1])):
            continue
        i = 2 * s
        nu0 = z[s, 0] - X[i]
        nu1 = z[s, 1] - X[i + 1]
        s00 = P[i, i] + r_var[s, 0]
        s01 = P[i, i + 1]
        s11 = P[i + 1, i + 1] + r_var[s, 1]
        det = s00 * s11 - s01 * s01
        i00 = s11 / det
        i01 = -s01 / det
        i11 = s00 / det
        d2 = nu0 * (i00 * nu0 + i01 * nu1) + nu1 * (i01 * nu0 + i11 * nu1)
        nis[s] = d2
        if d2 > gate:
            continue
        for k in range(N):
            K[k, 0] = P[k, i] * i00 + P[k, i + 1] * i01
            K[k, 1] = P[k, i] * i01 + P[k, i + 1] * i11
        for k in range(N):
            X[k] += K[k, 0] * nu0 + K[k, 1] * nu1
        # P ← P − K (H P) with H P = P[i:i+2, :] (= P − K S Kᵀ); rows of P are
        # contiguous, so the update runs row by row; symmetry is restored after all stars
        for j in range(N):
            hp0[j] = P[i, j]
            hp1[j] = P[i + 1, j]
        for k in range(N):
            k0 = K[k, 0]
            k1 = K[k, 1]
            for j in range(N):
                P[k, j] -= k0 * hp0[j] + k1 * hp1[j]
        accepted[s] = 1
        n_ok += 1
    if n_ok > 0:
        for k in range(N):
            for j in range(k + 1, N):
                v = 0.5 * (P[k, j] + P[j, k])
                P[k, j] = v
                P[j, k] = v
    return n_ok
