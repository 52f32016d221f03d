"""numba kernels of the coupled loop's per-sample and per-image paths (no Python objects).

Star state arrays (``S`` = :data:`gyrostar.loop.record.MAX_STARS` slots):

* ``X`` (S, 5), ``P`` (S, 5, 5): one paper-000 spot EKF per tracked star
  ([x, y] px from the principal point, [bx, by, bz] rad/s), see :mod:`gyrostar.core.spot_ekf`;
* ``active`` (S,) bool: slot in use; ``valid`` (S,) bool: the spot has been measured
  (its EKF holds an image update) and may be used for attitude;
* ``ref`` (S, 3): the identified catalog star's ICRS unit vector of each slot;
* ``hist_xy`` (S, H, 2): the spot's predicted position at each of the last H gyro samples
  (ring buffer, same index as ``hist_t``), used to bring a centroid measured at exposure
  mid-time forward to the current sample.

Attitude at every gyro sample is QUEST (:mod:`gyrostar.core.quest`) over the valid spots'
filtered positions (unprojected to body vectors) and their catalog vectors, weighted by
each EKF's position variance; gyro bias is the information-weighted fusion of the spot
EKFs' drift estimates.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..attitude import quat_propagate, quat_to_dcm
from ..camera import P_CX, P_CY, P_F, project_point, unproject_point
from ..core.quest import quest
from ..core.spot_ekf import spot_ekf_predict


@njit(cache=True)
def predict_stars(X, P, active, omega_m, dt, f_px, sigma_rate, sigma_bias_rw, model, hist_xy, h):
    """One gyro sample: every active spot EKF predicts; position stored in history slot h."""
    for i in range(X.shape[0]):
        if active[i]:
            spot_ekf_predict(X[i], P[i], omega_m, dt, f_px, sigma_rate, sigma_bias_rw, model)
            hist_xy[i, h, 0] = X[i, 0]
            hist_xy[i, h, 1] = X[i, 1]


@njit(cache=True)
def fuse_bias(X, P, use, prior_b, prior_var):
    """Information-weighted mean of the spots' drift estimates (rad/s) and its covariance."""
    info = np.eye(3) / prior_var
    vec = prior_b / prior_var
    for i in range(X.shape[0]):
        if use[i]:
            pb = P[i, 2:5, 2:5].copy()
            inv = np.linalg.inv(pb)
            info += inv
            vec += inv @ X[i, 2:5]
    cov = np.linalg.inv(info)
    return cov @ vec, cov


@njit(cache=True)
def attitude_from_stars(X, P, use, ref, params):
    """QUEST over the spots flagged ``use``: (q, cov3, n_used). n_used < 2 → q is NaN."""
    n = 0
    for i in range(X.shape[0]):
        if use[i]:
            n += 1
    q = np.full(4, np.nan)
    cov = np.full((3, 3), np.inf)
    if n < 2:
        return q, cov, n
    b = np.empty((n, 3))
    r = np.empty((n, 3))
    w = np.empty(n)
    f = params[P_F]
    k = 0
    for i in range(X.shape[0]):
        if use[i]:
            b[k] = unproject_point(params, X[i, 0] + params[P_CX], X[i, 1] + params[P_CY])
            r[k] = ref[i]
            var_px = 0.5 * (P[i, 0, 0] + P[i, 1, 1])
            w[k] = f * f / max(var_px, 1e-8)
            k += 1
    q, cov = quest(b, r, w)
    return q, cov, n


@njit(cache=True)
def star_residuals(X, use, ref, params, q):
    """Angle (rad) between each used spot's body vector and A(q)·ref; NaN where unused."""
    a = quat_to_dcm(q)
    out = np.full(X.shape[0], np.nan)
    for i in range(X.shape[0]):
        if use[i]:
            bv = unproject_point(params, X[i, 0] + params[P_CX], X[i, 1] + params[P_CY])
            p = a @ ref[i]
            c = bv[0] * p[0] + bv[1] * p[1] + bv[2] * p[2]
            out[i] = np.arccos(min(1.0, max(-1.0, c)))
    return out


@njit(cache=True)
def coast_attitude(q, omega_m, bias, dt):
    """Gyro-only attitude step with the bias-corrected rate."""
    return quat_propagate(q, omega_m - bias, dt)


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
