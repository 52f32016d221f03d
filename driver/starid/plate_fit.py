"""Least-squares plate fit: attitude, focal length and radial distortion k1 (and the
principal point, when asked) from matched stars of one or more images (numba).

Model (:mod:`gyrostar.camera`, frames of :mod:`gyrostar.attitude`): a catalog direction
``r`` (ICRS) is seen at body ``p = A(q) r``; ``xn = p_x/p_z``, ``yn = p_y/p_z``,
``r² = xn² + yn²``; ``u = cx + f·xn·(1 + k1 r²)``, ``v = cy + f·yn·(1 + k1 r²)`` (px,
[col, row]). Gauss–Newton on the pixel residuals with central-difference Jacobians; the
attitude is updated by a small body-frame rotation ``δq(δθ) ⊗ q``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..attitude import quat_mult, quat_normalize, quat_to_dcm, rotvec_to_quat


@njit(cache=True)
def project_radial(a, r, f, k1, cx, cy):
    """Catalog direction ``r`` (3,) through DCM ``a`` (ICRS → body) → (u, v, in_front)."""
    px = a[0, 0] * r[0] + a[0, 1] * r[1] + a[0, 2] * r[2]
    py = a[1, 0] * r[0] + a[1, 1] * r[1] + a[1, 2] * r[2]
    pz = a[2, 0] * r[0] + a[2, 1] * r[1] + a[2, 2] * r[2]
    if pz <= 1e-9:
        return np.nan, np.nan, False
    xn = px / pz
    yn = py / pz
    k = 1.0 + k1 * (xn * xn + yn * yn)
    return cx + f * xn * k, cy + f * yn * k, True


@njit(cache=True)
def _residuals(q, f, k1, cx, cy, uv, ref, out):
    a = quat_to_dcm(q)
    for i in range(uv.shape[0]):
        u, v, ok = project_radial(a, ref[i], f, k1, cx, cy)
        if not ok:
            u, v = 1e9, 1e9
        out[2 * i] = uv[i, 0] - u
        out[2 * i + 1] = uv[i, 1] - v


@njit(cache=True)
def _apply(q, f, k1, cx, cy, d, which):
    """Parameters after step ``d`` over the fitted ``which`` (0..2 rotation, 3 f, 4 k1, 5 cx, 6 cy)."""
    th = np.zeros(3)
    for j in range(d.shape[0]):
        w = which[j]
        if w < 3:
            th[w] = d[j]
        elif w == 3:
            f = f + d[j]
        elif w == 4:
            k1 = k1 + d[j]
        elif w == 5:
            cx = cx + d[j]
        else:
            cy = cy + d[j]
    if th[0] != 0.0 or th[1] != 0.0 or th[2] != 0.0:
        q = quat_normalize(quat_mult(rotvec_to_quat(th), q))
    return q, f, k1, cx, cy


@njit(cache=True)
def fit_plate(uv, ref, q, f, k1, cx, cy, fit_k1, fit_center, iters):
    """Fit one image's matched stars: ``uv`` (m, 2) px, ``ref`` (m, 3) ICRS unit vectors,
    start ``q, f, k1, cx, cy``. Fits the attitude and ``f`` always, ``k1`` when ``fit_k1``,
    ``cx, cy`` when ``fit_center``. Returns ``(q, f, k1, cx, cy, cov)``: ``cov`` the
    parameters' covariance in the fitted order [θx, θy, θz, f, (k1), (cx, cy)] scaled by the
    residual variance (rad², px², ...)."""
    m = uv.shape[0]
    np_ = 4 + (1 if fit_k1 else 0) + (2 if fit_center else 0)
    which = np.empty(np_, dtype=np.int64)
    which[0], which[1], which[2], which[3] = 0, 1, 2, 3
    j = 4
    if fit_k1:
        which[j] = 4
        j += 1
    if fit_center:
        which[j] = 5
        which[j + 1] = 6
    steps = np.array([1e-6, 1e-6, 1e-6, 1e-3 * f, 1e-4, 1e-2, 1e-2])
    r0 = np.empty(2 * m)
    rp = np.empty(2 * m)
    rm = np.empty(2 * m)
    jac = np.empty((2 * m, np_))
    cov = np.full((np_, np_), np.nan)
    for _ in range(iters):
        _residuals(q, f, k1, cx, cy, uv, ref, r0)
        for c in range(np_):
            d = np.zeros(np_)
            h = steps[which[c]]
            d[c] = h
            q1, f1, k11, cx1, cy1 = _apply(q, f, k1, cx, cy, d, which)
            _residuals(q1, f1, k11, cx1, cy1, uv, ref, rp)
            d[c] = -h
            q1, f1, k11, cx1, cy1 = _apply(q, f, k1, cx, cy, d, which)
            _residuals(q1, f1, k11, cx1, cy1, uv, ref, rm)
            for i in range(2 * m):
                jac[i, c] = -(rp[i] - rm[i]) / (2.0 * h)    # d(model)/dp
        jtj = jac.T @ jac
        jtr = jac.T @ r0
        for c in range(np_):
            jtj[c, c] *= 1.0 + 1e-9
        try:
            d = np.linalg.solve(jtj, jtr)
        except Exception:       # singular: keep the last parameters
            break
        q, f, k1, cx, cy = _apply(q, f, k1, cx, cy, d, which)
        if np.all(np.abs(d[:3]) < 1e-10) and abs(d[3]) < 1e-7 * f:
            break
    _residuals(q, f, k1, cx, cy, uv, ref, r0)
    dof = 2 * m - np_
    if dof > 0:
        s2 = (r0 @ r0) / dof
        jtj = jac.T @ jac
        try:
            cov = np.linalg.inv(jtj) * s2
        except Exception:
            pass
    return q, f, k1, cx, cy, cov


@njit(cache=True)
def pixel_residuals(uv, ref, q, f, k1, cx, cy):
    """Observed minus predicted pixel positions (m, 2) of matched stars."""
    out = np.empty(2 * uv.shape[0])
    _residuals(q, f, k1, cx, cy, uv, ref, out)
    return out.reshape(uv.shape[0], 2)


def fov_x_deg(f_px: float, width_px: int, cx_px: float, k1: float = 0.0) -> float:
    """Horizontal field of view (°): the angle between the directions seen at the left and
    right sensor edges on the principal point's row, with radial distortion ``k1``
    (undistorted by fixed-point iteration; k1 = 0: the pinhole's)."""
    total = 0.0
    for edge in (cx_px + 0.5, width_px - 0.5 - cx_px):
        xd = edge / f_px
        xn = xd
        for _ in range(50):
            xn = xd / (1.0 + k1 * xn * xn)
        total += math.atan(xn)
    return math.degrees(total)
