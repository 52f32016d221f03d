"""The spot EKF of paper 000 (eq. 3.1–3.10), in our axis convention.

State ``X = [x, y, b_x, b_y, b_z]``: spot position (px from the principal point, x along
columns, y along rows) and gyro drift (rad/s, body axes); gyro model
``ω_mea = ω_real + b + η`` (eq. 3.1). With ``f = F/a`` (focal length in pixels) and the
body-rate convention of ``gyrostar.attitude`` (``V_x = ω_z·y − ω_y·f``,
``V_y = −ω_z·x + ω_x·f``), eq. 3.4 ``X_{k+1} = Φ_k X_k + Ψ_k + w_k`` has

    Ψ_k = [−ω_y, ω_x, 0, 0, 0]ᵀ · f·Δt
    Φ_k = | 1        ω_z Δt   0       f Δt    −y_est Δt |
          | −ω_z Δt  1        −f Δt   0        x_est Δt |
          | 0 0 1 0 0 | 0 0 0 1 0 | 0 0 0 0 1 |

(the paper's matrix with the roll-term signs of our frame; ω = measured rates) and
``H = [I₂ 0]`` (eq. 3.10). ``model = MODEL_PINHOLE`` instead propagates the exact
projection of the rotation (``motion.step_spot``) with Φ = I + J·Δt, J the Jacobian of
the full pinhole velocity (off-axis x·y/f, x²/f terms). Measured on the xing2012 preset
(``gyrostar eval centroid``), the pinhole terms change the EKF error by ≤ 0.002 px even
for a star 570 px off-axis at 20 °/s (0.0581/0.1395 vs 0.0588/0.1408 px): the per-frame
update absorbs the ≤ 0.1 px/frame model error. Same cost; the pinhole model is the default.

Process noise: gyro white noise σ_ω (rad/s per sample) enters the position through
``G = ∂V/∂ω``: ``Q_pos = Δt² σ_ω² G Gᵀ``; the drift is a random walk of density
σ_b (rad/s/√s): ``Q_b = σ_b² Δt I``.

Predict runs at every gyro sample (400 Hz), ``spot_ekf_update`` at every image with a
χ² gate on the normalised innovation (2 dof); ``spot_ekf_reset`` re-acquires the
position from a measurement and keeps the drift estimate.
All functions work in place on preallocated arrays (no allocation per sample).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .motion import MODEL_PINHOLE, step_spot

CHI2_2DOF_999 = 13.815510557964274  # P(χ²₂ > 13.82) = 0.001


@njit(cache=True)
def spot_ekf_init(x, y, bias, sigma_pos_px, sigma_bias):
    """Initial state (5,) and covariance (5, 5) from a first centroid and a drift prior."""
    X = np.empty(5)
    X[0] = x
    X[1] = y
    X[2:] = bias
    P = np.zeros((5, 5))
    P[0, 0] = P[1, 1] = sigma_pos_px * sigma_pos_px
    P[2, 2] = P[3, 3] = P[4, 4] = sigma_bias * sigma_bias
    return X, P


@njit(cache=True)
def transition(X, omega_m, dt, f_px, model):
    """(Φ (5, 5), Ψ (5,), G (2, 3) = ∂V/∂ω) of one gyro interval at the estimate X."""
    x, y = X[0], X[1]
    wx, wy, wz = omega_m[0], omega_m[1], omega_m[2]
    phi = np.eye(5)
    psi = np.zeros(5)
    g = np.empty((2, 3))
    if model != MODEL_PINHOLE:
        phi[0, 1] = wz * dt
        phi[0, 3] = f_px * dt
        phi[0, 4] = -y * dt
        phi[1, 0] = -wz * dt
        phi[1, 2] = -f_px * dt
        phi[1, 4] = x * dt
        psi[0] = -wy * f_px * dt
        psi[1] = wx * f_px * dt
        g[0, 0] = 0.0
        g[0, 1] = -f_px
        g[0, 2] = y
        g[1, 0] = f_px
        g[1, 1] = 0.0
        g[1, 2] = -x
        return phi, psi, g
    # pinhole: Jacobian at ω = ω_m − b
    ux = wx - X[2]
    uy = wy - X[3]
    uz = wz - X[4]
    g[0, 0] = x * y / f_px
    g[0, 1] = -f_px - x * x / f_px
    g[0, 2] = y
    g[1, 0] = f_px + y * y / f_px
    g[1, 1] = -x * y / f_px
    g[1, 2] = -x
    phi[0, 0] += -(2.0 * x * uy - y * ux) / f_px * dt
    phi[0, 1] = (uz + x * ux / f_px) * dt
    phi[1, 0] = (-uz - y * uy / f_px) * dt
    phi[1, 1] += -(x * uy - 2.0 * y * ux) / f_px * dt
    for j in range(3):
        phi[0, 2 + j] = -g[0, j] * dt
        phi[1, 2 + j] = -g[1, j] * dt
    return phi, psi, g


@njit(cache=True)
def spot_ekf_predict(X, P, omega_m, dt, f_px, sigma_rate, sigma_bias_rw, model):
    """One gyro sample: propagate X (5,) and P (5, 5) in place over ``dt`` s."""
    x, y = X[0], X[1]
    wx = omega_m[0] - X[2]
    wy = omega_m[1] - X[3]
    wz = omega_m[2] - X[4]
    # Jacobian-structured covariance propagation P ← Φ P Φᵀ + Q
    phi, _psi, g = transition(X, omega_m, dt, f_px, model)
    if model == MODEL_PINHOLE:
        X[0], X[1] = step_spot(x, y, wx, wy, wz, dt, f_px, model)
    else:  # X ← Φ X + Ψ (eq. 3.4), written out
        X[0] = x + (wz * y - wy * f_px) * dt
        X[1] = y + (-wz * x + wx * f_px) * dt
    tmp = np.empty((5, 5))
    for i in range(2):
        for j in range(5):
            s = 0.0
            for k in range(5):
                s += phi[i, k] * P[k, j]
            tmp[i, j] = s
    for i in range(2, 5):
        for j in range(5):
            tmp[i, j] = P[i, j]
    for i in range(5):
        for j in range(2):
            s = 0.0
            for k in range(5):
                s += tmp[i, k] * phi[j, k]
            P[i, j] = s
        for j in range(2, 5):
            P[i, j] = tmp[i, j]
    q = sigma_rate * sigma_rate * dt * dt
    for i in range(2):
        for j in range(2):
            P[i, j] += q * (g[i, 0] * g[j, 0] + g[i, 1] * g[j, 1] + g[i, 2] * g[j, 2])
    qb = sigma_bias_rw * sigma_bias_rw * dt
    for i in range(2, 5):
        P[i, i] += qb


@njit(cache=True)
def spot_ekf_propagate(X, P, rates, dt, f_px, sigma_rate, sigma_bias_rw, model):
    """Predict over every gyro sample in ``rates`` (m, 3), in place."""
    for i in range(rates.shape[0]):
        spot_ekf_predict(X, P, rates[i], dt, f_px, sigma_rate, sigma_bias_rw, model)


@njit(cache=True)
def spot_ekf_update(X, P, zx, zy, r_var_x, r_var_y, gate):
    """Image update with centroid (zx, zy) px, H = [I₂ 0]; returns (accepted, NIS).

    The update is skipped (state untouched) when the normalised innovation squared
    exceeds ``gate`` (χ², 2 dof; e.g. ``CHI2_2DOF_999``) or the measurement or its variance
    is not finite.
    Joseph-form covariance update.
    """
    if not (np.isfinite(zx) and np.isfinite(zy) and np.isfinite(r_var_x) and np.isfinite(r_var_y)):
        return False, np.inf
    nu0 = zx - X[0]
    nu1 = zy - X[1]
    s00 = P[0, 0] + r_var_x
    s01 = P[0, 1]
    s11 = P[1, 1] + r_var_y
    det = s00 * s11 - s01 * s01
    i00 = s11 / det
    i01 = -s01 / det
    i11 = s00 / det
    nis = nu0 * (i00 * nu0 + i01 * nu1) + nu1 * (i01 * nu0 + i11 * nu1)
    if nis > gate:
        return False, nis
    K = np.empty((5, 2))
    for i in range(5):
        K[i, 0] = P[i, 0] * i00 + P[i, 1] * i01
        K[i, 1] = P[i, 0] * i01 + P[i, 1] * i11
    for i in range(5):
        X[i] += K[i, 0] * nu0 + K[i, 1] * nu1
    # Joseph form (I − K H) P (I − K H)ᵀ + K R Kᵀ, expanded:
    # P − K (H P) − (P Hᵀ) Kᵀ + K S Kᵀ, with H P the first two rows of P
    hp = np.empty((2, 5))
    for j in range(5):
        hp[0, j] = P[0, j]
        hp[1, j] = P[1, j]
    for i in range(5):
        ks0 = K[i, 0] * s00 + K[i, 1] * s01
        ks1 = K[i, 0] * s01 + K[i, 1] * s11
        for j in range(i, 5):
            v = (P[i, j] - K[i, 0] * hp[0, j] - K[i, 1] * hp[1, j] - hp[0, i] * K[j, 0]
                 - hp[1, i] * K[j, 1] + ks0 * K[j, 0] + ks1 * K[j, 1])
            P[i, j] = v
            P[j, i] = v
    return True, nis


@njit(cache=True)
def spot_ekf_reset(X, P, zx, zy, r_var_x, r_var_y):
    """Re-acquire: position ← measurement, drift estimate and its covariance kept."""
    X[0] = zx
    X[1] = zy
    for j in range(5):
        P[0, j] = 0.0
        P[1, j] = 0.0
        P[j, 0] = 0.0
        P[j, 1] = 0.0
    P[0, 0] = r_var_x
    P[1, 1] = r_var_y


@njit(cache=True)
def spot_ekf_update_delayed(X, P, X_mid, P_mid, zx, zy, r_var_x, r_var_y, gate, rates_since_mid, dt, f_px,
                            sigma_rate, sigma_bias_rw, model):
    """Image update when the image arrives after its exposure: returns (accepted, NIS).

    A smeared spot's centroid is the exposure-averaged position, i.e. the state at
    mid-exposure. The loop saves (X_mid, P_mid) at that gyro sample and keeps predicting
    (X, P); when the centroid arrives, the saved state is updated and re-propagated over
    the gyro samples since mid-exposure ``rates_since_mid`` (m, 3) into X, P (in place).
    On rejection X, P are left as predicted.
    """
    ok, nis = spot_ekf_update(X_mid, P_mid, zx, zy, r_var_x, r_var_y, gate)
    if ok:
        X[:] = X_mid
        P[:, :] = P_mid
        spot_ekf_propagate(X, P, rates_since_mid, dt, f_px, sigma_rate, sigma_bias_rw, model)
    return ok, nis
